"""The interval action of a Lagrangian system ``L(q, v, t)`` (the paper's case 2).

With ``v = (q_b - q_a)/tau``::

    S_k = tau L(Q, v, s).

Its stationarity in the interior ``q`` (the discrete Euler-Lagrange equations) is written with
the discrete Legendre transform, one pair of equations per interval, in the node momenta ``p``::

    p_a = dL/dv - tau alpha dL/dq,   p_b = dL/dv + tau beta dL/dq   (at (Q, v, s)),

so that ``p_k`` of interval ``k`` and of interval ``k-1`` agree exactly when the Euler-Lagrange
equation at node ``k`` holds. The energy is ``E = v . dL/dv - L``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..cache import cached
from ..physics.lagrangian import LagrangianSystem
from .action import IntervalAction, interval_arguments


class LagrangianAction(IntervalAction):
    row_units = ("p", "p")  # p_a - p_left, p_b - p_right

    def action(self, t_a, t_b, q_a, p_a, q_b, p_b, theta, varying: bool = False):
        Q, _, s, tau = self.arguments(t_a, t_b, q_a, p_a, q_b, p_b)
        return tau * self._L(varying)(Q, (q_b - q_a) / tau, s, theta)

    def interval_equations(self, t_a, t_b, q_a, p_a, q_b, p_b, theta):
        Q, _, s, tau = self.arguments(t_a, t_b, q_a, q_a, q_b, q_b)
        L_q, L_v = _partials(self.system, Q, (q_b - q_a) / tau, s, theta)
        p_left = L_v - tau * self.scheme.alpha * L_q
        p_right = L_v + tau * self.scheme.beta * L_q
        return ca.vertcat(p_a - p_left, p_b - p_right)

    def energy_at(self, t_a, t_b, q_a, p_a, q_b, p_b, clock, theta, varying: bool = False):
        Q, _, _, tau = self.arguments(t_a, t_b, q_a, p_a, q_b, p_b)
        v = (q_b - q_a) / tau
        _, L_v = _partials(self.system, Q, v, clock, theta)
        return ca.dot(v, L_v) - self._L(varying)(Q, v, clock, theta)

    def _L(self, varying: bool):
        return self.system.L_varying_function if varying else self.system.L_function


def _partials(system: LagrangianSystem, Q, v, s, theta):
    """``dL/dq`` and ``dL/dv`` at ``(Q, v, s)`` (any expressions)."""
    def build():
        L_q = ca.gradient(system.L, system.q)
        L_v = ca.gradient(system.L, system.v)
        return ca.Function("L_partials", [system.q, system.v, system.t, system.theta],
                           [L_q, L_v])
    return cached(system, "L_partials", build)(Q, v, s, theta)


def start_momentum(system: LagrangianSystem, scheme, q0, v0, *, t0, tau0, theta) -> np.ndarray:
    """``p_0`` of a march that starts from ``(q0, v0)``: the first interval has velocity ``v0``
    (``q_1 = q_0 + tau0 v0``) and ``p_0 = dL/dv - tau0 alpha dL/dq`` on it."""
    q0 = np.asarray(q0, float)
    q1 = q0 + tau0 * np.asarray(v0, float)
    Q, _, s, tau = interval_arguments(scheme, t0, t0 + tau0, q0, q0, q1, q1)
    L_q, L_v = _partials(system, ca.DM(Q), ca.DM(np.asarray(v0, float)), s, ca.DM(theta))
    return np.asarray(L_v - tau * scheme.alpha * L_q, dtype=float).ravel()
