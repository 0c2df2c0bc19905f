"""Per-block functions evaluated over a whole grid: the machinery every grid assembly shares.

A grid's residual and Jacobian are made of blocks (an interval, a node, a window of nodes), each
the same CasADi function of a few node vectors. Mapping that function over the whole grid would
build sparsity patterns that grow with ``N``; instead a fixed window of blocks is mapped once
and evaluated window after window through ``Function.buffer`` on numpy memory:

- `ChunkedMap` on CasADi's virtual machine (windows of ``CHUNK`` blocks), optionally in
  threads (``Compilation.threads``);
- `WindowMap` compiled when there is a compiler (windows of ``WINDOW`` blocks, one
  library for every grid), the virtual machine otherwise.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ...blocks import Sink, evaluate_in_blocks, through_buffer
from ...cache import cached
from ..compiler import CompileUnavailable, cache_folder, compile_function, find_compiler, warn_once
from ..options import Compilation

# Blocks per mapped evaluation (module docstring of ChunkedMap).
CHUNK = 4096
# Blocks per window of the compiled maps (WindowMap): building a map costs ~7 us a block per
# process (28 ms at 4096, 4 ms at 1024, measured), and at N = 1e6 the evaluations took the same
# time with 1024 and 4096.
WINDOW = 1024


class ChunkedMap:
    """A per-block function evaluated over ``count`` blocks in windows of ``CHUNK`` blocks, each
    by one mapped call through ``Function.buffer`` on numpy memory.

    A map over the whole grid cost 0.11 s to build at N = 1e5 (its sparsity patterns grow with
    N); a fixed window is built once per function and process. The last window is shifted back
    to end on the last block (it recomputes a few blocks: harmless). Block inputs are arrays of
    shape ``(count, size)``; ``theta`` is shared. Output ``j`` has shape ``(count, columns,
    rows)`` (CasADi's column-major blocks read as C arrays).
    """

    def __init__(self, function: ca.Function, threads: int = 1):
        self.function = function
        self.threads = threads
        self._maps: dict[int, tuple] = {}

    def _window(self, size: int):
        if size not in self._maps:
            # Threads did not pay off on 2 cores (measured at N = 1e5 and 1e6); the form
            # map(name, "thread", n, reduce_in, ...) aborted on evaluation (CasADi 3.8.2).
            mapped = self.function.map(size, "thread", self.threads) \
                if self.threads > 1 and size > 1 else self.function.map(size)
            self._maps[size] = mapped.buffer()
        return self._maps[size]

    def prepare(self, count: int) -> None:
        self._window(min(CHUNK, count))

    def __call__(self, blocks: list[np.ndarray], theta: np.ndarray, count: int):
        f = self.function
        outputs = [np.empty((count, f.size2_out(j), f.size1_out(j))) for j in range(f.n_out())]
        size = min(CHUNK, count)
        buffer, evaluate = self._window(size)
        shared = np.ascontiguousarray(np.tile(np.asarray(theta, float), size))
        buffer.set_arg(len(blocks), memoryview(shared))
        evaluate_in_blocks(through_buffer(buffer, evaluate), blocks, outputs, count=count,
                           width=size, last="shift")
        return outputs


def chunked(system, key, function: ca.Function, threads: int = 1) -> ChunkedMap:
    """The `ChunkedMap` of ``function``, one per system, ``key`` and thread count."""
    return cached(system, ("chunked", key, threads), lambda: ChunkedMap(function, threads))


class WindowMap:
    """A per-block function evaluated over ``count`` blocks in windows of ``WINDOW`` blocks, each
    by one mapped call through ``Function.buffer`` on numpy memory, compiled when it can be.

    Compiled (``compiler.compile_function``, cached on disk under a hash of the code): the
    window is always ``WINDOW`` blocks wide, so that one library serves every grid; a grid
    shorter than a window is padded (its last block repeated) and the surplus discarded. On
    CasADi's virtual machine (no compiler, ``Compilation(compiler=None)``, or a failed compile,
    with one warning) the window is ``min(WINDOW, count)`` blocks. As in `ChunkedMap`
    the last window is shifted back to end on the last block.

    Inputs are C-contiguous arrays ``(count, size)`` (slices of the grid: no copy), ``shared``
    one vector given to every block. Each output goes to an array ``(count, size)`` given by
    the caller (written in place: for the residual, a slice of ``F``), or, if ``None``, to a
    window-sized scratch that ``sink(first, values)`` receives after each window (the band rows,
    scattered from there while they are in cache)."""

    def __init__(self, function: ca.Function, compiler: str | None, folder):
        self.function = function
        self.path = "vm"
        self._compiled = None
        self._vm: dict[int, tuple] = {}
        if compiler is not None:
            try:
                self._compiled = compile_function(function.map(WINDOW), compiler, folder,
                                                  prefix="bvp").buffer()
                self.path = "compiled"
            except CompileUnavailable as exc:
                warn_once(exc)  # the virtual machine evaluates the same function

    def _window(self, count: int):
        if self._compiled is not None:
            return WINDOW, self._compiled
        size = min(WINDOW, count)
        if size not in self._vm:
            self._vm[size] = self.function.map(size).buffer()
        return size, self._vm[size]

    def prepare(self, count: int) -> None:
        self._window(count)

    def __call__(self, inputs, shared, outputs, count: int, sink=None) -> None:
        f = self.function
        size, (buffer, trigger) = self._window(count)
        tiled = np.tile(np.asarray(shared, float), (size, 1))
        buffer.set_arg(len(inputs), memoryview(tiled))
        kept = [out if out is not None else
                Sink((f.nnz_out(j),), sink if sink is not None else lambda first, rows: None)
                for j, out in enumerate(outputs)]
        evaluate_in_blocks(through_buffer(buffer, trigger), inputs, kept, count=count,
                           width=size, last="shift")


def window_map(system, key, function: ca.Function, compilation: Compilation) -> WindowMap:
    """The `WindowMap` of ``function``, one per system, ``key`` and compiler setting."""
    compiler = find_compiler(compilation.compiler)
    folder = cache_folder(compilation.cache_dir)
    return cached(system, ("bvp_window", key, compiler, str(folder)),
                  lambda: WindowMap(function, compiler, folder))


def evaluate_blocks(system, key, function: ca.Function, inputs, shared,
                    compilation: Compilation) -> list[np.ndarray]:
    """``function`` on every row of ``inputs`` (arrays ``(count, size_i)``, one block a row;
    ``shared``, the function's last input, given to every block), through a
    `WindowMap` kept per ``system`` and ``key``: compiled when there is a compiler, one
    library for every ``count``. Output ``j`` has shape ``(count, nnz_out(j))``.

    For per-node evaluations of the starts (``bvp/start.site_weights`` maps its function over
    ``N - 1`` intervals on CasADi's virtual machine, a map built for each ``N``)."""
    count = int(np.shape(inputs[0])[0])
    outputs = [np.empty((count, function.nnz_out(j))) for j in range(function.n_out())]
    window_map(system, key, function, compilation)(
        [np.ascontiguousarray(a, float) for a in inputs], np.ascontiguousarray(shared, float),
        outputs, count)
    return outputs
