"""The discrete equations of one interval and one node, written once (THEORY.md section 2).

Every solver uses exactly these functions: the march stacks them for one step, the
fixed-endpoint solver maps them over the whole grid, and the checks evaluate them on results.

Interval ``k`` joins node ``a = k`` and node ``b = k + 1``:

    Q = alpha q_a + beta q_b,   P = alpha p_b + beta p_a,   tau = t_b - t_a,
    s = t_a + tau/2 (midpoint clock) or t_a (left clock).

Discrete action of the interval (the paper's case 3):

    S_k = P . (q_b - q_a) - tau H(Q, P, s).

Canonical equations, in increment form (the paper's eq. cneqd3 multiplied by ``tau``, so they stay
well scaled as ``tau -> 0``):

    q_b - q_a - tau dH/dp(Q, P, s) = 0,   p_b - p_a + tau dH/dq(Q, P, s) = 0.

Energy equation at node ``k`` (joining intervals ``k-1`` and ``k``):

    vddvp:  H(Q_k, P_k, s_{k-1}) - H(Q_{k-1}, P_{k-1}, s_{k-1}) = 0
    lee:    dS_D/dt_k = d(S_{k-1} + S_k)/dt_k = 0   (by automatic differentiation)

Both are differences of energies and have the units of ``H``. With the midpoint clock the
``lee`` residual is ``H_k - H_{k-1} - (tau_k dH/dt_k + tau_{k-1} dH/dt_{k-1})/2``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..cache import cached
from ..physics.hamiltonian import HamiltonianSystem, derivatives_function
from .scheme import Scheme

CANONICAL_INPUTS = ["t_a", "t_b", "q_a", "p_a", "q_b", "p_b", "theta"]
ENERGY_INPUTS = ["t_prev", "t_mid", "t_next", "q_prev", "p_prev", "q_mid", "p_mid",
                 "q_next", "p_next", "theta"]


def _node_symbols(system: HamiltonianSystem, suffix: str):
    return (ca.SX.sym(f"t_{suffix}"), ca.SX.sym(f"q_{suffix}", system.n),
            ca.SX.sym(f"p_{suffix}", system.n))






def interval_arguments(scheme: Scheme, t_a, t_b, q_a, p_a, q_b, p_b):
    """``(Q, P, s, tau)`` of the interval from node ``a`` to node ``b``."""
    tau = t_b - t_a
    Q = scheme.alpha * q_a + scheme.beta * q_b
    P = scheme.alpha * p_b + scheme.beta * p_a
    s = t_a + tau / 2 if scheme.clock == "midpoint" else t_a
    return Q, P, s, tau


def interval_action_expression(system, scheme, t_a, t_b, q_a, p_a, q_b, p_b, theta):
    """``S_k = P . (q_b - q_a) - tau H(Q, P, s)``; for a Lagrangian system
    ``S_k = tau L(Q, (q_b - q_a)/tau, s)``."""
    Q, P, s, tau = interval_arguments(scheme, t_a, t_b, q_a, p_a, q_b, p_b)
    if system.lagrangian_form:
        return tau * system.L_function(Q, (q_b - q_a) / tau, s, theta)
    return ca.dot(P, q_b - q_a) - tau * system.H_function(Q, P, s, theta)


def canonical_expression(system, scheme, t_a, t_b, q_a, p_a, q_b, p_b, theta):
    """Increment-form canonical equations of one interval (2n entries, ``q`` rows first).

    For a Lagrangian system: the discrete Legendre transform of the interval,
    ``p_a - (dL/dv - tau alpha dL/dq)`` and ``p_b - (dL/dv + tau beta dL/dq)`` (``lagrangian.py``).
    """
    if system.lagrangian_form:
        from .lagrangian import discrete_momenta

        p_left, p_right = discrete_momenta(system, scheme, t_a, t_b, q_a, q_b, theta)
        return ca.vertcat(p_a - p_left, p_b - p_right)
    Q, P, s, tau = interval_arguments(scheme, t_a, t_b, q_a, p_a, q_b, p_b)
    _, H_q, H_p, _ = derivatives_function(system)(Q, P, s, theta)
    return ca.vertcat(q_b - q_a - tau * H_p, p_b - p_a + tau * H_q)


def energy_expression(system, scheme, rule, t_prev, t_mid, t_next, q_prev, p_prev, q_mid, p_mid,
                      q_next, p_next, theta):
    """Energy equation at the node between interval ``k-1`` (prev, mid) and ``k`` (mid, next)."""
    if rule == "vddvp":
        Q0, P0, s0, tau0 = interval_arguments(scheme, t_prev, t_mid, q_prev, p_prev, q_mid,
                                              p_mid)
        Q1, P1, _, tau1 = interval_arguments(scheme, t_mid, t_next, q_mid, p_mid, q_next, p_next)
        if system.lagrangian_form:  # E = v . dL/dv - L of each interval, both at clock s0
            from .lagrangian import interval_energy

            return (interval_energy(system, Q1, (q_next - q_mid) / tau1, s0, theta)
                    - interval_energy(system, Q0, (q_mid - q_prev) / tau0, s0, theta))
        return system.H_function(Q1, P1, s0, theta) - system.H_function(Q0, P0, s0, theta)
    if rule == "lee":
        # Differentiate with respect to a fresh symbol standing in for t_mid, so that t_mid
        # may itself be an expression (for example t_next - tau in the march).
        t_k = ca.SX.sym("t_k")
        action = (interval_action_expression(system, scheme, t_prev, t_k, q_prev, p_prev,
                                             q_mid, p_mid, theta)
                  + interval_action_expression(system, scheme, t_k, t_next, q_mid, p_mid,
                                               q_next, p_next, theta))
        return ca.substitute(ca.gradient(action, t_k), t_k, t_mid)
    raise ValueError(f"rule {rule!r} has no energy equation")


def diagnostic_rule(scheme: Scheme) -> str:
    """The energy equation reported for a scheme: its own, or for ``fixed`` steps the ``lee``
    balance ``dS_D/dt_k`` that fixed steps do not enforce (for autonomous ``H`` it is the change
    of the midpoint energy, the same as ``vddvp``)."""
    return scheme.rule if scheme.variable_steps else "lee"


def canonical_function(system: HamiltonianSystem, scheme: Scheme) -> ca.Function:
    """``canonical(t_a, t_b, q_a, p_a, q_b, p_b, theta) -> residual (2n,)``."""
    def build():
        t_a, q_a, p_a = _node_symbols(system, "a")
        t_b, q_b, p_b = _node_symbols(system, "b")
        r = canonical_expression(system, scheme, t_a, t_b, q_a, p_a, q_b, p_b, system.theta)
        return ca.Function("canonical", [t_a, t_b, q_a, p_a, q_b, p_b, system.theta], [r],
                           CANONICAL_INPUTS, ["residual"])
    return cached(system, ("canonical", scheme), build)


def energy_function(system: HamiltonianSystem, scheme: Scheme, rule: str | None = None):
    """``energy(t_prev, t_mid, t_next, q_prev, p_prev, q_mid, p_mid, q_next, p_next, theta)``."""
    rule = rule or diagnostic_rule(scheme)

    def build():
        t0, q0, p0 = _node_symbols(system, "prev")
        t1, q1, p1 = _node_symbols(system, "mid")
        t2, q2, p2 = _node_symbols(system, "next")
        r = energy_expression(system, scheme, rule, t0, t1, t2, q0, p0, q1, p1, q2, p2,
                              system.theta)
        return ca.Function(f"energy_{rule}", [t0, t1, t2, q0, p0, q1, p1, q2, p2, system.theta],
                           [r], ENERGY_INPUTS, ["residual"])
    return cached(system, ("energy", rule, scheme), build)


def midpoint_energy_function(system: HamiltonianSystem, scheme: Scheme) -> ca.Function:
    """``H_k = H(Q_k, P_k, s_k)`` of one interval: the energy the scheme conserves."""
    def build():
        t_a, q_a, p_a = _node_symbols(system, "a")
        t_b, q_b, p_b = _node_symbols(system, "b")
        Q, P, s, tau = interval_arguments(scheme, t_a, t_b, q_a, p_a, q_b, p_b)
        if system.lagrangian_form:
            from .lagrangian import interval_energy

            energy = interval_energy(system, Q, (q_b - q_a) / tau, s, system.theta)
        else:
            energy = system.H_function(Q, P, s, system.theta)
        return ca.Function("interval_energy", [t_a, t_b, q_a, p_a, q_b, p_b, system.theta],
                           [energy], CANONICAL_INPUTS, ["H"])
    return cached(system, ("interval_energy", scheme), build)


def grid_residuals(system: HamiltonianSystem, scheme: Scheme, t, q, p, theta):
    """All equations of a grid: canonical residuals ``(N-1, 2n)`` and energy residuals ``(N-2,)``
    of the scheme's diagnostic rule, unscaled."""
    t = np.asarray(t, float)
    q = np.asarray(q, float)
    p = np.asarray(p, float)
    N = t.size
    theta = np.asarray(theta, float)[:, None]
    canonical = np.zeros((max(N - 1, 0), 2 * system.n))
    energy = np.zeros(max(N - 2, 0))
    if N >= 2:
        f = canonical_function(system, scheme).map(N - 1)
        canonical = np.asarray(f(t[None, :-1], t[None, 1:], q[:-1].T, p[:-1].T, q[1:].T,
                                 p[1:].T, theta)).T
    if N >= 3:
        g = energy_function(system, scheme).map(N - 2)
        energy = np.asarray(g(t[None, :-2], t[None, 1:-1], t[None, 2:], q[:-2].T, p[:-2].T,
                              q[1:-1].T, p[1:-1].T, q[2:].T, p[2:].T, theta)).ravel()
    return canonical, energy


def interval_energies(system: HamiltonianSystem, scheme: Scheme, t, q, p, theta):
    """``H(Q_k, P_k, s_k)`` for every interval, shape ``(N-1,)``."""
    t = np.asarray(t, float)
    q = np.asarray(q, float)
    p = np.asarray(p, float)
    if t.size < 2:
        return np.zeros(0)
    f = midpoint_energy_function(system, scheme).map(t.size - 1)
    return np.asarray(f(t[None, :-1], t[None, 1:], q[:-1].T, p[:-1].T, q[1:].T, p[1:].T,
                        np.asarray(theta, float)[:, None])).ravel()
