"""Every equation of a returned grid, recomputed in compiled code.

The same residuals as ``discrete.equations.grid_residuals`` (the canonical equations of every
interval, the energy equation at every inner node, unscaled), from the same CasADi functions,
mapped over blocks of ``BLOCK`` intervals, compiled and called through numpy buffers: on
CasADi's virtual machine the recheck cost 2-3 us per node, more than the compiled march itself.
Without a compiler it is ``grid_residuals`` itself.
"""

from __future__ import annotations

import numpy as np

from ..cache import cached
from ..discrete import equations
from .compiler import (
    CompileUnavailable,
    FunctionBuffer,
    cache_folder,
    compile_function,
    warn_once,
)

BLOCK = 1024


def _blocks(system, scheme, compiler, cache_dir):
    """The compiled canonical and energy residuals of ``BLOCK`` intervals / nodes (cached)."""
    def build():
        folder = cache_folder(cache_dir)
        canonical = compile_function(
            equations.canonical_function(system, scheme).map(BLOCK), compiler, folder,
            prefix="recheck")
        energy = compile_function(
            equations.energy_function(system, scheme).map(BLOCK), compiler, folder,
            prefix="recheck")
        return FunctionBuffer(canonical), FunctionBuffer(energy)
    return cached(system, ("recheck", scheme, compiler, str(cache_dir)), build)


def _padded(values: np.ndarray, start: int, stop: int) -> np.ndarray:
    """Rows ``start:stop`` of ``values``, the last one repeated up to ``BLOCK`` rows."""
    part = values[start:stop]
    if part.shape[0] == BLOCK:  # a full block: no copy (np.pad cost 80 us a call)
        return part
    return np.pad(part, [(0, BLOCK - part.shape[0])] + [(0, 0)] * (part.ndim - 1), mode="edge")


def grid_residuals(system, scheme, t, q, p, theta, *, compiler=None, cache_dir=None):
    """Canonical residuals ``(N-1, 2n)`` and energy residuals ``(N-2,)``, as
    ``discrete.equations.grid_residuals`` returns them."""
    if compiler is None or np.size(t) < 3:
        return equations.grid_residuals(system, scheme, t, q, p, theta)
    try:
        blocks = _blocks(system, scheme, compiler, cache_dir)
    except CompileUnavailable as reason:  # the virtual machine gives the same residuals
        warn_once(reason)
        return equations.grid_residuals(system, scheme, t, q, p, theta)
    canonical_block, energy_block = blocks
    t, q, p = (np.asarray(a, float) for a in (t, q, p))
    N = t.size
    theta = np.broadcast_to(np.asarray(theta, float), (BLOCK, np.size(theta)))
    canonical = np.empty((N - 1, 2 * system.n))
    energy = np.empty(N - 2)
    for start in range(0, N - 1, BLOCK):
        stop = min(start + BLOCK, N - 1)
        (out,) = canonical_block(*(_padded(t, start + s, stop + s) for s in (0, 1)),
                                 *(_padded(a, start + s, stop + s) for s in (0, 1)
                                   for a in (q, p)), theta)
        canonical[start:stop] = out[:stop - start]
    for start in range(0, N - 2, BLOCK):
        stop = min(start + BLOCK, N - 2)
        (out,) = energy_block(*(_padded(t, start + s, stop + s) for s in (0, 1, 2)),
                              *(_padded(a, start + s, stop + s) for s in (0, 1, 2)
                                for a in (q, p)), theta)
        energy[start:stop] = out[:stop - start, 0]
    return canonical, energy
