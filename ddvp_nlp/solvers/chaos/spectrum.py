"""The full Lyapunov spectrum on the fixed-level map, with the trivial pair apart.

For autonomous ``H`` a march step of an energy rule, at the discrete level ``E`` the first step
sets, is a map ``Phi_E: z_k -> z_{k+1}`` of ``R^2n`` (``tangent.py``, observation ``level``),
and it is symplectic (the discrete Floquet monodromy of a periodic orbit is a product of its
tangents). ``2n`` tangent vectors are carried by the compiled chunk and orthonormalised after
every step by modified Gram-Schmidt in their order (no pivoting); with ``ell_{k,j} = ln R_jj``
of step ``k``, ``lambda_j = sum_k ell_{k,j} / (t_N - t_1)``.

The frame at node 1 is a *symplectic flag*: ``[v_1, ..., v_n, J v_n, ..., J v_1]`` with
``v_1 .. v_n`` orthonormal, each orthogonal to the ``v_i`` and ``J v_i`` before it (so the frame
is orthogonal and symplectic), ``v_n = f(z_1) / |f(z_1)|``. A symplectic map carries the flag
``span(v_1) < span(v_1, v_2) < ...`` and its symplectic complements to the same structure, so
the QR factor of every product is symplectic upper triangular and
``R_jj R_{2n+1-j, 2n+1-j} = 1``: the exponents pair, ``lambda_j + lambda_{2n+1-j} = 0``, at
every ``t`` and to round-off, without any re-imposed invariance (measured: pair sums below
1e-10 on Henon-Heiles, docs/chaos/README.md). Without the flag order (any other orthonormal
frame) the pairs hold only as ``t -> infinity``.

The middle pair, columns ``n`` and ``n + 1`` (``f`` and ``J f``, i.e. ``-grad H``), is the
*trivial pair*: the discrete image of (the flow direction, the energy), for the level map the
phase along the orbit and the step-size scale, a shear whose exponents decay like ``1/t`` (a
Jordan block). ``f`` is not an invariant direction of ``Phi_E`` (only to ``O(tau^2)``), so it
comes after the other ``v``: Gram-Schmidt gives the growing directions to the columns before
it and leaves it the neutral rest (with ``f`` first, its column took the largest exponent:
measured). The outer ``2n - 2`` columns are the *reduced* spectrum (for ``n = 2`` the pair
``(lambda, -lambda)`` of the Poincare map).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ...solution import Status
from .tangent_march import TangentMarch


def symplectic_flag(field: np.ndarray) -> np.ndarray:
    """The frame ``[u_2, ..., u_n, u_1, J u_1, J u_n, ..., J u_2]`` (``2n x 2n``, orthogonal
    and symplectic) with ``u_1`` along ``field`` (module docstring)."""
    k = field.size
    n = k // 2
    J = np.block([[np.zeros((n, n)), np.eye(n)], [-np.eye(n), np.zeros((n, n))]])
    u = [field / np.linalg.norm(field)]
    taken = [u[0], J @ u[0]]
    for e in np.eye(k):
        if len(u) == n:
            break
        v = e.copy()
        for _ in range(2):  # twice: orthogonal to round-off
            for b in taken:
                v -= (b @ v) * b
        if np.linalg.norm(v) > 0.1:
            v /= np.linalg.norm(v)
            u.append(v)
            taken += [v, J @ v]
    u = u[1:] + u[:1]  # the field's direction last among the u: the middle pair
    return np.column_stack(u + [J @ v for v in reversed(u)])


@dataclass
class Spectrum:
    """The exponents of the fixed-level map, per unit time, in the frame's column order.

    Attributes:
        exponents: ``(2n,)``; ``trivial``: the pair of the flow direction and the energy
            (for the level map the middle columns, for the exact flow the first and last);
            ``reduced``: the others, in column order.
        pair_sums: ``lambda_j + lambda_{2n+1-j}`` for ``j = 1..n`` (zero for a symplectic map).
        t: the last node's time; ``steps``, ``status``, ``message`` as for the march;
        ``seconds``: CPU seconds.
    """

    exponents: np.ndarray
    reduced: np.ndarray
    trivial: np.ndarray
    pair_sums: np.ndarray
    t: float
    steps: int
    status: Status
    message: str
    seconds: float = 0.0


def lyapunov_spectrum(system, q0, p0, t_span, *, tau0: float, scheme="vddvp", params=None,
                      steps=None, compilation=None) -> Spectrum:
    """The Lyapunov spectrum of the march from ``(q0, p0)`` on its fixed-level map (module
    docstring): ``2n`` vectors in the compiled chunk from the symplectic flag at node 1. The
    arguments are `march`'s (an energy rule, autonomous ``H``).

    Returns:
        `Spectrum`; a failed step is a status on it (the exponents up to its last node).
    """
    started = time.process_time()
    n = system.n
    run = TangentMarch.build(system, q0, p0, t_span, tau0=tau0, scheme=scheme, params=params,
                             steps=steps, compilation=compilation, vectors=2 * n,
                             observation="level")
    p = run.problem
    total, t_last, count = np.zeros(2 * n), p.t0, 0
    start, failure = run.first_step()
    t1 = p.t0
    if failure is None:
        t1, _, z1 = start
        field = np.asarray(run.chunk.tangent.field(z1, t1, p.theta)).ravel()
        # orthonormal and symplectic in the weighted coordinates (W dz: the norm the chunk
        # measures in, itself a symplectic scaling), carried in the march's own
        frame = symplectic_flag(run.weights * field) / run.weights[:, None]
        X1 = np.vstack([np.zeros((2, 2 * n)), -frame, frame])
        chunks = run.chunks(start, X1)
        t_last = t1
        while True:
            try:
                columns, kept = next(chunks)
            except StopIteration as end:
                status, message = end.value
                break
            total += columns["ell"][:kept].sum(axis=0)
            t_last, count = float(columns["t_next"][kept - 1]), count + kept
    else:
        status, message = failure
    span = t_last - t1
    exponents = total / span if span > 0 else np.full(2 * n, np.nan)
    middle = [n - 1, n]
    return Spectrum(exponents=exponents, trivial=exponents[middle],
                    reduced=np.delete(exponents, middle),
                    pair_sums=exponents[:n] + exponents[::-1][:n], t=t_last, steps=count + 1,
                    status=status, message=message, seconds=time.process_time() - started)
