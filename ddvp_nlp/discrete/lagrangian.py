"""The discrete Legendre transform and interval energy of a Lagrangian system (case 2)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..cache import cached
from ..physics.lagrangian import LagrangianSystem


def discrete_momenta(system: LagrangianSystem, scheme, t_a, t_b, q_a, q_b, theta):
    """``(p_a, p_b)`` of one interval by the discrete Legendre transform (THEORY.md section 3)."""
    from .equations import interval_arguments

    Q, _, s, tau = interval_arguments(scheme, t_a, t_b, q_a, q_a, q_b, q_b)
    L_q, L_v = _partials(system, Q, (q_b - q_a) / tau, s, theta)
    return L_v - tau * scheme.alpha * L_q, L_v + tau * scheme.beta * L_q


def _partials(system: LagrangianSystem, Q, v, s, theta):
    """``dL/dq`` and ``dL/dv`` at ``(Q, v, s)`` (any expressions)."""
    def build():
        L_q = ca.gradient(system.L, system.q)
        L_v = ca.gradient(system.L, system.v)
        return ca.Function("L_partials", [system.q, system.v, system.t, system.theta],
                           [L_q, L_v])
    return cached(system, "L_partials", build)(Q, v, s, theta)


def interval_energy(system: LagrangianSystem, Q, v, s, theta):
    """``E = v . dL/dv - L`` at ``(Q, v, s)``."""
    _, L_v = _partials(system, Q, v, s, theta)
    return ca.dot(v, L_v) - system.L_function(Q, v, s, theta)


def start_momentum(system: LagrangianSystem, scheme, q0, v0, *, t0, tau0, theta) -> np.ndarray:
    """``p_0`` of a march that starts from ``(q0, v0)``: the first interval has velocity ``v0``
    (``q_1 = q_0 + tau0 v0``) and ``p_0 = dL/dv - tau0 alpha dL/dq`` on it."""
    from .equations import interval_arguments

    q0 = np.asarray(q0, float)
    q1 = q0 + tau0 * np.asarray(v0, float)
    Q, _, s, tau = interval_arguments(scheme, t0, t0 + tau0, q0, q0, q1, q1)
    L_q, L_v = _partials(system, ca.DM(Q), ca.DM(np.asarray(v0, float)), s, ca.DM(theta))
    return np.asarray(L_v - tau * scheme.alpha * L_q, dtype=float).ravel()
