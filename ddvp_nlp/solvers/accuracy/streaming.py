"""The accuracy check of a march fed a window of nodes at a time: the check of a thinned march
(``Output(keep_every=k)``), whose nodes are dropped as it goes and so cannot be judged whole
at the end.

Every node is judged once, in order, by the tests of ``judgement.py``; between windows only
bounded state is kept (a few numbers per component, never per node):

- **scales**: the least and greatest value and the largest magnitude of each component over the
  nodes so far and the reference's states (`Extent`, `Scan`): exactly the whole run's at the
  end, since they only grow;
- **local error**: the largest ``|d_k,i|`` of each component (so the largest error relative to
  the final scales is exact) and the steps that fail the bound of the scales known when their
  window came (at most ``CANDIDATES``): a step that fails with the final scales failed with the
  smaller ones then, so the first of them that still fails is the whole run's first failure.
  The RK4 screen passes a step below ``CANDIDATE`` times the bound of the scales then: a step
  it passes passes the final bound too;
- **energy**: ``H(z_0)``, the largest ``|H - H_0|`` and the first nodes that pass half the
  bound at the scale then (``CANDIDATES``); the energy scale ``E_s`` is the time average of
  ``|S * grad H|``, summed window by window **with the scales known when the window came**
  (the one figure that is not the whole run's: the whole run's weights each node by the final
  scales; for a motion that has shown its range in the first window, every periodic one, they
  are the same);
- **trajectory error**: the reference flow grows with the nodes (`GrowingReference`), its
  tolerance ``atol`` set by the first window's scales, and a `Scan` measures each window; once
  the error drifts the reference stops. Where the reference's own error passes its share (a
  chaotic orbit), the whole-run check integrates again 100 times tighter; a streamed one cannot
  go back and reports the run drifted from there.
"""

from __future__ import annotations

import numpy as np

from ..columns import column_extremes
from ..exact.reference import FACTOR, GrowingReference
from .judgement import (
    REFERENCE_RTOL,
    ROUND_OFF,
    Extent,
    Judgement,
    Level,
    Scan,
    energy_varies,
    finite_or_none,
    gradient_sizes,
    step_differences,
    unjudged,
    verdict_report,
)

# Steps (and nodes) failing the bound of their window's scales that are kept to be judged again
# with the final scales: the first of them that still fails is the run's first failure.
CANDIDATES = 256


class StreamingJudgement:
    """The check of `Judgement` fed in windows (module docstring): `feed` each window of
    consecutive nodes (each starting with the last node of the one before), then `report`."""

    def __init__(self, judge: Judgement, *, screen: bool, exact=None, level=None):
        self.judge, self.screen, self.exact = judge, screen, exact
        self.level_of = level  # level(t, z) -> Level | None, from the first two nodes
        self.tol = judge.tolerance
        self.n = judge.system.n
        self.level: Level | None = None
        self.extent = None
        self.scan = None
        self.growing = None
        self.piece = None
        self.steps = 0
        self.t0 = None
        self.z0 = None
        self.finite = True
        self.column_max = None  # largest |d_k,i| of each component
        self.local_candidates: list = []  # (step, t, |d| row)
        self.H0 = None
        self.H_drift_max, self.H_abs_max = 0.0, 0.0
        self.energy_candidates: list = []  # (node, t, |H - H0|)
        self.energy_sum, self.weight_sum = 0.0, 0.0

    def feed(self, t: np.ndarray, z: np.ndarray, offset: int) -> np.ndarray:
        """Judge the steps of the window ``t`` (m+1,), ``z`` (m+1, 2n), node ``offset`` of the
        run first; returns ``|d_k|_inf`` of its ``m`` steps."""
        steps = t.size - 1
        if steps < 1:
            return np.zeros(0)
        if not (np.all(np.isfinite(z)) and np.all(np.isfinite(t))):
            self.finite = False
        if not self.finite:
            return np.full(steps, np.nan)
        judge = self.judge
        if self.extent is None:
            self.t0, self.z0 = float(t[0]), z[0].copy()
            self.extent = Extent(z, judge.free)  # winding angles: whole runs only (not streamed)
            self.level = self.level_of(t, z) if self.level_of else None
        else:
            low, high, largest = column_extremes(z)
            np.minimum(self.extent.low, low, out=self.extent.low)
            np.maximum(self.extent.high, high, out=self.extent.high)
            np.maximum(self.extent.largest, largest, out=self.extent.largest)
        self._trajectory(t, z, offset)
        scale = self.scan.scales()
        look = judge.values.first_look(t, z) if self.screen else None
        field, H = look[1:] if look is not None else judge.values.at_nodes(t, z)
        d, local, _, ratio = step_differences(judge, t, z, scale, look)
        seen = np.max(d, axis=0)
        self.column_max = seen if self.column_max is None else np.fmax(self.column_max, seen)
        for k in np.flatnonzero(~(ratio <= 1.0))[:CANDIDATES - len(self.local_candidates)]:
            self.local_candidates.append((offset + int(k), float(t[k]), d[k].copy()))
        self._energy(t, field, H, scale, offset)
        self.steps += steps
        return local

    def _energy(self, t, field, H, scale, offset):
        n = self.n
        if self.H0 is None:
            self.H0 = float(H[0])
        weights, norm = gradient_sizes(t, field, scale, n, self.judge.free, self.judge.kernel())
        self.energy_sum += float(np.sum(weights * norm))
        self.weight_sum += float(np.sum(weights))
        self.H_abs_max = max(self.H_abs_max, float(np.max(np.abs(H))))
        if energy_varies(self.judge.system):
            return
        drift = np.abs(H - self.H0)
        self.H_drift_max = max(self.H_drift_max, float(np.max(drift)))
        bound = 0.5 * self.tol.energy_tol * self._energy_scale()
        for k in np.flatnonzero(~(drift <= bound))[:CANDIDATES - len(self.energy_candidates)]:
            self.energy_candidates.append((offset + int(k), float(t[k]), float(drift[k])))

    def _energy_scale(self) -> float:
        typical = self.energy_sum / self.weight_sum if self.weight_sum > 0 else 0.0
        if not np.isfinite(typical):
            return np.inf
        return max(typical, ROUND_OFF * self.H_abs_max, np.finfo(float).tiny)

    def _trajectory(self, t, z, offset):
        """The window's nodes against the exact solution or the growing reference."""
        if self.scan is None:
            self.scan = Scan(self.extent, self.n, self.tol.global_tol, self.judge.kernel())
            if self.exact is None:
                self.rtol = REFERENCE_RTOL
                self.growing = GrowingReference(self.judge.flow(), z[0], t[0], t[-1],
                                                self.judge.theta, self.extent.scales(self.n),
                                                rtol=self.rtol)
        scan = self.scan
        low, high, largest = column_extremes(z)  # the scan's scales: every node's so far
        np.minimum(scan.low, low, out=scan.low)
        np.maximum(scan.high, high, out=scan.high)
        np.maximum(scan.largest, largest, out=scan.largest)
        if scan.stopped:
            return
        last = t.size - 1
        if self.exact is not None:
            states = np.asarray(self.exact(t[1:]), float).reshape(last, -1)
            scan.measure(t, z, 0, last, states, np.zeros(last), offset)
            return
        growing, start = self.growing, 0
        while start < last and not scan.stopped:
            if self.piece is None or (t[start + 1] > growing.reached and not growing.failed):
                if growing.done:  # nodes past where the reference was asked to end
                    growing.t_end, growing.done = float(t[last]), False
                self.piece = growing.advance()
                if growing.done and t[last] > growing.reached:
                    growing.t_end, growing.done = float(t[last]), False
            end = last if t[last] <= growing.reached else \
                int(np.searchsorted(t, growing.reached, side="right")) - 1
            if growing.failed:  # the first node past where the flow stopped is lost
                end = min(max(end, start) + 1, last)
            if end > start:
                with np.errstate(invalid="ignore", over="ignore"):
                    states, claim = growing.at(self.piece, t[start + 1:end + 1])
                    scan.measure(t, z, start, end, states, claim, offset)
                start = end

    def report(self, t_last: float) -> dict:
        """The report of `Judgement.report` over every node fed (``t_last``: the last node's
        time), ``"streamed": True``."""
        tol = self.tol
        if self.steps < 1 or not self.finite:
            t = np.array([self.t0 if self.t0 is not None else t_last])
            report = unjudged(t, np.full((1, 1), 1.0 if self.finite else np.nan), tol)
            report["steps"] = self.steps
            return {**report, "streamed": True}
        found = self.scan.figures(self.t0, "exact solution" if self.exact is not None else "")
        if self.exact is None:
            found["estimate"] = (
                f"reference flow (adaptive order-8 Runge-Kutta, DOP853 at rtol "
                f"{self.rtol / FACTOR:.0e}, {self.growing.steps} steps, grown with the march; "
                f"its own error at most {found['reference_error']:.1e} of the motion's size)")
        scale = found["scale"]
        limit = tol.rtol * scale + (tol.atol or 0.0)
        failure = None
        for step, time, d in self.local_candidates:
            if not np.all(d <= limit):
                failure = {"step": step, "t": time, "test": "local error",
                           "value": float(np.max(d / scale)), "limit": tol.rtol}
                break
        energy = self._energy_scale()
        energies = self.judge.energies(np.array([self.t0]), self.z0[None, :],
                                        np.array([self.H0]), energy, self.level, scale)
        figures, failures = energies["figures"], energies["failures"]
        if not energy_varies(self.judge.system):
            figures["energy_drift"] = finite_or_none(self.H_drift_max / energy)
            over = [c for c in self.energy_candidates if not c[2] / energy <= tol.energy_tol]
            if over or not self.H_drift_max / energy <= tol.energy_tol:
                node, time, value = over[0] if over else (None, None, self.H_drift_max)
                failures.append({"step": max(node - 1, 0) if node is not None else None,
                                 "t": time, "test": "nodal energy drift",
                                 "value": float(value / energy), "limit": tol.energy_tol})
        failures = [f for f in (failure, *failures) if f is not None]
        first = min(failures, key=lambda f: f["step"] if f["step"] is not None else
                    self.steps) if failures else None
        column_max = np.where(np.isfinite(self.column_max), self.column_max, 0.0)
        return {**verdict_report(first, found, scale, energy,
                                 float(np.max(column_max / scale, initial=0.0)), figures,
                                 self.steps, tol), "streamed": True}

