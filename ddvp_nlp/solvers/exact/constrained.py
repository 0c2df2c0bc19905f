"""The exact flow of a constrained system: ``H(q, p, t)`` on the manifold ``g(q, t) = 0`` (``k``
holonomic constraints, ``system.G`` the column ``g`` in the system's symbols), the reference
every verdict on a constrained run is measured against.

**Index reduction.** With ``G_q = dg/dq`` (k x n) the motion is ``q' = H_p``,
``p' = -H_q - G_q^T lambda`` on ``g = 0`` and its hidden constraint
``h(q, p, t) = G_q H_p + g_t = 0``. Differentiating ``h`` once more along the motion,
``h_q H_p + h_p (-H_q - G_q^T lambda) + h_t = 0`` with ``h_p = G_q H_pp``, gives the
multipliers from the k x k system

    (G_q H_pp G_q^T) lambda = h_q H_p - h_p H_q + h_t

(regular while ``G_q`` has full rank and ``H_pp`` is definite on its rows): an ordinary
differential equation `constrained_field` whose solutions from a consistent start keep
``g`` and ``h`` constant, integrated by the package's one adaptive DOP853 (``attempt.py``,
``flow.py``: the same tableau, estimator, controller and dense output).

**Projection inside the error control.** Every attempted step's order-8 result is projected
onto ``g = 0`` and ``h = 0`` (`projection_function`) before its error is estimated, its next
first stage taken and its dense output built: positions by ``PROJECTION_ITERATIONS``
Gauss-Newton steps ``q <- q - G_q^T (G_q G_q^T)^-1 g`` (the orthogonal projection), then
momenta along the constraint forces, ``p <- p - G_q^T mu`` with
``(G_q H_pp G_q^T) mu = h`` (exact in one step for ``H`` quadratic in ``p``; repeated). The
accepted states sit on the manifold to round-off, so the constraint drift of the plain
index-1 equation (linear in ``t`` for ``h``, quadratic for ``g``) never builds up, and the
reference's own error is that of DOP853 at its tolerance (Hairer, Lubich and Wanner,
*Geometric Numerical Integration*, IV.4: a projection keeps the method's order).

**Its error bound** is the one of ``reference.py`` (two runs, ``rtol`` and ``rtol / 10``, their
difference as the envelope): measured on the Cartesian planar pendulum against the elliptic
solution and the spherical pendulum against its equations in angles (scipy DOP853 at rtol
1e-13): see ``docs/accuracy/constrained.md`` for the figures (the reference within
``10 rtol`` of the exact motion, its claim above the true error at every time).

The multipliers are solved symbolically (CasADi SX): meant for a few constraints (a pendulum,
a linkage, a short chain); ``k`` in the tens makes the expressions large.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ...cache import cached
from ...errors import InputError

# Unrolled Gauss-Newton steps of the projection (positions, then momenta). A step's order-8
# result is off g = 0 by about the step's error (<= 1e-6 of the size where the controller
# accepts it): two steps reach round-off for a quadratic g; three leave a margin.
PROJECTION_ITERATIONS = 3
# A start farther than this (relative to each component's scale) from g = 0, h = 0 is not a
# consistent start: the reference refuses it rather than judge a run from another point.
CONSISTENT = 1e-8


def _parts(system):
    """``(G, G_q, g_t, H_p, H_pp, h, h_q, h_p, h_t)`` in the system's symbols."""
    q, p, t = system.q, system.p, system.t
    G = ca.vec(system.G)
    Gq = ca.jacobian(G, q)
    gt = ca.jacobian(G, t)
    Hp = ca.gradient(system.H, p)
    Hpp = ca.jacobian(Hp, p)
    h = ca.mtimes(Gq, Hp) + gt
    return G, Gq, gt, Hp, Hpp, h, ca.jacobian(h, q), ca.jacobian(h, p), ca.jacobian(h, t)


def check_constrained(system) -> int:
    """``k``, the number of constraints of ``system``, checked: ``system.G`` a column of ``k``
    expressions in ``q`` (and ``t``, parameters). A named error otherwise."""
    k = getattr(system, "n_constraints", 0)
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise InputError(f"system {getattr(system, 'name', '?')!r} has no constraints "
                         f"(n_constraints = {k!r}): use the unconstrained exact flow")
    G = getattr(system, "G", None)
    if not isinstance(G, ca.SX) or G.numel() != k or min(G.shape) != 1:
        shape = None if not isinstance(G, ca.SX) else G.shape
        raise InputError(f"system {system.name!r}: G must be a CasADi SX column of "
                         f"n_constraints = {k} expressions, got {type(G).__name__} of "
                         f"shape {shape}")
    if not ca.depends_on(G, system.q):
        raise InputError(f"system {system.name!r}: the constraints g do not depend on q")
    return int(k)


def constrained_field(system) -> ca.Function:
    """``(z, t, theta) -> z'``: ``(H_p, -H_q - G_q^T lambda)``, ``lambda`` from the twice
    differentiated constraints (module docstring), built once per system."""
    check_constrained(system)

    def build():
        q, p, t = system.q, system.p, system.t
        _, Gq, _, Hp, Hpp, _, hq, hp, ht = _parts(system)
        Hq = ca.gradient(system.H, q)
        A = ca.mtimes([Gq, Hpp, Gq.T])
        rhs = ca.mtimes(hq, Hp) - ca.mtimes(hp, Hq) + ht
        lam = ca.solve(A, rhs)
        z = ca.vertcat(q, p)
        dz = ca.vertcat(Hp, -Hq - ca.mtimes(Gq.T, lam))
        return ca.Function("constrained_field", [z, t, system.theta], [dz],
                           ["z", "t", "theta"], ["dz"], {"cse": True})
    return cached(system, "constrained_field", build)


def multipliers_function(system) -> ca.Function:
    """``(z, t, theta) -> lambda``: the constraint forces' multipliers of the exact motion."""
    check_constrained(system)

    def build():
        q, p, t = system.q, system.p, system.t
        _, Gq, _, Hp, Hpp, _, hq, hp, ht = _parts(system)
        Hq = ca.gradient(system.H, q)
        lam = ca.solve(ca.mtimes([Gq, Hpp, Gq.T]),
                       ca.mtimes(hq, Hp) - ca.mtimes(hp, Hq) + ht)
        return ca.Function("multipliers", [ca.vertcat(q, p), t, system.theta], [lam],
                           ["z", "t", "theta"], ["lambda"])
    return cached(system, "constraint_multipliers", build)


def projection_function(system, iterations: int = PROJECTION_ITERATIONS) -> ca.Function:
    """``(z, t, theta) -> z``: ``z`` projected onto ``g = 0`` (Gauss-Newton, orthogonal in
    ``q``) and then onto ``h = 0`` (along ``G_q^T``), ``iterations`` unrolled steps each."""
    check_constrained(system)

    def build():
        q, p, t, theta = system.q, system.p, system.t, system.theta
        G, Gq, _, _, Hpp, h, _, _, _ = _parts(system)
        position = ca.Function("g_step", [q, t, theta],
                               [q - ca.mtimes(Gq.T, ca.solve(ca.mtimes(Gq, Gq.T), G))])
        momentum = ca.Function("h_step", [q, p, t, theta], [p - ca.mtimes(
            Gq.T, ca.solve(ca.mtimes([Gq, Hpp, Gq.T]), h))])
        z, time = ca.SX.sym("z", 2 * system.n), ca.SX.sym("t")
        theta_in = ca.SX.sym("theta", theta.numel())
        qk, pk = z[:system.n], z[system.n:]
        for _ in range(iterations):
            qk = position(qk, time, theta_in)
        for _ in range(iterations):
            pk = momentum(qk, pk, time, theta_in)
        return ca.Function("project", [z, time, theta_in], [ca.vertcat(qk, pk)],
                           ["z", "t", "theta"], ["z_projected"], {"cse": True})
    return cached(system, ("constraint_projection", int(iterations)), build)


def residuals_function(system) -> ca.Function:
    """``(z, t, theta) -> (g, h)``: the constraints and their hidden (momentum) constraint."""
    check_constrained(system)

    def build():
        G, _, _, _, _, h, _, _, _ = _parts(system)
        z = ca.vertcat(system.q, system.p)
        return ca.Function("constraint_residuals", [z, system.t, system.theta], [G, h],
                           ["z", "t", "theta"], ["g", "h"])
    return cached(system, "constraint_residuals", build)


def constraint_residuals(system, t, z, theta) -> tuple[np.ndarray, np.ndarray]:
    """``|g|_inf`` and ``|h|_inf`` at every node (``t`` (N,), ``z`` (N, 2n)), in the units of
    ``g`` and of ``dg/dt``."""
    t = np.atleast_1d(np.asarray(t, float))
    z = np.asarray(z, float).reshape(t.size, -1)
    theta = np.asarray(theta, float)
    if z.shape[1] != 2 * system.n:
        raise InputError(f"z must have 2n = {2 * system.n} columns, got {z.shape[1]}")
    if not t.size:
        return np.zeros(0), np.zeros(0)
    mapped = residuals_function(system).map(t.size)
    g, h = mapped(z.T, t[None, :], np.tile(theta[:, None], (1, t.size)))
    return np.max(np.abs(np.asarray(g)), axis=0), np.max(np.abs(np.asarray(h)), axis=0)


def check_consistent(system, z0, t0: float, theta, scale) -> np.ndarray:
    """``z0`` projected onto ``g = 0``, ``h = 0``; a named error when that moves some
    component by more than ``CONSISTENT`` of its scale (the start is not on the manifold)."""
    z0 = np.asarray(z0, float)
    scale = np.broadcast_to(np.asarray(scale, float), z0.shape)
    projected = np.asarray(projection_function(system)(z0, t0, theta)).ravel()
    moved = np.abs(projected - z0) / scale
    if not np.all(np.isfinite(projected)) or not np.max(moved) <= CONSISTENT:
        worst = int(np.nanargmax(np.where(np.isfinite(moved), moved, np.inf)))
        raise InputError(
            f"z0 = {z0.tolist()} is not a consistent start of {system.name!r}: the "
            f"projection onto g = 0 and its hidden constraint moves component {worst} by "
            f"{moved[worst]:.3g} of its scale (> {CONSISTENT:g}); project the start first")
    return projected
