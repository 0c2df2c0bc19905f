"""One march step as CasADi functions: residual, predictor and check.

Two kinds of step (docs/theory.md section 5):

- *fixed-length*: given ``t_a, t_b, z_a``, solve the ``2n`` canonical equations of the interval
  ``[t_a, t_b]`` for ``z_b``. Every step of the ``fixed`` rule, and step 0 of the energy rules.
- *energy*: given ``t_{k-1}, t_k, z_{k-1}, z_k``, solve the ``2n`` canonical equations of interval
  ``k`` and the energy equation at node ``k`` for ``(z_{k+1}, tau_k)``.

`StepFunctions` holds, for each kind, the residual, a Runge-Kutta predictor and a *check*:
the step's unscaled residuals and what the monitors need of the new node (``H`` and the
site-density weight ``w``). Its attributes are the public interface that both paths build on:
the careful Newton (``newton.py``, `NewtonSteps`) and the
compiled chunk (``chunk.py``); `FixedCheck` and `EnergyCheck` name the check's
outputs.
"""

from __future__ import annotations

from typing import NamedTuple

import casadi as ca

from ...cache import cached
from ...discrete import equations
from ...discrete.runge_kutta import rk4
from ...discrete.scheme import Scheme
from ...physics.hamiltonian import (
    HamiltonianSystem,
    site_density_weight_function,
    vector_field_function,
)

# Newton's stopping test is absolute (``|g|_inf <= 1e-14``, ``step_newton.NEWTON_OPTIONS``),
# which a motion far below the units meets at its first guess: at a node of size 1e-10 the RK4
# guess passes it, though the step's residual is then 1e-5 of the node. The rows Newton is given
# are therefore those of the step divided by ``s = min(1, |z|_inf / NEWTON_REFERENCE)``: exactly
# 1 for a node of size ``NEWTON_REFERENCE`` or more (the same bits as the rows themselves, at
# the cost of a norm and a division a step), the energy row by ``s^2``, as an energy scales with
# the square of the state. Newton's iterates do not depend on a scaling of its rows; where it
# stops does: at ``1e-14 / NEWTON_REFERENCE`` (1e-12) of the node, a hundred times under the
# default acceptance tolerance. The acceptance test itself reads the unscaled rows.
NEWTON_REFERENCE = 1e-2


def newton_scale(z) -> ca.SX:
    """``s`` of the comment above for a node ``z`` (an SX column); at least 1e-150, so that
    ``s^2`` is a normal number."""
    return ca.fmin(1.0, ca.fmax(ca.norm_inf(z) / NEWTON_REFERENCE, 1e-150))


class FixedCheck(NamedTuple):
    """Outputs of ``StepFunctions.fixed_check(z_b, w)``, in order."""

    canonical: object  # |canonical residual|_inf
    size: object  # |z_a|_inf, the scale of the canonical residual
    H_node: object  # H(z_b, t_b)
    w_node: object  # site-density weight at (z_b, t_b)


class EnergyCheck(NamedTuple):
    """Outputs of ``StepFunctions.energy_check(x, w)``, in order."""

    canonical: object  # |canonical residual|_inf
    energy: object  # energy residual (signed, without the drift)
    size: object  # |z_k|_inf
    H_interval: object  # |H_k|, the interval energy: the scale of the energy residual
    H_node: object  # H(z_{k+1}, t_{k+1})
    w_node: object  # site-density weight at (z_{k+1}, t_{k+1})


class StepFunctions:
    """The CasADi functions of one march step, built once per system and scheme.

    Fixed-length step: unknown ``z_b``; parameters ``w = [t_a, t_b, z_a, theta]``.
    ``fixed_residual(z_b, w)``, ``fixed_predict(w)`` (RK4),
    ``fixed_check(z_b, w)`` (see `FixedCheck`); ``fixed_newton_residual``, the rows Newton
    solves (`newton_scale`; the same for energy steps).

    Energy step (energy rules only): unknown ``x = [z_{k+1}, tau_k]``; parameters
    ``w = [t_{k-1}, t_k, z_{k-1}, z_k, theta, drift]``. ``energy_residual(x, w)``,
    ``energy_predict(w, tau_guess)``, ``energy_check(x, w)`` (see
    `EnergyCheck`).

    ``node_monitor(z, t, theta)``: ``H`` and ``w`` at a node.
    """

    def __init__(self, system: HamiltonianSystem, scheme: Scheme):
        n = system.n
        theta = system.theta
        canonical = equations.canonical_function(system, scheme)
        field = vector_field_function(system)

        def flow(z, t):
            return field(z, t, theta)

        t_a, t_b = ca.SX.sym("t_a"), ca.SX.sym("t_b")
        z_a, z_b = ca.SX.sym("z_a", 2 * n), ca.SX.sym("z_b", 2 * n)
        w = ca.vertcat(t_a, t_b, z_a, theta)
        g = canonical(t_a, t_b, z_a[:n], z_a[n:], z_b[:n], z_b[n:], theta)
        self.fixed_residual = ca.Function("g", [z_b, w], [g])
        self.fixed_newton_residual = ca.Function("g_newton", [z_b, w], [g / newton_scale(z_a)])
        self.fixed_predict = ca.Function("predict", [w], [rk4(flow, z_a, t_a, t_b - t_a)])
        # The checks return H and w of the new node for the energy guard and the solvability
        # monitor, so neither path pays an extra call per node.
        weight = site_density_weight_function(system)
        z, t = ca.SX.sym("z", 2 * n), ca.SX.sym("t")
        self.node_monitor = ca.Function(
            "node_monitor", [z, t, theta],
            [system.H_function(z[:n], z[n:], t, theta), weight(z[:n], z[n:], t, theta)])
        self.fixed_check = ca.Function("check", [z_b, w], [
            ca.norm_inf(g), ca.norm_inf(z_a), *self.node_monitor(z_b, t_b, theta)])
        if scheme.variable_steps:
            self._build_energy_step(system, scheme, canonical, flow)

    def _build_energy_step(self, system, scheme, canonical, flow):
        n, theta = system.n, system.theta
        energy = equations.energy_function(system, scheme)
        interval_energy = equations.midpoint_energy_function(system, scheme)
        t_prev, t_mid = ca.SX.sym("t_prev"), ca.SX.sym("t_mid")
        z_prev, z_mid, z_next = (ca.SX.sym(s, 2 * n) for s in ("z_prev", "z_mid", "z_next"))
        tau = ca.SX.sym("tau")
        x = ca.vertcat(z_next, tau)
        # drift: the sum of the energy residuals accepted so far. Solving for
        # residual_k = -drift keeps that sum at round-off, so the round-off of single steps
        # (seen biased, about 3e-16 per step on fpu) does not add up to a drift of the energy
        # level; every node still satisfies its own equation to round-off.
        drift = ca.SX.sym("drift")
        w = ca.vertcat(t_prev, t_mid, z_prev, z_mid, theta, drift)
        t_next = t_mid + tau
        g_canonical = canonical(t_mid, t_next, z_mid[:n], z_mid[n:], z_next[:n], z_next[n:], theta)
        g_energy = energy(t_prev, t_mid, t_next, z_prev[:n], z_prev[n:], z_mid[:n], z_mid[n:],
                          z_next[:n], z_next[n:], theta)
        # The energy equation's derivative in tau is O(tau) (docs/theory.md section 7); dividing
        # by the previous step makes its Newton tolerance an absolute tolerance on tau.
        g = ca.vertcat(g_canonical, (g_energy + drift) / (t_mid - t_prev))
        self.energy_residual = ca.Function("g", [x, w], [g])
        scale = newton_scale(z_mid)
        self.energy_newton_residual = ca.Function("g_newton", [x, w], [ca.vertcat(
            g[:2 * n] / scale, g[2 * n] / (scale * scale))])
        guess = ca.SX.sym("tau_guess")
        self.energy_predict = ca.Function(
            "predict", [w, guess], [ca.vertcat(rk4(flow, z_mid, t_mid, guess), guess)])
        H_k = interval_energy(t_mid, t_next, z_mid[:n], z_mid[n:], z_next[:n], z_next[n:], theta)
        self.energy_check = ca.Function(
            "check", [x, w], [ca.norm_inf(g_canonical), g_energy, ca.norm_inf(z_mid),
                              ca.fabs(H_k), *self.node_monitor(z_next, t_next, theta)])


def step_functions(system: HamiltonianSystem, scheme: Scheme) -> StepFunctions:
    """The step functions of ``system`` and ``scheme``, built once and cached on the system."""
    return cached(system, ("march", scheme), lambda: StepFunctions(system, scheme))


