"""Every equation of a returned grid, recomputed in compiled code.

The same residuals as ``discrete.equations.grid_residuals`` (the canonical equations of every
interval, the energy equation at every inner node, unscaled), from the same CasADi functions,
mapped over blocks of ``BLOCK`` intervals in one compiled function per block (the nodes go in
once, the shifted columns are taken in C), called through numpy buffers: on CasADi's virtual
machine the recheck cost 2-3 us per node, more than the compiled march itself.
Without a compiler it is ``grid_residuals`` itself.
"""

from __future__ import annotations

import casadi as ca
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


def recheck_block(system, scheme) -> ca.Function:
    """``(T (BLOCK + 2), Z (2n x BLOCK + 2), theta) -> (canonical (2n x BLOCK), energy
    (1 x BLOCK))``: the canonical residuals of the intervals from the first ``BLOCK`` nodes of
    ``T, Z`` and the energy residuals at the ``BLOCK`` nodes after the first, each by the same
    function mapped over the shifted columns (so the same bits as separate mapped calls); one
    compiled call per block, the shifts done in C rather than as copies in numpy."""
    n = system.n
    T = ca.MX.sym("T", 1, BLOCK + 2)
    Z = ca.MX.sym("Z", 2 * n, BLOCK + 2)
    theta = ca.MX.sym("theta", system.theta.numel())
    q = [Z[:n, i:i + BLOCK] for i in range(3)]
    p = [Z[n:, i:i + BLOCK] for i in range(3)]
    t = [T[:, i:i + BLOCK] for i in range(3)]
    canonical = equations.canonical_function(system, scheme).map(BLOCK)(
        t[0], t[1], q[0], p[0], q[1], p[1], theta)
    energy = equations.energy_function(system, scheme).map(BLOCK)(
        t[0], t[1], t[2], q[0], p[0], q[1], p[1], q[2], p[2], theta)
    return ca.Function("recheck_block", [T, Z, theta], [canonical, energy])


def _block(system, scheme, compiler, cache_dir):
    """The compiled :func:`recheck_block` (cached)."""
    def build():
        function = compile_function(recheck_block(system, scheme), compiler,
                                    cache_folder(cache_dir), prefix="recheck")
        return FunctionBuffer(function)
    return cached(system, ("recheck_block", scheme, compiler, str(cache_dir)), build)


def grid_residuals(system, scheme, t, q, p, theta, *, compiler=None, cache_dir=None):
    """Canonical residuals ``(N-1, 2n)`` and energy residuals ``(N-2,)``, as
    ``discrete.equations.grid_residuals`` returns them."""
    if compiler is None or np.size(t) < 3:
        return equations.grid_residuals(system, scheme, t, q, p, theta)
    try:
        block = _block(system, scheme, compiler, cache_dir)
    except CompileUnavailable as reason:  # the virtual machine gives the same residuals
        warn_once(reason)
        return equations.grid_residuals(system, scheme, t, q, p, theta)
    t = np.asarray(t, float)
    z = np.column_stack([np.asarray(q, float).reshape(t.size, -1),
                         np.asarray(p, float).reshape(t.size, -1)])
    N = t.size
    canonical = np.empty((N - 1, 2 * system.n))
    energy = np.empty(N - 2)
    theta = np.asarray(theta, float)
    first = True
    for start in range(0, N - 1, BLOCK):
        stop = min(start + BLOCK + 2, N)
        if stop - start == BLOCK + 2:
            T, Z = t[start:stop], z[start:stop]
        else:  # the last block: the last node repeated (its residuals are not kept)
            T = np.pad(t[start:stop], (0, BLOCK + 2 - (stop - start)), mode="edge")
            Z = np.pad(z[start:stop], [(0, BLOCK + 2 - (stop - start)), (0, 0)], mode="edge")
        out_canonical, out_energy = block(T, Z, theta if first else None)
        first = False
        rows = min(BLOCK, N - 1 - start)
        canonical[start:start + rows] = out_canonical[:rows]
        rows = min(BLOCK, N - 2 - start)
        if rows > 0:
            energy[start:start + rows] = out_energy[:rows, 0]
    return canonical, energy
