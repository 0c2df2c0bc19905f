"""T.D. Lee's original left-point discretisation (docs/theory.md section 3):
another interval action.

For ``H = p.A p/2 + V(q, t)`` with a constant matrix ``A``, the left-point discrete Lagrangian of
interval ``k`` is ``tau_k [v_k.A^{-1} v_k/2 - V(q_k, t_k)]``, ``v_k = (q_{k+1} - q_k)/tau_k``.
The step equations at node ``k`` are the discrete Euler-Lagrange equation ``dS_D/dq_k = 0`` and
the energy equation ``dS_D/dt_k = 0``, both taken from the two-interval action by automatic
differentiation, in the unknowns ``(v_k, tau_k)``. The march that solves them is
``solvers/baselines/lee_left_stepper.py``.
"""

from __future__ import annotations

import casadi as ca

from ..errors import InputError
from ..physics.hamiltonian import HamiltonianSystem, quadratic_kinetic_matrix


class LeeLeftPointEquations:
    """The step equations of T.D. Lee's original left-point scheme (module docstring), as CasADi
    functions: ``residual(x, w)`` of a step in ``x = (v_k, tau_k)`` given
    ``w = (t_{k-1}, t_k, q_{k-1}, q_k, theta)``, its ``predict``-ion, the node ``momentum``, the
    ``first_velocity`` (and ``first_residual``) of the first step from ``(q_0, p_0)``, and the
    ``node_energy``."""

    def __init__(self, system: HamiltonianSystem):
        A = quadratic_kinetic_matrix(system)
        if isinstance(A, str):
            raise InputError(f"method 'lee_left' needs H = p.A p/2 + V(q, t) on "
                             f"{system.name!r}: {A}")
        n, theta = system.n, system.theta
        zero = ca.DM.zeros(n)
        potential = ca.Function("V", [system.q, system.t, theta],
                                [ca.substitute(system.H, system.p, zero)])
        A_function = ca.Function("A", [theta], [A])

        def interval_action(t_a, t_b, q_a, q_b):
            tau = t_b - t_a
            v = (q_b - q_a) / tau
            return tau * (ca.dot(v, ca.solve(A_function(theta), v)) / 2
                          - potential(q_a, t_a, theta))

        t0, t1, t2 = ca.SX.sym("t_prev"), ca.SX.sym("t_mid"), ca.SX.sym("t_next")
        q0, q1, q2 = ca.SX.sym("q_prev", n), ca.SX.sym("q_mid", n), ca.SX.sym("q_next", n)
        action = interval_action(t0, t1, q0, q1) + interval_action(t1, t2, q1, q2)
        euler_lagrange = ca.gradient(action, q1)
        energy = ca.gradient(action, t1)
        # Unknowns (v, tau) of the step: q_next = q_mid + tau v keeps both equations O(1) as
        # tau -> 0 (in q_next they carry 1/tau).
        v, tau = ca.SX.sym("v", n), ca.SX.sym("tau")
        x = ca.vertcat(v, tau)
        w = ca.vertcat(t0, t1, q0, q1, theta)
        g = ca.substitute(ca.vertcat(euler_lagrange, energy), ca.vertcat(q2, t2),
                          ca.vertcat(q1 + tau * v, t1 + tau))
        self.residual = ca.Function("lee_left_step", [x, w], [g])
        tau_prev = t1 - t0
        v_prev = (q1 - q0) / tau_prev
        V_q = ca.gradient(potential(q1, t1, theta), q1)
        guess = ca.vertcat(v_prev - tau_prev * ca.mtimes(A_function(theta), V_q), tau_prev)
        self.predict = ca.Function("lee_left_predict", [w], [guess])
        # Momentum at the new node, p_{k+1} = dS_k/dq_{k+1} = A^{-1} v_k.
        self.momentum = ca.Function("lee_left_momentum", [v, theta],
                                    [ca.solve(A_function(theta), v)])
        # First step from (q0, p0): p0 = -d(tau0 L_0)/dq_0, linear in v0, so one Newton step
        # from v0 = 0 solves it.
        p_start, tau0 = ca.SX.sym("p0", n), ca.SX.sym("tau0")
        first = ca.substitute(p_start + ca.gradient(interval_action(t0, t1, q0, q1), q0),
                              ca.vertcat(t1, q1), ca.vertcat(t0 + tau0, q0 + tau0 * v))
        start = ca.vertcat(t0, tau0, q0, p_start, theta)
        self.first_residual = ca.Function("lee_left_first_residual", [v, start], [first])
        v_first = ca.substitute(-ca.solve(ca.jacobian(first, v), first), v, zero)
        self.first_velocity = ca.Function("lee_left_first", [start], [v_first])
        self.node_energy = ca.Function(
            "lee_left_energy", [v, q0, t0, theta],
            [ca.dot(v, ca.solve(A_function(theta), v)) / 2 + potential(q0, t0, theta)])
