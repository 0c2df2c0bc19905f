"""The discrete equations of a system with holonomic constraints ``g(q, t) = 0`` (docs/theory.md,
"Holonomic constraints"): the interval action augmented with multipliers at the nodes, in the
form of RATTLE.

Interval ``k`` joins node ``k`` and node ``k+1``. Each node carries one momentum ``p_k`` on the
constraint's cotangent manifold (``g(q_k, t_k) = 0`` and the hidden constraint
``G(q_k, t_k) H_p(q_k, p_k, t_k) + g_t(q_k, t_k) = 0``), and each interval sees its own two
momenta, the node momenta moved by half a constraint impulse::

    p_k^+     = p_k     - (tau_k / 2) G(q_k, t_k)^T         lambda_k
    p_{k+1}^- = p_{k+1} + (tau_k / 2) G(q_{k+1}, t_{k+1})^T mu_k

The interval's ``2n`` equations are those of the unconstrained form (``action.py``) on
``(q_k, p_k^+)`` and ``(q_{k+1}, p_{k+1}^-)``; the node rows at ``k+1`` are ``g = 0`` and the
hidden constraint. ``lambda_k`` (``m``) is fixed by the position constraint at ``k+1``,
``mu_k`` (``m``) by the hidden one. Between two intervals the momentum jumps by
``G^T Lambda_k`` with ``Lambda_k = -(tau_k lambda_k + tau_{k-1} mu_{k-1}) / 2``: the
stationarity of ``S_D + sum_k Lambda_k . g(q_k, t_k)`` in ``q_k``, so the positions are those
of the augmented discrete action. The energy rules read the interval energies with the
interval's own momenta (``vddvp``), or differentiate the augmented action in ``t_k``
(``lee``). Both take the node time's derivative of the multiplier term,
``Lambda_k . g_t(q_k, t_k)``: a constraint imposed at the node sees ``t_k`` directly. Where
the constraints move (``g_t != 0``: a turning hoop, a rod whose length changes) it is the work
the constraint does over the half intervals around node ``k``, ``W_k = -Lambda_k . g_t``, and
the row says ``E_k - E_{k-1} = W_k`` (`constraint_work`); for constraints fixed in time it is
zero and the ``vddvp`` row is ``E_k = E_{k-1}``.
"""

from __future__ import annotations

import casadi as ca

from ..cache import cached
from ..physics.constraints import constraint_function
from ..physics.hamiltonian import derivatives_function
from .equations import action_for
from .scheme import Scheme


def interval_momenta(system, t_a, t_b, q_a, p_a, q_b, p_b, lam, mu, theta):
    """``(p_a^+, p_b^-)``: the node momenta moved by half of each node's constraint
    impulse."""
    constraints = constraint_function(system)
    tau = t_b - t_a
    _, G_a, _ = constraints(q_a, t_a, theta)
    _, G_b, _ = constraints(q_b, t_b, theta)
    return p_a - tau / 2 * ca.mtimes(G_a.T, lam), p_b + tau / 2 * ca.mtimes(G_b.T, mu)


def interval_expression(system, scheme: Scheme, t_a, t_b, q_a, p_a, q_b, p_b, lam, mu, theta):
    """The ``2n`` interval equations of interval ``a -> b`` with its multipliers."""
    plus, minus = interval_momenta(system, t_a, t_b, q_a, p_a, q_b, p_b, lam, mu, theta)
    return action_for(system, scheme).interval_equations(t_a, t_b, q_a, plus, q_b, minus, theta)


def node_expression(system, q, p, t, theta):
    """The ``2m`` node rows: ``g(q, t)`` and the hidden constraint ``G H_p + g_t``."""
    g, G, g_t = constraint_function(system)(q, t, theta)
    _, _, H_p, _ = derivatives_function(system)(q, p, t, theta)
    return ca.vertcat(g, ca.mtimes(G, H_p) + g_t)


def interval_energy_expression(system, scheme, t_a, t_b, q_a, p_a, q_b, p_b, lam, mu, theta):
    """``E_k``: the interval's energy at its own clock, with its own momenta."""
    plus, minus = interval_momenta(system, t_a, t_b, q_a, p_a, q_b, p_b, lam, mu, theta)
    return action_for(system, scheme).interval_energy(t_a, t_b, q_a, plus, q_b, minus, theta)


def energy_expression(system, scheme: Scheme, rule: str, nodes, multipliers, theta):
    """The energy row at the middle of ``nodes = (t_prev, t_mid, t_next, q_prev, p_prev, q_mid,
    p_mid, q_next, p_next)`` with ``multipliers = (lam_prev, mu_prev, lam, mu)`` of the
    intervals before and after it."""
    t0, t1, t2, q0, p0, q1, p1, q2, p2 = nodes
    lam0, mu0, lam1, mu1 = multipliers
    action = action_for(system, scheme)
    plus0, minus1 = interval_momenta(system, t0, t1, q0, p0, q1, p1, lam0, mu0, theta)
    plus1, minus2 = interval_momenta(system, t1, t2, q1, p1, q2, p2, lam1, mu1, theta)
    if rule == "vddvp":
        _, _, s_prev, _ = action.arguments(t0, t1, q0, plus0, q1, minus1)
        change = (action.energy_at(t1, t2, q1, plus1, q2, minus2, s_prev, theta, varying=True)
                  - action.energy_at(t0, t1, q0, plus0, q1, minus1, s_prev, theta,
                                     varying=True))
        if not constraints_move(system):  # W_k = 0: the expression as it always was
            return change
        return change - constraint_work(system, (t0, t1, t2), q1, lam1, mu0, theta)
    if rule == "lee":
        t_k = ca.SX.sym("t_k")
        total = (action.action(t0, t_k, q0, plus0, q1, minus1, theta, True)
                 + action.action(t_k, t2, q1, plus1, q2, minus2, theta, True))
        balance = ca.substitute(ca.gradient(total, t_k), t_k, t1)
        _, _, g_t = constraint_function(system)(q1, t1, theta)
        impulse = -((t2 - t1) * lam1 + (t1 - t0) * mu0) / 2
        return balance + ca.dot(impulse, g_t)
    raise ValueError(f"rule {rule!r} has no energy equation")


def constraints_move(system) -> bool:
    """Whether ``g`` depends on ``t`` (then ``g_t != 0`` and the constraint does work)."""
    return bool(system.n_constraints) and bool(ca.depends_on(ca.vec(system.G), system.t))


def constraint_work(system, times, q_mid, lam, mu_prev, theta):
    """``W_k = -Lambda_k . g_t(q_k, t_k) = ((tau_k lambda_k + tau_{k-1} mu_{k-1}) / 2) .
    g_t(q_k, t_k)`` at the middle node of ``times = (t_prev, t_mid, t_next)``: the node time's
    derivative of the multiplier term ``Lambda_k . g(q_k, t_k)`` of the augmented action, with
    its sign turned. Along the exact motion ``dH/dt = H_t + nu . g_t`` (the constraint force
    ``-G^T nu`` on the hidden constraint ``G H_p = -g_t``), and each half impulse is ``(tau /
    2)`` times a multiplier equal to ``nu`` to ``O(tau)``: ``W_k`` is the constraint's work
    over ``[s_{k-1}, s_k]`` to ``O(tau^3)`` where the step varies smoothly."""
    t0, t1, t2 = times
    _, _, g_t = constraint_function(system)(q_mid, t1, theta)
    return ca.dot(((t2 - t1) * lam + (t1 - t0) * mu_prev) / 2, g_t)


def constrained_field_function(system) -> ca.Function:
    """``f(z, t, theta) = (H_p, -H_q - G^T nu)``: the constrained flow, ``nu`` from the
    twice-differentiated constraint (``d/dt (G H_p + g_t) = 0`` along the flow, an ``m x m``
    solve). The dense output's slopes and the march's predictor."""
    def build():
        n = system.n
        z, t = ca.SX.sym("z", 2 * n), ca.SX.sym("t")
        q, p = z[:n], z[n:]
        _, H_q, H_p, _ = derivatives_function(system)(q, p, t, system.theta)
        _, G, _ = constraint_function(system)(q, t, system.theta)
        hidden = node_expression(system, q, p, t, system.theta)[system.n_constraints:]
        r_q, r_p, r_t = (ca.jacobian(hidden, s) for s in (q, p, t))
        nu = ca.solve(ca.mtimes(r_p, G.T), ca.mtimes(r_q, H_p) - ca.mtimes(r_p, H_q) + r_t)
        return ca.Function("f_constrained", [z, t, system.theta],
                           [ca.vertcat(H_p, -H_q - ca.mtimes(G.T, nu))], ["z", "t", "theta"],
                           ["f"])
    return cached(system, "constrained_field", build)


def constrained_field_sparse_function(system) -> ca.Function:
    """The constrained flow of `constrained_field_function` with ``nu`` from a sparse QR at run
    time (CasADi's ``qr`` linear solver) instead of a symbolic solve: the symbolic solve of the
    ``m x m`` system grows faster than ``m`` (a chain of 128 links: 91,000 lines of C for the
    field alone, most of what the compiler spends on a march's chunk), the factorisation's code
    grows with the nonzeros. The march's predictor; an MX function (it takes MX or numbers,
    not SX)."""
    def build():
        n, m = system.n, system.n_constraints
        z, t, nu = ca.SX.sym("z", 2 * n), ca.SX.sym("t"), ca.SX.sym("nu", m)
        q, p = z[:n], z[n:]
        _, H_q, H_p, _ = derivatives_function(system)(q, p, t, system.theta)
        _, G, _ = constraint_function(system)(q, t, system.theta)
        hidden = node_expression(system, q, p, t, system.theta)[m:]
        r_q, r_p, r_t = (ca.jacobian(hidden, s) for s in (q, p, t))
        parts = ca.Function("constrained_field_parts", [z, t, system.theta],
                            [ca.mtimes(r_p, G.T),
                             ca.mtimes(r_q, H_p) - ca.mtimes(r_p, H_q) + r_t])
        finish = ca.Function("constrained_field_finish", [z, t, system.theta, nu],
                             [ca.vertcat(H_p, -H_q - ca.mtimes(G.T, nu))])
        zm, tm = ca.MX.sym("z", 2 * n), ca.MX.sym("t")
        thm = ca.MX.sym("theta", system.theta.numel())
        A, b = parts(zm, tm, thm)
        return ca.Function("f_constrained_sparse", [zm, tm, thm],
                           [finish(zm, tm, thm, ca.solve(A, b, "qr"))], ["z", "t", "theta"],
                           ["f"])
    return cached(system, "constrained_field_sparse", build)


def solvability_function(system) -> ca.Function:
    """``c(z, t, theta)``, the coefficient of ``tau^2`` in the midpoint interval energy of a
    constrained step from ``z`` (``alpha = 1/2``, ``H`` autonomous):
    ``c = (nu' G H_pp G' nu - f' H_zz f) / 8`` with ``f = (H_p, -H_q)`` the unconstrained field
    and ``nu`` the multiplier of the constrained flow (docs/theory.md). An energy step keeps a
    positive root while ``c`` keeps its sign along the orbit. For a constraint that moves the
    interval energies gain ``(tau_k / 2) lambda_k . g_t`` and ``(tau_{k-1} / 2) mu_{k-1} .
    g_t``, which are the row's `constraint_work`: the row is again ``c (tau_k^2 -
    tau_{k-1}^2) + O(tau^3)``, with the moving flow's ``nu`` (docs/constraints.md,
    "Constraints that move": a turning hoop's steps keep ``tau^3 c`` constant to O(tau), and
    its libration stops where this ``c`` changes sign)."""
    def build():
        n = system.n
        z, t = ca.SX.sym("z", 2 * n), ca.SX.sym("t")
        q, p = z[:n], z[n:]
        H = system.H_function(q, p, t, system.theta)
        f = ca.vertcat(ca.gradient(H, p), -ca.gradient(H, q))
        f_c = constrained_field_function(system)(z, t, system.theta)
        force = f[n:] - f_c[n:]  # G' nu
        H_pp = ca.hessian(H, p)[0]
        w = ca.mtimes([f.T, ca.hessian(H, z)[0], f])
        c = (ca.mtimes([force.T, H_pp, force]) - w) / 8
        return ca.Function("constrained_solvability", [z, t, system.theta], [c],
                           ["z", "t", "theta"], ["c"])
    return cached(system, "constrained_solvability", build)


__all__ = ["constrained_field_function", "constrained_field_sparse_function",
           "constraint_work", "constraints_move", "energy_expression", "interval_energy_expression",
           "interval_expression", "interval_momenta", "node_expression", "solvability_function"]
