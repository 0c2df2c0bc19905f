"""A function of one block of rows, evaluated over many rows block after block.

Every evaluation of the package over the nodes or steps of a long result runs a CasADi function
built for a fixed number of rows, its block's ``width`` (a ``map`` over ``width`` nodes,
compiled or on CasADi's virtual machine, serial or in threads, called with DM arguments or
through a buffer on numpy memory), over arrays of any length: the checks of a result
(`evaluate_columns`, ``solvers/marching/recheck.py``), the grid assemblies
(``solvers/grid/maps.py``), the accuracy check's node values
(``solvers/accuracy/node_values.py``) and the exact flow's short steps
(``solvers/exact/short_flows.py``). `evaluate_in_blocks` is that loop, written once; what the
function is stays the caller's, passed as ``evaluate(inputs, outputs)``: fill the block's
outputs from its inputs (`through_buffer` and `copied` are the two usual ones).

Rows are the first axis of every input and output. The blocks start at ``0, width, 2 width,
...``; each reads ``width + halo`` rows of every input (``halo``: rows past the block that its
function reads too, as the energy equation at a node reads the node after it). A short last
block is

- padded (``last="pad"``): its last row repeated up to ``width + halo`` rows; or
- shifted back (``last="shift"``) to end on the last row, recomputing rows of the block before
  it (padded all the same when there are fewer rows than ``width``).

A mapped function computes each row alone, so the rows kept are the same bits whatever the
width and however the last block is filled (``tests/library/test_blocks.py``); where rows of
one block share work (the recheck's pieces of 8 intervals), the blocks start where they always
did. An output's rows are written in place where the block covers them whole (a view of the
caller's array, which a buffer writes to directly), through a scratch block otherwise; an
output may have fewer rows than the blocks (the energy equations of a grid: one fewer than its
intervals), or be a `Sink`, which is handed each block's rows instead of keeping them.

`evaluate_columns` evaluates a per-node function on every node of a long result (``H`` at the
nodes, the equations of a grid) through a block-wide map kept in ``cache.FUNCTIONS``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .cache import FUNCTIONS, cached


@dataclass(frozen=True)
class Sink:
    """An output handed to ``receive(first, rows)`` block by block instead of being kept (the
    band rows of a grid's Jacobian, scattered while they are in cache); ``row_shape``: the
    shape of one row."""

    row_shape: tuple[int, ...]
    receive: Callable[[int, np.ndarray], None]


Evaluate = Callable[[list[np.ndarray], list[np.ndarray]], None]


def evaluate_in_blocks(evaluate: Evaluate, inputs: Sequence[np.ndarray],
                       outputs: Sequence[np.ndarray | Sink], *, count: int, width: int,
                       last: str = "pad", halo: int = 0) -> None:
    """``evaluate(block_inputs, block_outputs)`` on the blocks of ``width`` rows of ``count``
    rows (module docstring): each input gives ``width + halo`` rows a block, each output
    receives the rows of the block it has (``min(width, len(output) - first)``)."""
    if last not in ("pad", "shift"):
        raise ValueError(f"last must be 'pad' or 'shift', got {last!r}")
    shifted = last == "shift" and count >= width
    scratch: dict[int, np.ndarray] = {}

    def scratch_block(j: int, output) -> np.ndarray:
        if j not in scratch:
            shape = output.row_shape if isinstance(output, Sink) else output.shape[1:]
            scratch[j] = np.empty((width, *shape))
        return scratch[j]

    for first in range(0, count, width):
        if shifted:
            first = min(first, count - width)
        rows = min(width, count - first)
        in_place = [not isinstance(out, Sink) and len(out) - first >= width for out in outputs]
        block_outputs = [out[first:first + width] if whole else scratch_block(j, out)
                         for j, (out, whole) in enumerate(zip(outputs, in_place, strict=True))]
        evaluate([_rows(values, first, width + halo) for values in inputs], block_outputs)
        for out, block, whole in zip(outputs, block_outputs, in_place, strict=True):
            if isinstance(out, Sink):
                out.receive(first, block[:rows])
            elif not whole and min(rows, len(out) - first) > 0:
                kept = min(rows, len(out) - first)
                out[first:first + kept] = block[:kept]


def _rows(values: np.ndarray, first: int, size: int) -> np.ndarray:
    """Rows ``first .. first + size`` of ``values``, the last one repeated where there are
    fewer (``np.pad`` took 0.1 ms a call, more than a block's compiled work)."""
    part = values[first:first + size]
    rows = part.shape[0]
    if rows == size:
        return part
    out = np.empty((size, *part.shape[1:]))
    out[:rows] = part
    out[rows:] = part[rows - 1]
    return out


def through_buffer(buffer, trigger) -> Evaluate:
    """``evaluate`` for `evaluate_in_blocks` through ``Function.buffer()``'s ``(buffer,
    trigger)``: the block's arrays handed to CasADi as they are (C-contiguous inputs are not
    copied; outputs are written in place); the arguments after the blocks' (shared by every
    block) are the caller's to set once."""
    def evaluate(inputs, outputs):
        held = [np.ascontiguousarray(values) for values in inputs]  # CasADi keeps addresses
        for j, values in enumerate(held):
            buffer.set_arg(j, memoryview(values))
        for j, values in enumerate(outputs):
            buffer.set_res(j, memoryview(values))
        trigger()
    return evaluate


def copied(call: Callable[..., Sequence[np.ndarray]]) -> Evaluate:
    """``evaluate`` for `evaluate_in_blocks` from ``call(*block_inputs)`` returning the block's
    outputs (a ``FunctionBuffer``'s arrays), copied into the block's outputs (``(width, 1)``
    into ``(width,)`` too)."""
    def evaluate(inputs, outputs):
        for out, values in zip(outputs, call(*inputs), strict=False):
            out[...] = values.reshape(out.shape)
    return evaluate


# Columns per call of `evaluate_columns`' map: one map of this width is built (and compiled)
# once per equation and reused for every grid; a map as wide as the grid was rebuilt for each
# length (1.4 s for 400,000 nodes) and converted back element by element.
COLUMN_BLOCK = 8192


def evaluate_columns(system, function, columns: list, theta, *,
                     compile=None) -> np.ndarray:
    """``function`` (one output) on every column of ``columns`` (arrays ``(rows_i, N)``), with
    ``theta`` for every column: shape ``(rows_out, N)``. Runs a cached ``COLUMN_BLOCK``-wide
    map (or, for fewer columns, one as wide as the next power of two) block by block (the last
    block padded by repeating its last column), compiled by ``compile`` if given, else by the
    one registered for ``system`` (`use_compiler`)."""
    N = columns[0].shape[1]
    # A short grid gets a map of the next power of two, padded: a map per grid length was
    # built anew for every run of a comparison (66 runs of `ddvp compare kepler`: 1.8 s of
    # building maps for the energy errors; measured); a map per power of two is built once.
    width = min(COLUMN_BLOCK, 1 << max(N - 1, 0).bit_length())
    if width < COLUMN_BLOCK:
        compile = None  # a short grid: compiling a map of its own width costs more than it saves
    else:
        compile = compile or FUNCTIONS.get(system, ("block compiler",), lambda: None)
    mapped = cached(system, ("block", function.name(), width, compile is not None),
                    lambda: (compile or (lambda f: f))(function.map(width)))
    theta = np.repeat(np.asarray(theta, float)[:, None], width, axis=1)
    result = np.empty((function.size1_out(0), N))

    def evaluate(inputs, outputs):
        outputs[0][...] = mapped(*(block.T for block in inputs), theta).full().T

    evaluate_in_blocks(evaluate, [c.T for c in columns], [result.T], count=N, width=width)
    return result


def use_compiler(system, compile) -> None:
    """Make ``compile`` (``Function -> Function``) the one `evaluate_columns` uses for
    ``system`` from now on: once a march has a working compiler, the checks of its results
    (every equation at every node) run compiled too."""
    FUNCTIONS.get(system, ("block compiler",), lambda: compile)


__all__ = ["COLUMN_BLOCK", "Sink", "copied", "evaluate_columns", "evaluate_in_blocks",
           "through_buffer", "use_compiler"]
