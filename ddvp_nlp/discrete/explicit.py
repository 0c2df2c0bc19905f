"""The step maps of the explicit schemes users would pick instead (run by
``solvers/baselines/fixed_step.py``).

- Stormer-Verlet for separable ``H = T(p) + V(q, t)`` in its two Strang splittings of the
  autonomous extended system (time advances with ``q``), both order 2, symplectic, symmetric.
  ``stormer_verlet`` is kick-drift-kick (velocity Verlet)::

      p_h = p_k - tau/2 V_q(q_k, t_k),   q_{k+1} = q_k + tau T_p(p_h),
      p_{k+1} = p_h - tau/2 V_q(q_{k+1}, t_k + tau);

  ``leapfrog`` is drift-kick-drift (position Verlet; SUNDIALS' ``ARKODE_SPRK_LEAPFROG_2_2``)::

      q_h = q_k + tau/2 T_p(p_k),   p_{k+1} = p_k - tau V_q(q_h, t_k + tau/2),
      q_{k+1} = q_h + tau/2 T_p(p_{k+1}).

- Classical Runge-Kutta (RK4) on ``z' = (H_p, -H_q)``, order 4, neither symplectic nor
  energy-conserving.
"""

from __future__ import annotations

import casadi as ca

from ..cache import cached
from ..errors import InputError
from ..physics.hamiltonian import HamiltonianSystem, separable_parts, vector_field_function
from .runge_kutta import rk4


def stormer_verlet_step(system: HamiltonianSystem) -> ca.Function:
    """``(z, t, tau, theta) -> z_next`` by Stormer-Verlet; ``InputError`` if ``H`` is not
    separable."""
    def build():
        T_p, V_q = separable_or_raise(system, "stormer_verlet")
        n = system.n
        z, t, tau = ca.SX.sym("z", 2 * n), ca.SX.sym("t"), ca.SX.sym("tau")
        q, p = z[:n], z[n:]
        p_half = p - tau / 2 * V_q(q, t, system.theta)
        q_next = q + tau * T_p(p_half, system.theta)
        p_next = p_half - tau / 2 * V_q(q_next, t + tau, system.theta)
        return ca.Function("stormer_verlet", [z, t, tau, system.theta],
                           [ca.vertcat(q_next, p_next)])
    return cached(system, "stormer_verlet_step", build)


def leapfrog_step(system: HamiltonianSystem) -> ca.Function:
    """``(z, t, tau, theta) -> z_next`` by drift-kick-drift Stormer-Verlet; ``InputError`` if
    ``H`` is not separable."""
    def build():
        T_p, V_q = separable_or_raise(system, "leapfrog")
        n = system.n
        z, t, tau = ca.SX.sym("z", 2 * n), ca.SX.sym("t"), ca.SX.sym("tau")
        q, p = z[:n], z[n:]
        q_half = q + tau / 2 * T_p(p, system.theta)
        p_next = p - tau * V_q(q_half, t + tau / 2, system.theta)
        q_next = q_half + tau / 2 * T_p(p_next, system.theta)
        return ca.Function("leapfrog", [z, t, tau, system.theta], [ca.vertcat(q_next, p_next)])
    return cached(system, "leapfrog_step", build)


def separable_or_raise(system: HamiltonianSystem, method: str):
    """``(T_p, V_q)`` of a separable ``H``; ``InputError`` naming ``method`` otherwise."""
    parts = separable_parts(system)
    if isinstance(parts, str):
        raise InputError(f"method {method!r} needs a separable H on {system.name!r}: {parts}")
    return parts


def rk4_step(system: HamiltonianSystem) -> ca.Function:
    """``(z, t, tau, theta) -> z_next`` by the classical Runge-Kutta method."""
    def build():
        field = vector_field_function(system)

        def flow(z, t):
            return field(z, t, system.theta)

        z, t, tau = ca.SX.sym("z", 2 * system.n), ca.SX.sym("t"), ca.SX.sym("tau")
        return ca.Function("rk4", [z, t, tau, system.theta], [rk4(flow, z, t, tau)])
    return cached(system, "rk4_step", build)


FIXED_STEPS = {"stormer_verlet": stormer_verlet_step, "leapfrog": leapfrog_step,
               "rk4": rk4_step}
