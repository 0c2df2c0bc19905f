"""Every equation of a returned grid, recomputed in compiled code.

``discrete.equations.grid_residuals`` (the canonical equations of every interval, the energy
equation at every inner node, unscaled), from the same CasADi functions, its blocks of
``BLOCK`` intervals one compiled function each (`recheck_block`: the nodes go in once, the
shifted columns are taken in C), called through numpy buffers: on CasADi's virtual machine the
recheck cost 2-3 us per node, more than the compiled march itself. Without a compiler it is
``grid_residuals`` with its mapped functions.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ...cache import cached
from ...discrete import equations
from ..compiler import (
    CompileUnavailable,
    FunctionBuffer,
    cache_folder,
    compile_function,
    warn_once,
)

BLOCK = 1024


# Nodes per piece whose equations are written out together with common subexpressions merged:
# the canonical equations of interval k and the energy equations at nodes k and k + 1 share the
# interval's midpoint terms and clock factors, computed once instead of up to three times. Per
# node, side by side against separate mapped functions: paper's example 0.18 -> 0.05 us,
# Henon-Heiles 0.08 -> 0.05, fpu 0.19 -> 0.10 (pieces of 8; 16 and 32 no faster, longer to
# compile). Past WIDE_PIECE degrees of freedom a piece is one interval: the 64-mass chain's
# recheck of 8-interval pieces was 494 kB of C and 14 s of gcc, more than its march's chunk.
PIECE = 8
WIDE_PIECE = 6


def piece_size(n: int) -> int:
    """Intervals per piece for ``n`` degrees of freedom (`PIECE`, or 1 past ``WIDE_PIECE``)."""
    return PIECE if n <= WIDE_PIECE else 1


def _piece(system, scheme) -> ca.Function:
    """``(T (P + 2), Z (2n x P + 2), theta) -> (canonical (2n x P), energy (1 x P))`` for
    ``P = piece_size(n)`` intervals, as one SX function with merged subexpressions: the same
    operations on the same operands as separate calls (merging only shares identical ones),
    so the same bits."""
    n = system.n
    size = piece_size(n)
    T = ca.SX.sym("T", 1, size + 2)
    Z = ca.SX.sym("Z", 2 * n, size + 2)
    theta = ca.SX.sym("theta", system.theta.numel())
    canonical_f = equations.canonical_function(system, scheme)
    energy_f = equations.energy_function(system, scheme)
    canonical, energy = [], []
    for k in range(size):
        t0, t1, t2 = T[0, k], T[0, k + 1], T[0, k + 2]
        (q0, p0), (q1, p1), (q2, p2) = ((Z[:n, j], Z[n:, j]) for j in (k, k + 1, k + 2))
        canonical.append(canonical_f(t0, t1, q0, p0, q1, p1, theta))
        energy.append(energy_f(t0, t1, t2, q0, p0, q1, p1, q2, p2, theta))
    return ca.Function("recheck_piece", [T, Z, theta],
                       [ca.horzcat(*canonical), ca.horzcat(*energy)], {"cse": True})


def recheck_block(system, scheme) -> ca.Function:
    """``(T (BLOCK + 2), Z (2n x BLOCK + 2), theta) -> (canonical (2n x BLOCK), energy
    (1 x BLOCK))``: the canonical residuals of the intervals from the first ``BLOCK`` nodes of
    ``T, Z`` and the energy residuals at the ``BLOCK`` nodes after the first, computed in pieces
    (`_piece`: the same bits as the separate mapped functions); one compiled call per block,
    the shifts done in C rather than as copies in numpy."""
    n = system.n
    T = ca.MX.sym("T", 1, BLOCK + 2)
    Z = ca.MX.sym("Z", 2 * n, BLOCK + 2)
    theta = ca.MX.sym("theta", system.theta.numel())
    piece, size = _piece(system, scheme), piece_size(n)
    if size == 1:  # one interval a call: a loop over three shifted views, not BLOCK calls
        theta_k = ca.SX.sym("theta", system.theta.numel())
        shifted = [ca.SX.sym(f"{name}{j}", rows) for name, rows in (("t", 1), ("z", 2 * n))
                   for j in range(3)]
        one = ca.Function("recheck_interval", [*shifted, theta_k],
                          piece(ca.horzcat(*shifted[:3]), ca.horzcat(*shifted[3:]), theta_k))
        mapped = one.map("recheck_intervals", "serial", BLOCK, [6], [])
        c, e = mapped(*(T[:, j:j + BLOCK] for j in range(3)),
                      *(Z[:, j:j + BLOCK] for j in range(3)), theta)
        return ca.Function("recheck_block", [T, Z, theta], [c, e])
    canonical, energy = [], []
    for start in range(0, BLOCK, size):
        c, e = piece(T[:, start:start + size + 2], Z[:, start:start + size + 2], theta)
        canonical.append(c)
        energy.append(e)
    return ca.Function("recheck_block", [T, Z, theta],
                       [ca.horzcat(*canonical), ca.horzcat(*energy)])


def _block(system, scheme, compiler, cache_dir):
    """The compiled `recheck_block` (cached)."""
    def build():
        function = compile_function(recheck_block(system, scheme), compiler,
                                    cache_folder(cache_dir), prefix="recheck")
        return FunctionBuffer(function)
    return cached(system, ("recheck_block", scheme, compiler, str(cache_dir)), build)


def recheck_residuals(system, scheme, t, q, p, theta, *, compiler=None, cache_dir=None):
    """``discrete.equations.grid_residuals`` (canonical residuals ``(N-1, 2n)``, energy
    residuals ``(N-2,)``), its blocks the compiled `recheck_block` when there is a compiler."""
    if compiler is None or np.size(t) < 3:
        return equations.grid_residuals(system, scheme, t, q, p, theta)
    try:
        block = _block(system, scheme, compiler, cache_dir)
    except CompileUnavailable as reason:  # the virtual machine gives the same residuals
        warn_once(reason)
        return equations.grid_residuals(system, scheme, t, q, p, theta)
    block.inputs[2][:] = np.asarray(theta, float)  # kept for every block
    return equations.grid_residuals(system, scheme, t, q, p, theta,
                                    block=lambda T, Z: block(T, Z, None), block_width=BLOCK)
