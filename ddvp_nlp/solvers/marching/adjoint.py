"""Reverse mode of a march's derivatives (issue 47), the sweep ``gradient(sol, cotangent)``
(``gradient.py``) and ``march(..., derivatives=DerivativeOptions(mode="reverse"))`` run.

For a scalar ``L = sum_i c_i . z(T_i)`` of the states at the output times ``t_eval``, the
gradient ``dL/d(q0, p0, theta)`` by one discrete adjoint sweep backwards over the accepted steps:
the transpose of the forward chain (``derivatives.py``). Forward carries ``Y_k = [S_{k-1};
S_k]`` (``S_k = d(z_k, t_k)/d(inputs)``) by the affine step maps ``Y_{k+1} = M_k Y_k + N_k
dtheta`` from ``Y_0 = [0; (dz_0, 0)]``, and reads ``dz(T_i) = P_a S_a + P_b S_b + R dtheta`` at
the nodes ``a``, ``b`` of ``T_i``'s interval. Its transpose, for the adjoint ``l_k`` of
``Y_k``::

    l_last = [0; e_last],   l_k = M_k^T l_{k+1} + [0; e_k],   g_theta = sum_k N_k^T l_{k+1}
                                                                      + sum_i R_i^T c_i,
    g_(q0, p0) = the z-rows of l_0's second half,

where ``e_k = sum_i (P_a^T c_i [k = a_i] + P_b^T c_i [k = b_i])`` injects the cotangents at the
nodes the outputs read. Step lengths are included as in forward mode (the energy row's
``dtau_k``, ``t_{k+1} = t_k + tau_k``).

Checkpointing: the step maps depend only on the nodes ``(t_k, z_k)``, which the solution keeps
(every accepted node: the march's own memory); nothing of the forward chain is stored. The sweep
walks the steps backwards ``CHUNK`` at a time, evaluating that chunk's Jacobians again (mapped
CasADi calls) and dropping them after, so its own memory is that of one chunk whatever the
march's length. Inside a chunk the maps of ``BLOCK`` consecutive steps are composed for all
blocks at once, and the adjoint crosses a block in one product (a block where an output reads
an interior node is crossed step by step). Many cotangents (the columns of ``cotangent``'s last
axis) share the Jacobians and the compositions.

What a gradient is of, and what it refuses, are those of forward mode: the discrete solution at
fixed times; a march kept thinned, run backwards, with replaced (least-squares) steps or with
a ``target_error`` pilot is refused by name (`check_solution`).
"""

from __future__ import annotations

import numpy as np

from ...discrete.scheme import Scheme
from ...errors import InputError
from .derivatives import BLOCK, CHUNK, affine_maps, in_blocks, readout

__all__ = ["check_cotangent", "check_solution", "reverse_derivatives", "reverse_sweep"]

# Cotangent columns swept together (bounds the injected adjoints' memory: 2 M (2n + 1) of them).
COLUMNS = 256


def check_solution(sol, *, needs_times: bool = True) -> None:
    """Refuse by name a solution whose derivative is not the chain of its kept nodes (and,
    ``needs_times``, one without ``t_eval``)."""
    from ...solution import Solution
    if not isinstance(sol, Solution):
        raise InputError(f"sol must be a Solution of march, solve_bvp or solve_periodic, got "
                         f"{type(sol).__name__}")
    record = sol.march
    if record is None or sol.system is None:
        raise InputError("gradient needs a Solution of march (its nodes, system and "
                         "parameters), solve_bvp or solve_periodic; this one is of another "
                         "solver")
    if needs_times and sol.t_eval is None:
        raise InputError("gradient is of the states at fixed times: march with "
                         "output=Output(t_eval=...)")
    refusals = (
        (record.backward, "a backward march (t_end < t0)"),
        (record.kept is not None, f"a thinned march (kept: {record.kept.get('keep_every')!r} "
                                  f"every, keep={record.kept.get('keep')!r})"
         if isinstance(record.kept, dict) else "a thinned march"),
        (bool(record.least_squares), f"replaced (least-squares) steps "
                                     f"({len(record.least_squares)} of them)"),
        (record.target_error is not None, "target_error (its first step is chosen by a pilot "
                                          "march)"))
    for refused, what in refusals:
        if refused:
            raise InputError(f"gradient is not supported for {what}")


def check_cotangent(cotangent, count: int, n2: int) -> np.ndarray:
    """``cotangent`` as a finite ``(count, n2)`` float array (``count`` output times reached),
    or an ``InputError`` naming its shape or its first bad entry."""
    try:
        value = np.asarray(cotangent, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"cotangent must be an array of real numbers of shape ({count}, "
                         f"{n2}), got {cotangent!r:.80}") from None
    if value.shape != (count, n2):
        raise InputError(f"cotangent must have shape (len(sol.t_eval), 2n) = ({count}, {n2}), "
                         f"got {value.shape}")
    bad = np.argwhere(~np.isfinite(value))
    if bad.size:
        i, j = bad[0]
        raise InputError(f"cotangent must be finite, got {float(value[i, j])!r} at [{i}, {j}]")
    return value


def reverse_derivatives(system, scheme, theta, t, z, t_eval, names, *,
                        frozen_steps: bool = False) -> dict[str, np.ndarray]:
    """The derivatives forward mode gives (``march_derivatives``), by reverse sweeps: one
    cotangent column per output entry ``(i, row)``, ``COLUMNS`` of them per sweep."""
    n2 = z.shape[1]
    n, m = n2 // 2, np.size(theta)
    t_eval = np.asarray(t_eval, float).ravel()
    count = t_eval.size * n2
    rows_z, rows_theta = np.zeros((n2, count)), np.zeros((m, count))
    for first in range(0, count, COLUMNS):
        width = min(COLUMNS, count - first)
        c = np.zeros((t_eval.size * n2, width))
        c[first + np.arange(width), np.arange(width)] = 1.0
        g_z, g_theta = reverse_sweep(system, scheme, theta, t, z, t_eval,
                                     c.reshape(t_eval.size, n2, width),
                                     frozen_steps=frozen_steps)
        rows_z[:, first:first + width], rows_theta[:, first:first + width] = g_z, g_theta
    jacobian_z = rows_z.T.reshape(t_eval.size, n2, n2)
    jacobian_theta = rows_theta.T.reshape(t_eval.size, n2, m)
    found = {"q0": jacobian_z[:, :, :n], "p0": jacobian_z[:, :, n:], "params": jacobian_theta}
    return {name: found[name].copy() for name in names}


def reverse_sweep(system, scheme, theta, t, z, t_eval, cotangent, *,
                  frozen_steps: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``(g_z0 (2n, P), g_theta (m, P))`` for the ``P`` cotangents ``cotangent`` ``(M, 2n, P)``
    at the output times ``t_eval`` (``M``, within the nodes ``t``) of the march whose nodes are
    ``t``, ``z`` (module docstring)."""
    scheme = Scheme.coerce(scheme)
    theta = np.asarray(theta, float).ravel()
    n2, m, P = z.shape[1], theta.size, cotangent.shape[2]
    r = n2 + 1
    if t_eval.size == 0:
        return np.zeros((n2, P)), np.zeros((m, P))
    if t.size < 2:  # every output is the start itself
        return cotangent.sum(axis=0), np.zeros((m, P))
    interval = np.clip(np.searchsorted(t, t_eval, side="right") - 1, 0, t.size - 2)
    P_a, P_b, R = readout(system, theta, t, z, t_eval, interval)
    inject: dict[int, np.ndarray] = {}
    for i, k in enumerate(interval.tolist()):
        for node, P_node in ((k, P_a[i]), (k + 1, P_b[i])):
            inject[node] = inject.get(node, 0.0) + P_node.T @ cotangent[i]
    g_theta = np.einsum("imj,imp->jp", R, cotangent)
    last = max(inject)
    adjoint = np.zeros((2 * r, P))
    adjoint[r:] = inject[last]
    energy = scheme.variable_steps and not frozen_steps
    for start in reversed(range(0, last, CHUNK)):
        steps = np.arange(start, min(start + CHUNK, last))
        M, N = affine_maps(system, scheme, theta, t, z, steps, np.eye(m), energy)
        adjoint, g_theta = _scan_back(M, N, adjoint, g_theta, start, inject)
    return adjoint[r:r + n2], g_theta


def _scan_back(M, N, adjoint, g_theta, start: int, inject: dict):
    """The adjoint from the chunk's last node back to its first (node ``start``), ``g_theta``
    with the chunk's share: blocks of ``BLOCK`` steps composed (all at once), then crossed
    from the last, step by step where a cotangent enters at an interior node."""
    K, r = M.shape[0], M.shape[1] // 2
    M, N, count = in_blocks(M, N)
    inside = {node - start for node in inject if start < node < start + K}
    plain = [b for b in range(count)
             if not any(b * BLOCK < j < (b + 1) * BLOCK for j in inside)]
    whole_M, whole_N = M[plain, 0], N[plain, 0]
    for j in range(1, BLOCK):
        whole_M, whole_N = M[plain, j] @ whole_M, M[plain, j] @ whole_N + N[plain, j]
    composed = {b: i for i, b in enumerate(plain)}
    for b in reversed(range(count)):
        if b in composed:
            i = composed[b]
            g_theta = g_theta + whole_N[i].T @ adjoint
            adjoint = whole_M[i].T @ adjoint
        else:
            for j in reversed(range(BLOCK)):
                g_theta = g_theta + N[b, j].T @ adjoint
                adjoint = M[b, j].T @ adjoint
                if j and b * BLOCK + j in inside:
                    adjoint[r:] += inject[start + b * BLOCK + j]
        if start + b * BLOCK in inject:  # the block's first node (the chunk's, for b = 0)
            adjoint[r:] += inject[start + b * BLOCK]
    return adjoint, g_theta
