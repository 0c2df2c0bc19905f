"""When the march accepts a step: one pair of predicates for the careful and the compiled path.

A step from node ``k`` with length ``tau_k`` is accepted when its own unscaled residuals are
small against the size of what they measure,

    ``|g_canonical|_inf <= tol * max(1, |z_k|_inf)``  and  ``|g_energy| <= tol * max(1, |H_k|)``,

and when its length keeps the optional bounds ``tau_min <= tau_k <= tau_max`` and
``max(tau_k / tau_{k-1}, tau_{k-1} / tau_k) <= max_step_ratio``. The predicates take scalars (a
careful step) or arrays (every step of a compiled chunk at once), so both paths apply the very
same test; `Acceptance.broken_bound` names the first bound a rejected step breaks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...solution import Status


@dataclass(frozen=True)
class Acceptance:
    """The tolerance and the step bounds of one march (``None``: no such bound)."""

    tol: float
    tau_min: float | None = None
    tau_max: float | None = None
    max_step_ratio: float | None = None

    def residuals_ok(self, canonical, size, energy=0.0, H=0.0):
        """The residual test: canonical relative to ``max(1, |z|)``, energy relative to
        ``max(1, |H|)`` (``H`` is already ``|H_k|``)."""
        return ((canonical <= self.tol * np.maximum(1.0, size))
                & (np.abs(energy) <= self.tol * np.maximum(1.0, H)))

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
