"""One march step as CasADi functions, and its careful solve: Newton with retries.

Two kinds of step (docs/theory.md section 5):

- *fixed-length*: given ``t_a, t_b, z_a``, solve the ``2n`` canonical equations of the interval
  ``[t_a, t_b]`` for ``z_b``. Every step of the ``fixed`` rule, and step 0 of the energy rules.
- *energy*: given ``t_{k-1}, t_k, z_{k-1}, z_k``, solve the ``2n`` canonical equations of interval
  ``k`` and the energy equation at node ``k`` for ``(z_{k+1}, tau_k)``.

:class:`StepFunctions` holds, for each kind, the residual, a Runge-Kutta predictor and a *check*:
the step's unscaled residuals and what the monitors need of the new node (``H`` and the
site-density weight ``w``). Its attributes are the public interface that the compiled chunk
(``chunk.py``) builds on; :class:`FixedCheck` and :class:`EnergyCheck` name the check's outputs.
:class:`NewtonSteps` solves one step with CasADi's ``newton`` and says how it went in a
:class:`StepResult`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import casadi as ca
import numpy as np

from ...cache import cached
from ...discrete import equations
from ...discrete.runge_kutta import rk4
from ...discrete.scheme import Scheme
from ...errors import InputError
from ...physics.hamiltonian import (
    HamiltonianSystem,
    site_density_weight_function,
    vector_field_function,
)
from ...solution import Status

NEWTON_OPTIONS = {"abstol": 1e-14, "abstolStep": 1e-14, "max_iter": 30, "error_on_fail": False}
# Starting guesses for tau, as multiples of the previous step, tried in order when Newton from the
# predictor fails or lands on tau <= 0. The spurious root sits at -tau_{k-1}; these start far
# from it.
RETRY_FACTORS = (1.0, 0.5, 2.0, 0.25)


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


def _rootfinder(name: str, residual: ca.Function, system, scheme: Scheme) -> ca.Function:
    """CasADi's Newton rootfinder on ``residual``; a step whose equations cannot determine it
    (a structurally singular Jacobian, for example ``H = p[0]`` or a constant ``H`` under an
    energy rule, whose energy equation does not depend on the step) is refused by name."""
    rows = residual.size1_out(0)
    rank = residual.sparsity_jac(0, 0)
    if ca.sprank(rank) < rows:
        unknowns = "(z_next, tau)" if name == "energy_step" else "z_next"
        raise InputError(
            f"H of {system.name!r} has no well-posed {scheme.rule} step: the step equations do "
            f"not determine {unknowns} (their Jacobian is structurally singular: rank "
            f"{ca.sprank(rank)} of {rows}). Under an energy rule the energy of an interval must "
            "depend on its length, which it does not for H linear in p or constant; use "
            "--scheme fixed" if name == "energy_step" else
            f"H of {system.name!r} has no well-posed step: the canonical equations do not "
            f"determine z_next (rank {ca.sprank(rank)} of {rows})")
    return ca.rootfinder(name, "newton", residual, NEWTON_OPTIONS)


class StepFunctions:
    """The CasADi functions of one march step, built once per system and scheme.

    Fixed-length step: unknown ``z_b``; parameters ``w = [t_a, t_b, z_a, theta]``.
    ``fixed_residual(z_b, w)``, ``fixed_root`` (Newton), ``fixed_predict(w)`` (RK4),
    ``fixed_check(z_b, w)`` (see :class:`FixedCheck`).

    Energy step (energy rules only): unknown ``x = [z_{k+1}, tau_k]``; parameters
    ``w = [t_{k-1}, t_k, z_{k-1}, z_k, theta, drift]``. ``energy_residual(x, w)``,
    ``energy_root``, ``energy_predict(w, tau_guess)``, ``energy_check(x, w)`` (see
    :class:`EnergyCheck`).

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
        self.fixed_root = _rootfinder("fixed_step", self.fixed_residual, system, scheme)
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
        self.energy_root = _rootfinder("energy_step", self.energy_residual, system, scheme)
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


@dataclass
class StepResult:
    """One careful step: the new node, or a failure status with a detail in words.

    The new node is ``(t_next, z_next)``; ``tau`` is the length an energy step solved for.
    ``energy`` is the energy residual of an accepted energy step (it joins the drift);
    ``H_node``, ``w_node`` are the monitors' values at the new node."""

    status: Status
    detail: str = ""
    t_next: float | None = None
    z_next: np.ndarray | None = None
    tau: float | None = None
    energy: float = 0.0
    H_node: float = 0.0
    w_node: float = 0.0

    @classmethod
    def failed(cls, status: Status, detail: str = "") -> StepResult:
        return cls(status, detail)


class NewtonSteps:
    """Careful steps: CasADi's ``newton`` on :class:`StepFunctions`, checked by ``acceptance``
    (an :class:`~ddvp_nlp.solvers.march.acceptance.Acceptance`). Counts Newton iterations and
    retries."""

    def __init__(self, functions: StepFunctions, theta: np.ndarray, acceptance):
        self.functions = functions
        self.theta = theta
        self.acceptance = acceptance
        self.newton_iterations = 0
        self.retries = 0

    def _solve(self, root, guess, w):
        x = np.asarray(root(guess, w)).ravel()
        stats = root.stats()
        self.newton_iterations += int(stats.get("iter_count", 0))
        # Read return_status: CasADi's "success" flag was seen False on converged calls.
        return x, stats.get("return_status") == "success"

    def fixed_step(self, t_a: float, t_b: float, z_a: np.ndarray) -> StepResult:
        """``z_b`` on ``[t_a, t_b]`` from the RK4 predictor."""
        f = self.functions
        w = np.concatenate([[t_a, t_b], z_a, self.theta])
        z_b, converged = self._solve(f.fixed_root, f.fixed_predict(w), w)
        if not np.all(np.isfinite(z_b)):
            return StepResult.failed(Status.NON_FINITE, f"z = {z_b.tolist()}")
        if not converged:
            return StepResult.failed(Status.NEWTON_FAILED)
        check = FixedCheck(*(float(v) for v in f.fixed_check(z_b, w)))
        if not self.acceptance.residuals_ok(check.canonical, check.size):
            return StepResult.failed(Status.RESIDUAL_TOO_LARGE,
                                     f"canonical residual {check.canonical:.3e}")
        return StepResult(Status.SUCCESS, t_next=t_b, z_next=z_b, H_node=check.H_node,
                          w_node=check.w_node)

    def energy_parameters(self, t_prev, t_mid, z_prev, z_mid, drift) -> np.ndarray:
        """The parameter vector ``w`` of the energy step functions."""
        return np.concatenate([[t_prev, t_mid], z_prev, z_mid, self.theta, [drift]])

    def energy_step(self, t_prev, t_mid, z_prev, z_mid, drift) -> StepResult:
        """``(z_{k+1}, tau_k)``: Newton from the predictor with ``tau = f tau_{k-1}`` for each
        ``f`` in ``RETRY_FACTORS`` until a root passes every check. On failure the status says
        how the worst attempt failed (a residual above the tolerance over a negative step over
        Newton's failure)."""
        f = self.functions
        w = self.energy_parameters(t_prev, t_mid, z_prev, z_mid, drift)
        tau_prev = t_mid - t_prev
        detail = ""
        worst = Status.NEWTON_FAILED
        for attempt, factor in enumerate(RETRY_FACTORS):
            if attempt:
                self.retries += 1
            x, converged = self._solve(f.energy_root, f.energy_predict(w, factor * tau_prev), w)
            if not np.all(np.isfinite(x)):
                worst, detail = Status.NON_FINITE, f"(z, tau) = {x.tolist()}"
                continue
            if not converged:
                continue
            tau = x[-1]
            if tau <= 0:
                if worst is not Status.RESIDUAL_TOO_LARGE:
                    worst, detail = Status.NO_ADMISSIBLE_STEP, f"Newton found tau = {tau:.6g}"
                continue
            check = EnergyCheck(*(float(v) for v in f.energy_check(x, w)))
            if not self.acceptance.residuals_ok(check.canonical, check.size, check.energy,
                                                check.H_interval):
                worst, detail = Status.RESIDUAL_TOO_LARGE, (
                    f"canonical residual {check.canonical:.3e}, energy residual "
                    f"{check.energy:.3e}")
                continue
            return StepResult(Status.SUCCESS, t_next=t_mid + tau, z_next=x[:-1], tau=tau,
                              energy=check.energy, H_node=check.H_node, w_node=check.w_node)
        return StepResult.failed(worst, detail)
