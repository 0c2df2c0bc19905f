"""An accuracy check of a trajectory that does not trust the scheme's own equations.

A march can satisfy every one of its equations and still not follow the motion: the energy
equation holds on a wrong energy level just as well as on the right one. So every trajectory is
also measured against the exact flow ``z' = f(z, t) = (H_p, -H_q)``, with three estimates:

1. **Local error of every step.** ``delta_k = |z_{k+1} - Phi_k|_inf``, where ``Phi_k`` is one
   classical Runge-Kutta step (two half steps for methods of order 3 or 4) of the exact flow from
   ``(t_k, z_k)`` over the accepted ``tau_k``. For a second-order scheme the RK4 step's own error,
   ``O(tau^5)``, is far below the scheme's ``O(tau^3)``, so ``delta_k`` is the step's local error
   up to a relative ``O(tau^2)``. A step fails when
   ``delta_k > atol + rtol * max(|z_k|_inf, |z_{k+1}|_inf)``.
2. **Energy.** ``level_error``: the energy level the first step sets (for the energy rules, the
   first interval's energy ``E_0``, kept for the whole march, so an error here is never repaired)
   against ``H(z_0, t_0)``; ``energy_drift`` (autonomous ``H`` only): ``max_k |H(z_k) - H(z_0)|``.
   Both relative to ``max(1, |H(z_0, t_0)|)``; each fails above ``energy_tol``.
3. **Global error estimate.** The signed local errors ``d_k = z_{k+1} - Phi_k`` propagated
   along the flow to first order, ``e_{k+1} = M_k e_k + d_k`` with ``M_k = dPhi_k/dz_k``
   (applied by forward differentiation), reported as ``|e_k|_inf`` and saturated at twice the
   size of the orbit. Measured against DOP853: within a factor 0.5-1.3 of the true error on
   pendulum, harmonic, henon_heiles and kepler (e = 0.5) while that error is below 0.1 (the
   sum of ``|d_k|`` missed kepler's by a factor 10-25: the flow shears an energy error into a
   growing phase error). It is checked only against ``global_tol`` when one is given: over long
   horizons the phase error of any scheme grows past every trajectory tolerance while the orbit
   stays right (the paper's own example: a true error of 1.5 at t = 1000).

The check runs as a monitor of the step loop (``driver.py``), on the nodes each call of the
stepper accepted, so it stops a march at the first step that fails (or, with ``stop=False``,
records the first failure and lets the march go on). The march's compiled chunk computes the
estimates with its steps (``chunk.py``: the same `local_error_function`, the error vector
in the chunk's state) and hands them over in ``Advance.values`` (``ACCURACY_VALUES``); where they
are absent (the careful path, a finished trajectory) the monitor computes them itself, with a
compiled CasADi function mapped over blocks of nodes.
"""

from __future__ import annotations

import math
from dataclasses import replace
from types import SimpleNamespace

import casadi as ca
import numpy as np

from ..cache import cached
from ..discrete.runge_kutta import rk4
from ..physics.hamiltonian import vector_field_function
from ..solution import Status
from .compiler import (
    CompileUnavailable,
    FunctionBuffer,
    buffered,
    cache_folder,
    compile_function,
    warn_once,
)
from .options import Tolerance

BLOCK = 1024  # nodes per call of the compiled estimate (the last block is padded)
SMALL = 16  # fewer steps than this go one by one, unpadded
# The per-step estimates a stepper may hand the monitor in ``Advance.values``: ``delta``,
# ``scale``, ``H_new``, ``global_error`` (each (m,)) and ``error`` (m, 2n), the error vector
# after each step.
ACCURACY_VALUES = ("delta", "scale", "H_new", "global_error", "error")
ADVICE = ("try a smaller tau0, fixed steps (--scheme fixed), or the least-squares step "
          "(--least-squares); --accept-inaccurate (accept_inaccurate=True) records the estimates "
          "and goes on")


def local_error_function(system, substeps: int = 1) -> ca.Function:
    """``(e, z_a, z_b, t_a, tau, theta) -> (e_next, delta, scale, H_b)`` of the step from
    ``z_a`` to ``z_b``: the propagated global error ``e_next = M e + d`` (``d = z_b - Phi``,
    ``M = dPhi/dz_a`` applied by forward differentiation), ``delta = |d|_inf``,
    ``max(|z_a|, |z_b|)`` and ``H`` at the new node."""
    def build():
        n2 = 2 * system.n
        field = vector_field_function(system)
        e, z_a, z_b = ca.SX.sym("e", n2), ca.SX.sym("z_a", n2), ca.SX.sym("z_b", n2)
        t_a, tau = ca.SX.sym("t_a"), ca.SX.sym("tau")
        theta = ca.SX.sym("theta", system.theta.numel())

        def flow(z, t):
            return field(z, t, theta)

        phi, h = z_a, tau / substeps
        for i in range(substeps):
            phi = rk4(flow, phi, t_a + i * h, h)
        d = z_b - phi
        e_next = ca.jtimes(phi, z_a, e) + d
        scale = ca.fmax(ca.norm_inf(z_a), ca.norm_inf(z_b))
        # Saturate: an error cannot exceed the size of the region the orbit crosses, but the
        # linear propagation grows without bound where the flow separates orbits (the paper's
        # pendulum near its separatrix: 3e11 against a true 1.5 at t = 1000).
        limit = 2 * ca.fmax(1, scale)
        e_next = e_next * ca.fmin(1, limit / ca.fmax(ca.norm_inf(e_next), 1e-300))
        H_b = system.H_function(z_b[:system.n], z_b[system.n:], t_a + tau, theta)
        return ca.Function("local_error", [e, z_a, z_b, t_a, tau, theta],
                           [e_next, ca.norm_inf(d), scale, H_b],
                           ["e", "z_a", "z_b", "t_a", "tau", "theta"],
                           ["e_next", "delta", "scale", "H_b"])
    return cached(system, ("local_error", substeps), build)


class ErrorEstimates:
    """The local error estimates and the propagated global error of many steps at once: a
    compiled ``mapaccum`` over ``BLOCK`` steps (CasADi's virtual machine where no compiler is
    given), carrying the global error vector ``e`` from block to block.

    ``e_{k+1} = M_k e_k + d_k`` is the first-order propagation of the step errors along the
    flow: it sees what adding up ``|d_k|`` cannot, how the flow shears errors (a small error of
    the energy becomes a phase error that grows linearly, as on Kepler orbits)."""

    def __init__(self, system, substeps: int = 1, *, compiler=None, cache_dir=None):
        self.system = system
        self.e = np.zeros(2 * system.n)
        self.single = local_error_function(system, substeps)
        self.substeps = substeps
        self.compiler, self.cache_dir = compiler, cache_dir
        self._buffer = None

    @property
    def buffer(self) -> FunctionBuffer:
        """The block function, built (and compiled) at its first use: a march whose chunk
        computes the estimates never needs it."""
        if self._buffer is None:
            function = self.single.mapaccum("error_block", BLOCK)
            if self.compiler is not None:
                key = ("error_block", self.substeps, self.compiler, str(self.cache_dir))
                try:
                    function = cached(self.system, key, lambda: compile_function(
                        function, self.compiler, cache_folder(self.cache_dir),
                        prefix="accuracy"))
                except CompileUnavailable as reason:  # the virtual machine computes the same
                    warn_once(reason)
            self._buffer = FunctionBuffer(function)
        return self._buffer

    def __call__(self, t: np.ndarray, z: np.ndarray, theta: np.ndarray):
        """For the steps between the rows of ``t`` (M+1,) and ``z`` (M+1, 2n), continuing the
        propagation from the previous call: ``delta``, ``scale``, ``H`` of the new node and the
        global error estimate ``|e_{k+1}|_inf``, four arrays of shape (M,)."""
        steps = t.size - 1
        if steps < SMALL:
            return self._one_by_one(t, z, theta)
        out = np.empty((4, max(steps, 0)))
        theta_block = np.broadcast_to(np.asarray(theta, float), (BLOCK, np.size(theta)))
        for start in range(0, steps, BLOCK):
            stop = min(start + BLOCK, steps)
            count = stop - start
            z_a, z_b = _padded(z[start:stop]), _padded(z[start + 1:stop + 1])
            t_a = _padded(t[start:stop])
            tau = _padded(np.diff(t[start:stop + 1]))
            e, delta, scale, H_b = self.buffer(self.e, z_a, z_b, t_a, tau, theta_block)
            self.e = e[count - 1].copy()
            out[0, start:stop] = delta[:count, 0]
            out[1, start:stop] = scale[:count, 0]
            out[2, start:stop] = H_b[:count, 0]
            out[3, start:stop] = np.max(np.abs(e[:count]), axis=1)
        return out[0], out[1], out[2], out[3]

    def _one_by_one(self, t, z, theta):
        """Few steps (the careful path's one at a time): the single-step function, no padding."""
        steps = t.size - 1
        out = np.empty((4, steps))
        single = buffered(self.single, "local_error", self.substeps, owner=self.system)
        for k in range(steps):
            # through Function.buffer: the same evaluation without a DM for each argument and
            # result (a call cost 100 us of a 2 ms short march; the careful path makes one a step)
            e, delta, scale, H_b = single(self.e, z[k], z[k + 1], t[k], t[k + 1] - t[k], theta)
            self.e = e[0].copy()
            out[:, k] = (delta[0, 0], scale[0, 0], H_b[0, 0], np.max(np.abs(self.e)))
        return out[0], out[1], out[2], out[3]


def _finite_or_none(value: float) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


class _Series:
    """Per-step values, appended block by block into one array that grows by doubling: no list
    of blocks that are views of (and keep alive) whole batches of a compiled chunk's outputs,
    and no concatenation each time they are read."""

    def __init__(self):
        self.data = np.empty(0)
        self.count = 0

    def append(self, values: np.ndarray):
        end = self.count + values.size
        if end > self.data.size:
            data = np.empty(max(2 * self.data.size, end, BLOCK))
            data[:self.count] = self.data[:self.count]
            self.data = data
        self.data[self.count:end] = values
        self.count = end

    def head(self, count: int) -> np.ndarray:
        """A copy of ``values[:count]`` (all there are, if fewer)."""
        return self.data[:self.count][:count].copy()


def _padded(values: np.ndarray) -> np.ndarray:
    """``values`` (rows) repeated from its last row up to ``BLOCK`` rows."""
    extra = BLOCK - values.shape[0]
    if extra == 0:  # a full block: no copy (np.pad cost 80 us a call)
        return values
    return np.pad(values, [(0, extra)] + [(0, 0)] * (values.ndim - 1), mode="edge")


class AccuracyMonitor:
    """The accuracy check as a monitor of the step loop (``driver.py``, rule 5).

    ``level`` is ``None`` for schemes without an energy level (fixed steps), else a function of
    the first two nodes ``(t, z)`` giving the level the first step sets."""

    def __init__(self, system, theta, tolerance: Tolerance, *, H0: float, level=None,
                 substeps: int = 1, compiler=None, cache_dir=None, errors=None):
        self.system = system
        self.theta = np.asarray(theta, float)
        self.tolerance = tolerance
        self.H0 = H0
        self.energy_scale = max(1.0, abs(H0))
        self.level_of = level
        self.autonomous = not system.time_dependent
        if errors is None:
            errors = ErrorEstimates(system, substeps, compiler=compiler, cache_dir=cache_dir)
        self.errors = errors
        self.delta = _Series()  # delta_k of every step watched
        self.global_errors = _Series()  # |e_k|_inf
        self.level = None
        self.level_error = math.nan
        self.energy_drift = 0.0 if self.autonomous else math.nan
        self.size = 0.0
        self.failure = None  # the first failed test: {"step", "t", "test", "value", "limit"}

    # -- the monitor -------------------------------------------------------------------------
    def watch(self, nodes, first: int, advance):
        start = max(first - 1, 0)  # the new steps run from node start to nodes.count - 1
        t, z = nodes.t[start:nodes.count], nodes.z[start:nodes.count]
        if t.size < 2:
            return None
        if start == 0 and self.level_of is not None:
            self.level = float(self.level_of(t[:2], z[:2]))
            self.level_error = abs(self.level - self.H0) / self.energy_scale
        delta, scale, H, globals_ = self._estimates(t, z, advance)
        self.delta.append(delta)
        self.global_errors.append(globals_)
        self.size = max(self.size, float(scale.max()))
        failure = self._first_failure(start, t, delta, scale, H, globals_)
        if failure is None or self.failure is not None:
            return None
        self.failure = failure
        if not self.tolerance.stop:
            return None
        keep = failure["step"] + 1 - first + 1  # the nodes up to the end of the failing step
        return Status.INACCURATE, self.describe(failure), max(keep, 0)

    def _estimates(self, t, z, advance):
        """The stepper's own estimates of these steps if it computed them (a compiled chunk),
        else this check's; either way ``errors.e`` ends at the newest node."""
        values = advance.values if advance is not None else {}
        if "delta" in values and values["delta"].size == t.size - 1:
            self.errors.e = values["error"][-1].copy()
            return values["delta"], values["scale"], values["H_new"], values["global_error"]
        return self.errors(t, z, self.theta)

    def _first_failure(self, start, t, delta, scale, H, globals_):
        """The first step among these that fails a test, as a dict, or None."""
        tol = self.tolerance
        candidates = []
        # No step fails the local test when the largest delta passes the smallest bound
        # (``atol + rtol * scale`` rounds monotonically in ``scale``; a NaN fails this pre-test
        # and goes to the full one): two reductions instead of five array operations.
        if not delta.max() <= tol.atol + tol.rtol * scale.min():
            local = delta > tol.atol + tol.rtol * scale
            if np.any(local):
                i = int(np.argmax(local))
                candidates.append((i, "local error", delta[i], tol.atol + tol.rtol * scale[i]))
        if start == 0 and self.level is not None:
            if self.level_error > tol.energy_tol:
                candidates.append((0, "energy level of the first step", self.level_error,
                                   tol.energy_tol))
        if self.autonomous:
            drift_max = self._largest_drift(H)
            if drift_max is None or drift_max > tol.energy_tol:  # find the node
                drift = np.abs(H - self.H0) / self.energy_scale
                drift_max = float(np.max(drift))
                over = drift > tol.energy_tol
                if np.any(over):
                    i = int(np.argmax(over))
                    candidates.append((i, "nodal energy drift", drift[i], tol.energy_tol))
            self.energy_drift = max(self.energy_drift, drift_max)
        if tol.global_tol is not None:
            relative = globals_ / np.maximum(1.0, scale)
            over = relative > tol.global_tol
            if np.any(over):
                i = int(np.argmax(over))
                candidates.append((i, "global error estimate", relative[i], tol.global_tol))
        if not candidates:
            return None
        i, test, value, limit = min(candidates, key=lambda c: c[0])
        return {"step": start + i, "t": float(t[i]), "test": test, "value": float(value),
                "limit": float(limit)}

    def _largest_drift(self, H) -> float | None:
        """``max |H - H0| / max(1, |H0|)`` from the extremes of ``H`` (the same number:
        subtraction and division round monotonically), or ``None`` if ``H`` holds a NaN."""
        high, low = float(H.max()), float(H.min())
        if math.isnan(high) or math.isnan(low):
            return None
        return max(high - self.H0, self.H0 - low) / self.energy_scale

    # -- what it found -----------------------------------------------------------------------
    def local_errors(self, steps: int) -> np.ndarray:
        """``delta_k`` of the first ``steps`` steps."""
        return self.delta.head(steps)

    def global_error(self, steps: int) -> np.ndarray:
        """``|e_k|_inf`` at the nodes ``1 .. steps``: the propagated global error estimate."""
        return self.global_errors.head(steps)

    @staticmethod
    def describe(failure) -> str:
        return (f"the {failure['test']} of step {failure['step']} (from t = "
                f"{failure['t']:.10g}) is {failure['value']:.3e} > {failure['limit']:.3e}; "
                + ADVICE)

    def report(self, steps: int) -> dict:
        """The estimates of a run of ``steps`` steps, for ``Solution.stats["accuracy"]``."""
        delta = self.local_errors(steps)
        propagated = self.global_error(steps)
        tol = self.tolerance
        return {"verdict": "inaccurate" if self.failure else "accurate",
                "first_failure": self.failure,
                # None, not NaN, where a figure does not apply (strict JSON has no NaN)
                "level": self.level, "level_error": _finite_or_none(self.level_error),
                "energy_drift": _finite_or_none(self.energy_drift),
                "local_error_max": float(delta.max()) if delta.size else 0.0,
                "local_error_sum": float(delta.sum()),
                "global_error_estimate": float(propagated[-1]) if propagated.size else 0.0,
                "global_error_estimate_max": float(propagated.max()) if propagated.size else 0.0,
                # at its cap: the estimate only says the error is as large as the orbit
                "global_error_saturated": bool(propagated.size and propagated[-1]
                                               >= 2 * max(1.0, self.size) * (1 - 1e-9)),
                "orbit_size": float(max(1.0, self.size)),
                "rtol": tol.rtol, "atol": tol.atol, "energy_tol": tol.energy_tol,
                "global_tol": tol.global_tol}


def assess(system, t, z, theta, tolerance: Tolerance, *, level=None, substeps: int = 1,
           compiler=None, cache_dir=None) -> tuple[dict, np.ndarray]:
    """The accuracy check on a finished trajectory of any method (``t`` (N,), ``z`` (N, 2n)),
    without stopping it: the report of `AccuracyMonitor.report` and the local errors.
    ``level`` is the energy level the method keeps, if it keeps one (a number)."""
    H0 = float(system.energy(z[:1, :system.n], z[:1, system.n:], t[:1], theta)[0])
    monitor = AccuracyMonitor(system, theta, replace(tolerance, stop=False), H0=H0,
                              level=None if level is None else (lambda t, z: level),
                              substeps=substeps, compiler=compiler, cache_dir=cache_dir)

    if t.size >= 2:  # the finished trajectory, seen by the monitor as one call's new nodes
        monitor.watch(SimpleNamespace(t=t, z=z, count=t.size), 1, None)
    steps = t.size - 1
    return monitor.report(steps), monitor.local_errors(steps)
