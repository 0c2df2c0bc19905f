"""Linear stability of a periodic orbit of a constrained system, on the constrained exact flow
(``periodic_stability`` hands a constrained system here and analyses the monodromy as any
other, ``floquet.analyse``; docs/periodic/constrained.md).

**The manifold.** The motion lives on ``g = 0``, ``h = G H_p = 0``: ``d = 2n - 2m``
dimensions, a symplectic submanifold of ``(q, p)`` (the constraints are second class: the
brackets ``{g_i, h_j} = (G H_pp G^T)_ij`` are nonsingular). The ambient monodromy
(``2n x 2n``) of the index-reduced flow has ``2m`` more multipliers 1 from the directions off
the manifold (``g`` and ``h`` are invariants of the index-reduced flow, ``g`` growing linearly
with ``h``): they say nothing about the orbit and are not computed. The monodromy is taken on
the tangent space instead, in a symplectic basis ``S`` of it (``S^T J S = J_d``, by the
symplectic Gram-Schmidt process on an orthonormal basis of the kernel of ``d(g, h)/dz``):
``M = L dPhi_T S`` with ``L = -J_d S^T J`` (``L S = I``), a ``d x d`` symplectic matrix.

**The trivial multipliers** on the manifold: the pair of the flow direction ``f(z_0)``
(fixed) and the energy (its dual), as for an unconstrained orbit; and a pair for each first
integral given whose symmetry is not the orbit's own motion. The spherical pendulum's conical
orbit (``d = 4``) has the trivial pair and one nontrivial pair ``exp(+-i Omega T)``, the
oscillation of the polar angle about the cone.

**The exact orbit.** The discrete orbit's node 0 is not on an exact periodic orbit; the exact
one near it is found first by Gauss-Newton in the tangent coordinates (``z = P(z_c + B a)``,
``P`` the projection onto the manifold) and the period: rows ``B^T (Phi_T(z) - z)``,
``H(z) - E`` and the section, least squares (the closure has one dependent row, the energy),
derivatives by central differences of the exact flow (DOP853 at ``rtol = 1e-12``, projected
in each step). Then ``dPhi_T S`` by central differences of the flow from projected points:
the projection's second-order terms cancel; the error of ``M`` is about ``rtol / EPSILON``.
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from ...solution import Solution
from ..exact.constrained_flow import constrained_field, projection_function
from ..exact.flow import exact_flow
from .closed_grid import integral_gradients
from .orbit import parse_section

RTOL = 1e-12
EPSILON = 1e-6  # the central differences' step, relative to the state's size
CLOSING_ITERATIONS = 12


def constrained_monodromy(system, orbit: Solution, *, params=None, integrals=()):
    """``(M, fixed, extra)``: the monodromy on the constraint manifold of the exact periodic
    orbit nearest a constrained orbit that `solve_periodic` found, in a symplectic basis
    (module docstring), its fixed directions as columns (the flow, then the generators of
    ``integrals``), and ``extra``: the exact orbit's period, closure, distance from node 0, the
    manifold's dimension. ``floquet.periodic_stability`` analyses them."""
    if not isinstance(orbit, Solution) or orbit.orbit is None:
        raise InputError("orbit must be a periodic orbit returned by solve_periodic")
    if not orbit.success:
        raise InputError(f"orbit: a failed solve has no monodromy to trust ({orbit.status.code}:"
                         f" {orbit.message[:120]})")
    theta = system.parameter_vector(params)
    index, value, _ = parse_section(orbit.orbit.section, system.n)
    z0 = np.concatenate([orbit.q[0], orbit.p[0]])
    flow = exact_flow(system)
    closed, period, closure = _closed(system, flow, theta, z0, float(orbit.orbit.period),
                                      float(orbit.orbit.energy), index - 1, value)
    S = _symplectic_basis(_tangent_basis(system, theta, closed))
    d = S.shape[1]
    J, J_d = _form(2 * system.n), _form(d)
    L = -J_d @ S.T @ J
    step = EPSILON * float(np.max(np.abs(closed)))
    columns = [(_flow_end(system, flow, theta, closed + step * S[:, i], period)
                - _flow_end(system, flow, theta, closed - step * S[:, i], period)) / (2 * step)
               for i in range(d)]
    M = L @ np.column_stack(columns)
    fixed = [L @ np.asarray(constrained_field(system)(closed, 0.0, theta), float).ravel()]
    if integrals:
        n = system.n
        gradients = np.asarray(integral_gradients(system, tuple(integrals))(
            closed[:n], closed[n:], theta))[:, 1:]
        fixed += [L @ np.concatenate([g[n:], -g[:n]]) for g in gradients.T]
    return M, np.column_stack(fixed), {
        "exact_period": period, "exact_closure": closure,
        "distance_from_node_0": float(np.max(np.abs(closed - z0))),
        "manifold_dimension": d, "monodromy_norm": float(np.linalg.norm(M, 2))}


def _form(k: int) -> np.ndarray:
    n = k // 2
    return np.block([[np.zeros((n, n)), np.eye(n)], [-np.eye(n), np.zeros((n, n))]])


def _tangent_basis(system, theta, z) -> np.ndarray:
    """An orthonormal basis (columns) of the kernel of ``d(g, h)/dz`` at ``z``."""
    import casadi as ca

    n, m = system.n, system.n_constraints
    symbol = ca.SX.sym("z", 2 * n)
    g = ca.substitute(ca.vec(system.G), system.q, symbol[:n])
    H_p = ca.substitute(ca.gradient(system.H, system.p), ca.vertcat(system.q, system.p),
                        symbol)
    h = ca.mtimes(ca.jacobian(g, symbol[:n]), H_p)
    rows = ca.Function("manifold_rows", [symbol, system.t, system.theta],
                       [ca.jacobian(ca.vertcat(g, h), symbol)])
    D = np.asarray(rows(z, 0.0, theta), float)
    _, _, Vt = np.linalg.svd(D)
    return Vt[2 * m:].T


def _symplectic_basis(B: np.ndarray) -> np.ndarray:
    """``S = [e_1 .. e_k, f_1 .. f_k]`` spanning the columns of ``B`` with ``S^T J S = J_d``
    (symplectic Gram-Schmidt, the largest pairing chosen at each stage)."""
    J = _form(B.shape[0])
    vectors, es, fs = [B[:, i] for i in range(B.shape[1])], [], []
    while vectors:
        e = vectors.pop(0)
        j = int(np.argmax([abs(e @ J @ v) for v in vectors]))
        f = vectors.pop(j)
        f = f / (e @ J @ f)
        es.append(e)
        fs.append(f)
        vectors = [v + (f @ J @ v) * e - (e @ J @ v) * f for v in vectors]
    return np.column_stack(es + fs)


def _flow_end(system, flow, theta, z, period: float) -> np.ndarray:
    """The exact flow over ``period`` from ``z`` projected onto the manifold."""
    z = np.asarray(projection_function(system)(z, 0.0, theta), float).ravel()
    size = float(np.max(np.abs(z)))
    run = flow.run(z, 0.0, period, theta, rtol=RTOL, atol=RTOL * size)
    if not run.success:
        raise InputError(f"the constrained exact flow from node 0 stopped at t = "
                         f"{run.t_reached:.6g} of the period {period:.6g}: no monodromy")
    return np.asarray(run.z_end, float)


def _closed(system, flow, theta, z0, period, energy, component, value):
    """``(z, T, closure)``: the exact periodic orbit near ``(z0, T)`` (module docstring)."""
    z = np.asarray(projection_function(system)(z0, 0.0, theta), float).ravel()
    size = float(np.max(np.abs(z)))
    B = _tangent_basis(system, theta, z)

    def point(a):
        return np.asarray(projection_function(system)(z + B @ a, 0.0, theta), float).ravel()

    def rows(a, T):
        x = point(a)
        return np.concatenate([B.T @ (_flow_end(system, flow, theta, x, T) - x),
                               [(float(system.H_function(x[:system.n], x[system.n:], 0.0,
                                                         theta)) - energy),
                                x[component] - value]])

    unknowns = np.concatenate([np.zeros(B.shape[1]), [period]])
    step = EPSILON * size
    for _ in range(CLOSING_ITERATIONS):
        F = rows(unknowns[:-1], unknowns[-1])
        if np.max(np.abs(F)) <= 1e-10 * size:
            break
        columns = []
        for i in range(unknowns.size):
            e = np.zeros(unknowns.size)
            e[i] = step
            plus, minus = unknowns + e, unknowns - e
            columns.append((rows(plus[:-1], plus[-1]) - rows(minus[:-1], minus[-1]))
                           / (2 * step))
        unknowns = unknowns - np.linalg.lstsq(np.column_stack(columns), F, rcond=None)[0]
    closure = float(np.max(np.abs(rows(unknowns[:-1], unknowns[-1]))))
    if closure > 1e-8 * size:
        raise InputError(f"orbit: the exact flow does not close near its node 0 (closure "
                         f"{closure:.2e} after {CLOSING_ITERATIONS} Gauss-Newton steps): no "
                         "exact periodic orbit to analyse nearby")
    return point(unknowns[:-1]), float(unknowns[-1]), closure


__all__ = ["constrained_monodromy"]
