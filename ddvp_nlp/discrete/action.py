"""The discrete action of one interval, and the node equations derived from it for every form.

Interval ``k`` joins node ``a = k`` and node ``b = k + 1``; its arguments are

    Q = alpha q_a + beta q_b,   P = alpha p_b + beta p_a,   tau = t_b - t_a,
    s = t_a + tau/2 (midpoint clock) or t_a (left clock).

Each form of system gives an `IntervalAction` (``hamiltonian.py``, ``lagrangian.py``) with
three things, and only these:

- ``action``: the interval action ``S_k(t_a, t_b, z_a, z_b, theta)``, which takes both node
  times, so variable steps are native;
- ``interval_equations``: the ``2n`` equations that make the summed action stationary in the node
  states, written per interval (the canonical equations, or the discrete Legendre transform);
- ``energy_at``: the interval's energy with its clock replaced by a given time.

From those, the same code for every form derives (this module):

- the interval energy ``E_k = energy_at(interval k, s_k)``, the quantity the energy rules conserve;
- the energy equation at node ``k`` (between intervals ``k-1`` and ``k``)::

      vddvp:  E(interval k at clock s_{k-1}) - E(interval k-1 at clock s_{k-1}) = 0
      lee:    dS_D/dt_k = d(S_{k-1} + S_k)/dt_k = 0   (by automatic differentiation)

  Both are differences of energies and have the units of ``H``. They are formed with
  ``varying=True``: ``H`` (or ``L``) without the terms that depend on none of the state and the
  clock (`physics.hamiltonian.varying_part`), which cancel in the difference; left in, their
  round-off would enter it (``H + 1e12``: the steps would follow the round-off of ``1e12``).
  With the midpoint clock and a Hamiltonian the ``lee`` residual is
  ``H_k - H_{k-1} - (tau_k dH/dt_k + tau_{k-1} dH/dt_{k-1})/2``.
"""

from __future__ import annotations

import casadi as ca

from .scheme import Scheme


def interval_arguments(scheme: Scheme, t_a, t_b, q_a, p_a, q_b, p_b):
    """``(Q, P, s, tau)`` of the interval from node ``a`` to node ``b``."""
    tau = t_b - t_a
    Q = scheme.alpha * q_a + scheme.beta * q_b
    P = scheme.alpha * p_b + scheme.beta * p_a
    s = t_a + tau / 2 if scheme.clock == "midpoint" else t_a
    return Q, P, s, tau


class IntervalAction:
    """``S_k`` of one system form under one scheme; subclasses give the three form-specific
    parts, the energy equations and the interval energy follow here.

    Every method takes CasADi expressions (or numbers) of the two nodes
    ``(t_a, t_b, q_a, p_a, q_b, p_b)`` and the parameters ``theta``.
    """

    # The units of the interval equations' two blocks of n rows: a position's then a
    # momentum's (the increment form of the canonical equations), or a momentum's twice (the
    # discrete Legendre transform); a verification measures each row against its block's motion.
    row_units: tuple[str, str] = ("q", "p")

    def __init__(self, system, scheme: Scheme):
        self.system = system
        self.scheme = scheme

    def arguments(self, t_a, t_b, q_a, p_a, q_b, p_b):
        return interval_arguments(self.scheme, t_a, t_b, q_a, p_a, q_b, p_b)

    def action(self, t_a, t_b, q_a, p_a, q_b, p_b, theta, varying: bool = False):
        raise NotImplementedError

    def interval_equations(self, t_a, t_b, q_a, p_a, q_b, p_b, theta):
        raise NotImplementedError

    def energy_at(self, t_a, t_b, q_a, p_a, q_b, p_b, clock, theta, varying: bool = False):
        raise NotImplementedError

    def interval_energy(self, t_a, t_b, q_a, p_a, q_b, p_b, theta):
        """``E_k``: the interval's energy at its own clock."""
        _, _, s, _ = self.arguments(t_a, t_b, q_a, p_a, q_b, p_b)
        return self.energy_at(t_a, t_b, q_a, p_a, q_b, p_b, s, theta)

    def energy_equation(self, rule: str, t_prev, t_mid, t_next, q_prev, p_prev, q_mid, p_mid,
                        q_next, p_next, theta):
        """The energy equation of ``rule`` at the node between interval ``k-1`` (prev, mid) and
        interval ``k`` (mid, next)."""
        if rule == "vddvp":
            _, _, s_prev, _ = self.arguments(t_prev, t_mid, q_prev, p_prev, q_mid, p_mid)
            return (self.energy_at(t_mid, t_next, q_mid, p_mid, q_next, p_next, s_prev, theta,
                                   varying=True)
                    - self.energy_at(t_prev, t_mid, q_prev, p_prev, q_mid, p_mid, s_prev, theta,
                                     varying=True))
        if rule == "lee":
            # Differentiate with respect to a fresh symbol standing in for t_mid, so that t_mid
            # may itself be an expression (for example t_next - tau in the march).
            t_k = ca.SX.sym("t_k")
            action = (self.action(t_prev, t_k, q_prev, p_prev, q_mid, p_mid, theta, True)
                      + self.action(t_k, t_next, q_mid, p_mid, q_next, p_next, theta, True))
            return ca.substitute(ca.gradient(action, t_k), t_k, t_mid)
        raise ValueError(f"rule {rule!r} has no energy equation")
