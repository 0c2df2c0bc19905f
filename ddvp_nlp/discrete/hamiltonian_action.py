"""The interval action of a Hamiltonian system (the paper's case 3).

    S_k = P . (q_b - q_a) - tau H(Q, P, s).

Its interval equations are the canonical equations in increment form (the paper's eq. cneqd3
multiplied by ``tau``, so they stay well scaled as ``tau -> 0``)::

    q_b - q_a - tau dH/dp(Q, P, s) = 0,   p_b - p_a + tau dH/dq(Q, P, s) = 0,

and its energy is ``H(Q, P, clock)``.
"""

from __future__ import annotations

import casadi as ca

from ..physics.hamiltonian import derivatives_function
from .action import IntervalAction


class HamiltonianAction(IntervalAction):
    def action(self, t_a, t_b, q_a, p_a, q_b, p_b, theta, varying: bool = False):
        Q, P, s, tau = self.arguments(t_a, t_b, q_a, p_a, q_b, p_b)
        return ca.dot(P, q_b - q_a) - tau * self._H(varying)(Q, P, s, theta)

    def interval_equations(self, t_a, t_b, q_a, p_a, q_b, p_b, theta):
        Q, P, s, tau = self.arguments(t_a, t_b, q_a, p_a, q_b, p_b)
        _, H_q, H_p, _ = derivatives_function(self.system)(Q, P, s, theta)
        return ca.vertcat(q_b - q_a - tau * H_p, p_b - p_a + tau * H_q)

    def energy_at(self, t_a, t_b, q_a, p_a, q_b, p_b, clock, theta, varying: bool = False):
        Q, P, _, _ = self.arguments(t_a, t_b, q_a, p_a, q_b, p_b)
        return self._H(varying)(Q, P, clock, theta)

    def _H(self, varying: bool):
        return self.system.H_varying_function if varying else self.system.H_function
