"""When the march accepts a step: one pair of predicates for the careful and the compiled path.

A step from node ``k`` with length ``tau_k`` is accepted when its own unscaled residuals are
small against the size of what they measure,

    ``|g_canonical|_inf <= tol * max(|z_k|_inf, Z)``  and  ``|g_energy| <= tol * max(|H_k|, E)``,

and when its length keeps the optional bounds ``tau_min <= tau_k <= tau_max`` and
``max(tau_k / tau_{k-1}, tau_{k-1} / tau_k) <= max_step_ratio``. The predicates take scalars (a
careful step) or arrays (every step of a compiled chunk at once), so both paths apply the very
same test; `Acceptance.broken_bound` names the first bound a rejected step breaks.

**The scales come from the problem, never from 1** (`start_scales`). A floor of 1 in the units
of the state let a motion of size 1e-6 pass residuals 1e6 times its own round-off, and made the
verdict depend on the units. Each row is judged against the magnitudes it is computed from: the
node's own ``|z_k|_inf`` and ``|H_k|`` (the interval energy), joined with two scales of the run
taken at its start:

- ``Z = max(|q_0|_inf, |p_0|_inf, |dz_0|_inf)``, ``dz_0`` the motion of the first step (the
  march's RK4 predictor over ``tau0`` from ``z_0``): a start at ``q = 0`` or ``p = 0`` is still
  judged against the size of its motion, and a start at rest off an equilibrium against how far
  it moves in its first step;
- ``E = sum_i (Q |dH/dq_i| + P |dH/dp_i|)`` at ``(z_0, t_0)``, ``Q = max(|q_0|_inf,
  |dq_0|_inf)``, ``P = max(|p_0|_inf, |dp_0|_inf)``: how much ``H`` changes when the state moves
  by its own size (its kinetic part is ``|p . dH/dp|``, twice the kinetic energy of a natural
  system). It does not vanish when ``H_k`` happens to be 0 and does not change when a constant
  is added to ``H``. It is never below ``ROUNDOFF_ALLOWANCE * eps * e_H / tol``, ``e_H`` the
  running error bound of ``H``'s own evaluation at the start (`physics.roundoff`): an energy
  row cannot be asked for less than the round-off of the values of ``H`` it differences (the
  pendulum's ``1 - cos q`` at small amplitude is computed from terms of size 1).

Both scale with the state and ``H`` under a change of units of ``q``, ``p``, ``t`` and ``H`` by
one factor, so the same motion in metres and in micrometres accepts the same steps; adding a
constant to ``H`` or translating a translation-invariant system raises only the magnitudes the
rows' round-off genuinely grows with (``|H_k|``, ``|q|``). The inf-norms mix the ``q`` and ``p``
rows, as the check's outputs do: with ``q`` and ``p`` in very different units the block of the
smaller units is judged against the larger. A state at rest at an equilibrium has ``Z = E = 0``:
its exact motion is the state itself, its residuals are exactly zero and pass ``0 <= 0`` (a
fixed-step march stays there; an energy rule's step length is then undetermined and the march
says so with its usual failure status).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...solution import Status


@dataclass(frozen=True)
class Acceptance:
    """The tolerance, the step bounds (``None``: no such bound) and the run's scales ``Z``
    (``z_scale``) and ``E`` (``H_scale``) of one march (module docstring; `at_start` takes them
    from the start, 0 leaves each row to its node's own magnitude)."""

    tol: float
    tau_min: float | None = None
    tau_max: float | None = None
    max_step_ratio: float | None = None
    z_scale: float = 0.0
    H_scale: float = 0.0
    H_motion: float = 0.0  # E from the motion alone, before the round-off floor
    H_roundoff: float = 0.0  # eps e_H, the round-off bound of one evaluation of H
    step_fraction: float = 0.0  # |dz_0|_inf / Z, how far the first step moves against Z

    @classmethod
    def at_start(cls, steps, system, q0, p0, t0: float, tau0: float, theta) -> Acceptance:
        """The acceptance test of a march of ``steps`` (a `StepControl`) from ``(q0, p0)`` at
        ``t0`` with first step ``tau0``: its bounds and the scales of `start_scales`."""
        z_scale, H_motion, H_roundoff, step = start_values(system, q0, p0, t0, tau0, theta)
        return cls(steps.tol, steps.tau_min, steps.tau_max, steps.max_step_ratio, z_scale,
                   _energy_scale(H_motion, H_roundoff, steps.tol), H_motion, H_roundoff, step)

    def residuals_refused(self, canonical, size, energy=None, H=0.0) -> str:
        """Why a step's residuals fail `residuals_ok`, each beside what it was allowed, and,
        where the energy equation of this motion changes over a step by no more than the
        round-off of ``H``, that round-off then sets the step length."""
        allowed = self.tol * max(self.z_scale, size)
        words = f"canonical residual {canonical:.3e} (allowed {allowed:.3e})"
        if energy is None:
            return words
        words += (f", energy residual {energy:.3e} (allowed "
                  f"{self.tol * max(self.H_scale, H):.3e})")
        # The energy equation's dependence on the step length is second order in it (about
        # E (|dz|/Z)^2 over a step, docs/theory.md section 7): where that is within the
        # round-off of the evaluations of H it differences, the step length it sets is round-off
        sensitivity = self.H_motion * self.step_fraction ** 2
        if self.H_roundoff and sensitivity < ROUNDOFF_ALLOWANCE * self.H_roundoff:
            words += (f"; the energy equation changes by about {sensitivity:.2e} over a step, "
                      f"less than {ROUNDOFF_ALLOWANCE:g} times the round-off bound of one "
                      f"evaluation of H ({self.H_roundoff:.2e}), so round-off sets the step "
                      "length: march with fixed steps (scheme 'fixed'), or write H so that it "
                      "is not a difference of large terms (2 sin(q/2)**2 for 1 - cos q)")
        return words

    def residuals_ok(self, canonical, size, energy=0.0, H=0.0):
        """The residual test: canonical relative to ``max(|z_k|, Z)``, energy relative to
        ``max(|H_k|, E)`` (``size`` is ``|z_k|_inf``, ``H`` is already ``|H_k|``)."""
        return ((canonical <= self.tol * np.maximum(self.z_scale, size))
                & (np.abs(energy) <= self.tol * np.maximum(self.H_scale, H)))

    def bounds_ok(self, tau, tau_prev):
        """Which steps keep ``tau_min``, ``tau_max`` and ``max_step_ratio`` (``tau_prev`` is
        ``None`` for a first step, which has no ratio)."""
        ok = np.ones(np.shape(tau), dtype=bool)
        if self.tau_min is not None:
            ok &= tau >= self.tau_min
        if self.tau_max is not None:
            ok &= tau <= self.tau_max
        if self.max_step_ratio is not None and tau_prev is not None:
            with np.errstate(invalid="ignore", divide="ignore"):
                ok &= np.maximum(tau / tau_prev, tau_prev / tau) <= self.max_step_ratio
        return ok

    def broken_bound(self, tau: float, tau_prev: float | None) -> tuple[Status, str]:
        """Status and detail of the first bound a step breaks (``SUCCESS`` if none)."""
        if self.bounds_ok(tau, tau_prev):
            return Status.SUCCESS, ""
        if self.tau_min is not None and tau < self.tau_min:
            return Status.STEP_BELOW_MIN, f"tau = {tau:.6g} < tau_min = {self.tau_min:.6g}"
        if self.tau_max is not None and tau > self.tau_max:
            return Status.STEP_ABOVE_MAX, f"tau = {tau:.6g} > tau_max = {self.tau_max:.6g}"
        ratio = max(tau / tau_prev, tau_prev / tau)
        return Status.STEP_RATIO, (f"tau = {tau:.6g} after {tau_prev:.6g} (ratio "
                                   f"{ratio:.4g} > max_step_ratio {self.max_step_ratio})")


def start_scales(system, q0, p0, t0: float, tau0: float, theta,
                 tol: float | None = None) -> tuple[float, float]:
    """``(Z, E)``, the run's scales of the canonical and the energy residual (module
    docstring; `start_values`). Given the tolerance ``tol``, ``E`` is at least
    ``ROUNDOFF_ALLOWANCE * eps * e_H / tol``: no tolerance asks an energy row for less than
    the round-off of the evaluations of ``H`` it is computed from."""
    z_scale, H_motion, H_roundoff, _ = start_values(system, q0, p0, t0, tau0, theta)
    return z_scale, _energy_scale(H_motion, H_roundoff, tol)


def _energy_scale(H_motion: float, H_roundoff: float, tol: float | None) -> float:
    """``E``: the motion's, floored at the round-off a tolerance ``tol`` may not ask below."""
    if tol is None or not tol > 0:
        return H_motion
    return max(H_motion, ROUNDOFF_ALLOWANCE * H_roundoff / tol)


def start_values(system, q0, p0, t0: float, tau0: float,
                 theta) -> tuple[float, float, float, float]:
    """``(Z, E_motion, eps e_H, |dz_0|_inf / Z)`` from the start ``(q0, p0)`` at ``t0``, the
    first step ``tau0`` and the parameters ``theta`` (module docstring): one call of a function
    built once per system (the march's RK4 predictor over ``tau0``, the vector field and the
    round-off bound ``e_H`` of ``H`` at the start), whatever the scheme."""
    q0, p0 = np.asarray(q0, float).ravel(), np.asarray(p0, float).ravel()
    n = q0.size
    z0 = np.concatenate([q0, p0])
    theta = np.asarray(theta, float).ravel()
    moved, slope = (np.asarray(v, float).ravel() for v in _start_motion(system)(
        z0, t0, tau0, theta))
    bound = _H_roundoff(system)
    roundoff = bound(q0, p0, t0, theta) if bound is not None else 0.0
    Q = max(_largest(q0), _largest(moved[:n]))
    P = max(_largest(p0), _largest(moved[n:]))
    # f = (H_p, -H_q): |dH/dq_i| = |f_{n+i}|, |dH/dp_i| = |f_i|
    energy = Q * _total(slope[n:]) + P * _total(slope[:n])
    energy = energy if np.isfinite(energy) else 0.0
    Z = max(Q, P)
    roundoff = EPS * roundoff if np.isfinite(roundoff) else 0.0
    return Z, energy, roundoff, _largest(moved) / Z if Z > 0 else 0.0


# How many times the first-order round-off bound of one evaluation of H an energy row may hold:
# the row differences a few evaluations of H (the interval energies of two steps) and Newton
# leaves it at the round-off of its last evaluation
ROUNDOFF_ALLOWANCE = 16.0
EPS = float(np.finfo(float).eps)


def _start_motion(system):
    """``(z0, t0, tau0, theta) -> (RK4 step - z0, f(z0, t0))``, built once per system."""
    import casadi as ca

    from ...cache import cached
    from ...discrete.runge_kutta import rk4
    from ...physics.hamiltonian import vector_field_function

    def build():
        f = vector_field_function(system)
        z, t, tau = ca.SX.sym("z", 2 * system.n), ca.SX.sym("t"), ca.SX.sym("tau")
        theta = ca.SX.sym("theta", system.theta.numel())
        step = rk4(lambda y, s: f(y, s, theta), z, t, tau)
        return ca.Function("start_motion", [z, t, tau, theta], [step - z, f(z, t, theta)])
    return cached(system, "start_motion", build)


def _H_roundoff(system):
    """The running error bound of ``H`` without its constant terms (the one the energy rows
    difference), `physics.roundoff.roundoff_bound` in ``(q, p, t)``, read once per system;
    ``None`` where ``H`` has an operation without a scalar rule."""
    from ...cache import cached
    from ...physics.roundoff import roundoff_bound

    def build():
        try:
            return roundoff_bound(system.H_varying_function, (0, 1, 2))
        except ValueError:
            return None
    return cached(system, "H_roundoff", build)


def _largest(values: np.ndarray) -> float:
    """``|values|_inf`` over the finite entries (0 for none): a predictor that diverges over
    the first step gives no scale, rather than an infinite one that would pass any residual."""
    return float(np.max(np.abs(values[np.isfinite(values)]), initial=0.0))


def _total(values: np.ndarray) -> float:
    """``sum |values|`` over the finite entries."""
    return float(np.sum(np.abs(values[np.isfinite(values)])))
