"""The step of RATTLE and SHAKE for a separable ``H = T(p) + V(q, t)`` on holonomic constraints
``g(q, t) = 0`` (``system.G``, ``k`` of them; Hairer, Lubich and Wanner, *Geometric Numerical
Integration*, VII.1), run by ``solvers/baselines/rattle.py``.

RATTLE (Andersen 1983), order 2, symplectic on the constraint manifold::

    p_h     = p_k - tau/2 (V_q(q_k, t_k) + G_q(q_k, t_k)^T lambda)
    q_{k+1} = q_k + tau T_p(p_h),                 g(q_{k+1}, t_{k+1}) = 0
    p_{k+1} = p_h - tau/2 (V_q(q_{k+1}, t_{k+1}) + G_q(q_{k+1}, t_{k+1})^T mu)
    G_q(q_{k+1}, t_{k+1}) T_p(p_{k+1}) + g_t(q_{k+1}, t_{k+1}) = 0

SHAKE (Ryckaert, Ciccotti and Berendsen 1977) in one-step form: the first two lines alone (the
position constraint only), ``p_{k+1} = p_h - tau/2 V_q(q_{k+1}, t_{k+1})``; its positions are
those of the two-step SHAKE ``q_{k+1} - 2 q_k + q_{k-1} = -tau^2 T_pp (V_q + G_q^T lambda)``,
its node momenta carry no projection onto the hidden constraint.

RATTLE solves each constraint system by Newton (the Jacobian at every iterate, from
``lambda = mu = 0``); SHAKE by its classical iteration, Newton with the Jacobian of the step's
start ``-tau^2/2 G_q(q_k) T_pp G_q(q_k)^T`` (linear convergence, rate about ``tau |v|`` over
the constraint's length, so the residual it stops at follows ``tol``). Each iterates while its
residual passes ``tol`` (``|g|_inf`` for the position constraint, ``tau |hidden|_inf`` for the
momentum constraint: both in the units of ``g``), at most ``ITERATIONS`` times (SHAKE
``SHAKE_FACTOR`` times that), unrolled in the step's CasADi expression.
"""

from __future__ import annotations

import casadi as ca

from ..cache import cached
from ..errors import InputError
from ..physics.hamiltonian import HamiltonianSystem, separable_parts

ITERATIONS = 12  # Newton iterations per solve at most (quadratic: 4-5 reach round-off)
SHAKE_FACTOR = 4  # SHAKE's iteration converges linearly (rate about tau |v| / length)
METHODS = ("rattle", "shake")


def constrained_separable(system: HamiltonianSystem, method: str):
    """``(T_p, V_q)`` of a separable ``H`` with constraints, or a named error."""
    if method not in METHODS:
        raise InputError(f"method must be one of {METHODS}, got {method!r}")
    if getattr(system, "n_constraints", 0) < 1 or getattr(system, "G", None) is None:
        raise InputError(f"{method} needs a system with holonomic constraints; "
                         f"{system.name!r} has none")
    parts = separable_parts(system)
    if isinstance(parts, str):
        raise InputError(f"{method} needs a separable H = T(p) + V(q, t): {parts}")
    return parts


def _newton(residual, jacobian, unknown, tol, iterations):
    """``unknown`` after at most ``iterations`` masked Newton steps on ``residual(x) = 0``
    (a step is taken only while ``|residual|_inf > tol``); the steps taken."""
    taken = ca.SX(0)
    for _ in range(iterations):
        r = residual(unknown)
        going = ca.mmax(ca.fabs(r)) > tol
        unknown = ca.if_else(going, unknown - ca.solve(jacobian(unknown), r), unknown)
        taken = taken + going
    return unknown, taken


def rattle_step(system: HamiltonianSystem, method: str = "rattle",
                iterations: int = ITERATIONS) -> ca.Function:
    """``(z, t, tau, theta, tol) -> (z_next, residual, newton)``: one step of ``method``
    (module docstring); ``residual`` the step's constraint residual after the solves
    (``max(|g|_inf, tau |hidden|_inf)`` for RATTLE, ``|g|_inf`` for SHAKE), ``newton`` the
    Newton iterations taken."""
    T_p, V_q = constrained_separable(system, method)

    def build():
        n, theta = system.n, system.theta
        q_s, p_s, t_s = system.q, system.p, system.t
        G = ca.vec(system.G)
        g = ca.Function("g", [q_s, t_s, theta], [G])
        Gq = ca.Function("G_q", [q_s, t_s, theta], [ca.jacobian(G, q_s)])
        gt = ca.Function("g_t", [q_s, t_s, theta], [ca.jacobian(G, t_s)])
        Tpp = ca.Function("T_pp", [p_s, theta], [ca.jacobian(T_p(p_s, theta), p_s)])
        z, t, tau, tol = ca.SX.sym("z", 2 * n), ca.SX.sym("t"), ca.SX.sym("tau"), ca.SX.sym("tol")
        q, p = z[:n], z[n:]
        t1 = t + tau
        G0 = Gq(q, t, theta)
        kick = p - tau / 2 * V_q(q, t, theta)

        def half(lam):
            return kick - tau / 2 * ca.mtimes(G0.T, lam)

        def position(lam):
            return q + tau * T_p(half(lam), theta)

        def jac_position(lam):
            if method == "shake":  # the classical SHAKE matrix: gradients of the start
                return -tau ** 2 / 2 * ca.mtimes([G0, Tpp(kick, theta), G0.T])
            return -tau ** 2 / 2 * ca.mtimes([Gq(position(lam), t1, theta),
                                               Tpp(half(lam), theta), G0.T])

        k = G.numel()
        lam, taken = _newton(lambda lam: g(position(lam), t1, theta), jac_position,
                             ca.SX.zeros(k), tol,
                             iterations * (SHAKE_FACTOR if method == "shake" else 1))
        q1, p_half = position(lam), half(lam)
        kicked = p_half - tau / 2 * V_q(q1, t1, theta)
        p_end = kicked
        residual = ca.mmax(ca.fabs(g(q1, t1, theta)))
        if method == "rattle":
            G1 = Gq(q1, t1, theta)

            def momentum(mu):
                return kicked - tau / 2 * ca.mtimes(G1.T, mu)

            def hidden(mu):
                return tau * (ca.mtimes(G1, T_p(momentum(mu), theta)) + gt(q1, t1, theta))

            def jac_hidden(mu):
                return -tau ** 2 / 2 * ca.mtimes([G1, Tpp(momentum(mu), theta), G1.T])

            mu, more = _newton(hidden, jac_hidden, ca.SX.zeros(k), tol, iterations)
            p_end, taken = momentum(mu), taken + more
            residual = ca.fmax(residual, ca.mmax(ca.fabs(hidden(mu))))
        return ca.Function(f"{method}_step", [z, t, tau, theta, tol],
                           [ca.vertcat(q1, p_end), residual, taken],
                           ["z", "t", "tau", "theta", "tol"],
                           ["z_next", "residual", "newton"], {"cse": True})
    return cached(system, (f"{method}_step", int(iterations)), build)
