"""The accuracy check: a verdict on a trajectory that does not trust the scheme's own equations.

A march can satisfy every one of its equations and still not follow the motion: the energy
equation holds on a wrong energy level just as well as on the right one. So every trajectory is
judged against the exact flow ``z' = f(z, t) = (H_p, -H_q)`` (``reference.py``: an order-8
Runge-Kutta integration, compiled, its own error controlled by step doubling), and gets one of
three verdicts:

- ``accurate``: the trajectory error stays within ``global_tol`` of the motion's size over the
  whole run;
- ``drifted``: every step follows the flow and the energy is right, but the trajectory error
  passes ``global_tol`` from ``t_drift`` on (a phase error: over long horizons every scheme's
  phase error outgrows every tolerance while the orbit stays right);
- ``inaccurate``: a step does not follow the flow, or the energy level is wrong.

**Scales come from the motion, never from 1.** ``S_i``, the size of component ``i`` of
``z = (q, p)``, is its range over the run (the nodes and the reference's states), at least a
tenth of the largest range of its block (``q`` or ``p``; `motion_scales`). The energy
scale ``E_s = max_k |S * grad H(z_k, t_k)|_2`` is how much ``H`` changes when the state moves by
``S``, where it changes fastest (`energy_scale`): an energy error ``dE`` puts the nodes at
least ``dE / E_s`` (in units of ``S``) off the exact level set. Every figure below is relative to
these, so a verdict does not change when ``q``, ``p``, ``t`` and ``H`` are rescaled
consistently, when a constant is added to ``H`` or when a translation-invariant system is
translated (tests/test_accuracy_metamorphic.py).

The tests, in the order the verdict reads them:

1. **Local error** of every step: ``d_k = z_{k+1} - Phi_{tau_k}(z_k)`` with ``Phi`` the exact
   flow over the accepted step; the step fails when ``|d_k,i| > rtol S_i (+ atol)`` for some
   ``i``. A march's own loop already computes ``|z_{k+1} - RK4(z_k)|_inf`` with its steps (the
   *first look*, `ErrorEstimates`, compiled into the march's chunk); the steps whose
   first look is below half the bound pass, the others are measured again with the reference
   flow.
2. **Energy level of the first step** (energy rules, which keep it for the whole march): the
   first interval's energy against ``H`` of the exact motion at the first interval's clock,
   ``H(Phi_{s_0 - t_0}(z_0), s_0)`` (for autonomous ``H`` simply ``H(z_0)``; for a
   time-dependent one the explicit change of ``H`` over half a step is motion, not error: a
   gauge term ``10 sin t`` is not refused). Fails above ``energy_tol``.
3. **Nodal energy drift** (autonomous ``H``): ``max_k |H(z_k) - H(z_0)| / E_s`` against
   ``energy_tol``.
4. **Trajectory error**: ``max_i |z_k,i - z_ref,i(t_k)| / S_i`` at every node, ``z_ref`` the
   reference flow from ``z_0`` at the run's own node times (or the exact solution, where one is
   given). The first node above ``global_tol`` is ``t_drift``; the scan stops there (the verdict
   needs no more: the run is not accurate). The reference is computed again with twice the
   substeps wherever its own error (``|A - B|``, ``reference.py``) passes a tenth of
   ``global_tol``; where even ``MAX_SUBSTEPS`` do not hold it there (a chaotic orbit past its
   horizon) the run is ``drifted`` from that time, and the report says the error could not be
   measured further.

``inaccurate`` if test 1, 2 or 3 fails (the first failure is reported with its step, time,
value and limit), else ``drifted`` if test 4 found a ``t_drift``, else ``accurate``. Why the
defaults (``rtol = global_tol = 1e-2``, ``energy_tol = 0.1``) keep an ``inaccurate`` verdict
honest: a local error above ``rtol S`` moves the trajectory by about that much at once, and an
energy error above ``energy_tol E_s`` puts some node at least ``energy_tol / sqrt(2n)`` of the
motion's size off the exact level set; both are trajectory errors above ``global_tol``.

Why the linear propagation is not the verdict: the first-order estimate ``e_{k+1} = M_k e_k +
d_k`` (``M_k`` the derivative of the RK4 step) is exact to first order and costs little, but it
underestimates the true error 3-90 times once that error passes a few percent of the orbit
(kepler at ``e = 0.6``: 3.4e-2 against a true 1.34). It is kept as the march's first look
(``linear_estimate_max`` in the report) and never decides.

The check runs in two places. During a march, `AccuracyMonitor` (a monitor of the step
loop, ``driver.py``) gathers the first look the compiled chunk computed with its steps (``Advance
.values``, ``ACCURACY_VALUES``) or computes it itself; it never stops the march, because the
scales are those of the whole run. At the end, `Judgement` makes the verdict on the
finished trajectory; `assess` does the same for the trajectory of any method, a
fixed-endpoint or periodic solution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...cache import cached
from ...discrete.runge_kutta import rk4
from ...physics.hamiltonian import vector_field_function
from ...solution import Status
from ..compiler import (
    CompileUnavailable,
    FunctionBuffer,
    buffered,
    cache_folder,
    compile_function,
    warn_once,
)
from ..exact.flow import MAX_SUBSTEPS, ReferenceFlow
from ..options import Tolerance

BLOCK = 1024  # nodes per call of the compiled estimate (the last block is padded)
SMALL = 16  # fewer steps than this go one by one, unpadded
# The per-step estimates a stepper may hand the monitor in ``Advance.values``: ``delta``,
# ``scale``, ``H_new``, ``global_error`` (each (m,)) and ``error`` (m, 2n), the error vector
# after each step.
ACCURACY_VALUES = ("delta", "scale", "H_new", "global_error", "error")
ADVICE = ("try a smaller tau0, fixed steps (--scheme fixed), or the least-squares step "
          "(--least-squares); --accept-inaccurate (Tolerance(stop=False)) records the verdict "
          "and keeps the status")
# A component's scale is at least this fraction of the largest range of its block (q or p).
BLOCK_FLOOR = 0.1
# ... and at least this fraction of its own magnitude (a block that does not move at all).
ROUND_OFF = 1e-12
# Steps whose first look is below this fraction of the local bound pass without a second look.
CANDIDATE = 0.5
# The reference's own error (|A - B|) may use this fraction of global_tol.
REFERENCE_SHARE = 0.1


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
        limit = 2 * ca.fmax(scale, 1e-300)
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




def _finite_or_none(value) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


# -- the scales of a motion -------------------------------------------------------------------

def motion_scales(low: np.ndarray, high: np.ndarray, largest: np.ndarray, n: int) -> np.ndarray:
    """``S_i`` of each component of ``z = (q, p)`` from its least and greatest values over the
    motion and its largest magnitude: its range ``high - low``, at least ``BLOCK_FLOOR`` times
    the largest range of its block (``q`` or ``p``: a coordinate that barely moves is measured
    against the motion of the others, not against round-off) and at least ``ROUND_OFF`` times
    its magnitude (a block that does not move at all)."""
    span = np.asarray(high, float) - np.asarray(low, float)
    scale = span.copy()
    for block in (slice(0, n), slice(n, 2 * n)):
        scale[block] = np.maximum(scale[block], BLOCK_FLOOR * np.max(span[block]))
    scale = np.maximum(scale, ROUND_OFF * np.asarray(largest, float))
    return np.maximum(scale, np.finfo(float).tiny)


class _Extent:
    """The least and greatest value and the largest magnitude of each component over the rows
    seen so far (the march's nodes, then the reference's, block by block)."""

    def __init__(self, rows: np.ndarray):
        self.low, self.high = rows.min(axis=0), rows.max(axis=0)
        self.largest = np.abs(rows).max(axis=0)

    def add(self, rows: np.ndarray) -> None:
        np.minimum(self.low, rows.min(axis=0), out=self.low)
        np.maximum(self.high, rows.max(axis=0), out=self.high)
        np.maximum(self.largest, np.abs(rows).max(axis=0), out=self.largest)

    def scales(self, n: int) -> np.ndarray:
        return motion_scales(self.low, self.high, self.largest, n)


def energy_scale(t: np.ndarray, field: np.ndarray, H: np.ndarray, scale: np.ndarray,
                 n: int) -> float:
    """``E_s``, the time average over the run of ``|S * grad H(z_k, t_k)|_2`` (from the vector
    field ``f = (H_p, -H_q)`` at the nodes, rows, and ``H`` there): how much ``H`` changes when
    the state moves by the motion's own size ``S`` in each component, typically over the
    motion. An energy error ``dE`` puts the nodes ``dE / |S * grad H|`` (in units of ``S``) off
    the exact level set, so wherever the gradient is at most its average (somewhere it is) at
    least ``dE / E_s``: a displacement, free of units and of constants added to ``H``. At
    least ``ROUND_OFF`` times ``max |H|`` (a motion at rest)."""
    # grad H = (H_q, H_p) = (-f_p, f_q)
    weighted = np.hstack([field[:, n:] * scale[:n], field[:, :n] * scale[n:]])
    norm = np.sqrt(np.sum(weighted ** 2, axis=1))
    weights = np.zeros(t.size)  # each node stands for half of each step beside it
    weights[:-1] += np.diff(t) / 2
    weights[1:] += np.diff(t) / 2
    typical = float(np.sum(weights * norm) / np.sum(weights)) if t.size > 1 else \
        float(norm[0]) if norm.size else 0.0
    if not math.isfinite(typical):
        return math.inf
    return max(typical, ROUND_OFF * float(np.max(np.abs(H), initial=0.0)),
               np.finfo(float).tiny)


# -- the verdict ----------------------------------------------------------------------------

@dataclass
class FirstLook:
    """The first look of a second-order march: ``linear`` (N,), the first-order propagation's
    ``|e_{k+1}|_inf`` its own loop computed (the compiled chunk or the careful path's
    `ErrorEstimates`), reported beside the reference's error. Given, it also lets the
    local test pass the steps whose error against one RK4 step of the exact flow is below
    ``CANDIDATE`` times the bound (RK4's own error, ``O(tau^5)``, is far below a second-order
    scheme's ``O(tau^3)``; a method of order 4 or more must be measured with the reference)."""

    linear: np.ndarray


@dataclass
class Level:
    """The energy level a scheme keeps, set by its first step: ``value`` (``H`` of the first
    interval) at the first interval's clock ``clock``."""

    value: float
    clock: float


def _unjudged(t, z, tol: Tolerance) -> dict:
    """The report of a run without a step (or with a non-finite node): nothing to measure."""
    finite = bool(np.all(np.isfinite(z))) and bool(np.all(np.isfinite(t)))
    failure = None if finite else {"step": 0, "t": float(t[0]) if t.size else 0.0,
                                   "test": "finite nodes", "value": math.inf, "limit": 0.0}
    return {"verdict": "accurate" if finite else "inaccurate", "first_failure": failure,
            "t_drift": None, "drift_step": None, "error_max": 0.0, "error_max_t": None,
            "estimate": "none (no step)", "reference_until": None, "reference_error": None,
            "reference_lost": None, "scale": None, "energy_scale": None,
            "local_error_max": 0.0, "linear_estimate_end": None, "linear_estimate_max": None,
            "level": None, "level_reference": None, "level_error": None, "energy_drift": None,
            "steps": max(t.size - 1, 0), "rtol": tol.rtol, "atol": tol.atol,
            "energy_tol": tol.energy_tol, "global_tol": tol.global_tol,
            "require_accurate": tol.require_accurate}


class Judgement:
    """The accuracy check of one trajectory ``t`` (N+1,), ``z`` (N+1, 2n) against the exact
    flow, made once (`report`); see the module docstring for the tests and the verdict."""

    def __init__(self, system, theta, tolerance: Tolerance, *, compiler=None, cache_dir=None):
        self.system, self.theta, self.tolerance = system, np.asarray(theta, float), tolerance
        self.reference = ReferenceFlow(system, theta, compiler=compiler, cache_dir=cache_dir)

    def report(self, t, z, *, level: Level | None = None, first_look: FirstLook | None = None,
               exact=None) -> tuple[dict, np.ndarray]:
        """The report (``Solution.stats["accuracy"]``) and the local error of every step,
        ``|z_{k+1} - Phi(z_k)|_inf``."""
        t, z = np.asarray(t, float), np.asarray(z, float)
        steps = t.size - 1
        if steps < 1 or not np.all(np.isfinite(z)) or not np.all(np.isfinite(t)):
            return _unjudged(t, z, self.tolerance), np.zeros(max(steps, 0))
        trajectory = self._trajectory(t, z, exact)
        n = self.system.n
        scale = trajectory["extent"].scales(n)
        look = self.reference.first_look(t, z) if first_look is not None else None
        field, H = look[1:] if look is not None else self.reference.at_nodes(t, z)
        energy = energy_scale(t, field, H, scale, n)
        local, local_error, local_max = self._local(t, z, scale, look)
        energies = self._energies(t, z, H, energy, level)
        failures = [f for f in (local, *energies["failures"]) if f is not None]
        failure = min(failures, key=lambda f: f["step"]) if failures else None
        drift = trajectory["drift"]
        verdict = "inaccurate" if failure else ("drifted" if drift is not None else "accurate")
        tol = self.tolerance
        report = {
            "verdict": verdict, "first_failure": failure,
            "t_drift": None if drift is None else float(t[drift]),
            "drift_step": drift, "error_max": trajectory["error_max"],
            "error_max_t": trajectory["error_max_t"], "estimate": trajectory["estimate"],
            "reference_until": float(t[trajectory["states"].shape[0]]),
            "reference_error": trajectory["reference_error"],
            "reference_lost": trajectory["lost"],
            "scale": scale.tolist(), "energy_scale": energy,
            "local_error_max": local_max,
            **_linear_figures(first_look),
            **energies["figures"], "steps": steps,
            "rtol": tol.rtol, "atol": tol.atol, "energy_tol": tol.energy_tol,
            "global_tol": tol.global_tol, "require_accurate": tol.require_accurate}
        return report, local_error

    # -- the trajectory's error ---------------------------------------------------------------
    def _trajectory(self, t, z, exact) -> dict:
        """The reference states at the nodes (the exact solution if given, else the reference
        flow from ``z_0``), up to the first node whose error passes ``global_tol`` (where the
        scan stops: the verdict needs no more), with the scales of the motion."""
        if exact is not None:
            states = np.asarray(exact(t), float).reshape(t.size, -1)
            return self._measured(t, z, states[1:], "exact solution", 0.0, 1)
        tol = self.tolerance.global_tol
        substeps = 1
        while True:
            extent = _Extent(z)
            found = self._scan(t, z, extent, substeps, tol)
            if found["lost"] is None or 2 * substeps > MAX_SUBSTEPS:
                break
            substeps *= 2  # the reference's own error passed its share: resolve the flow better
        found["estimate"] = (f"reference flow (order-8 Runge-Kutta, {2 * substeps} substeps "
                             f"per step, its own error at most "
                             f"{found['reference_error']:.1e} of the motion's size)")
        return found

    def _scan(self, t, z, extent: _Extent, substeps: int, tol: float) -> dict:
        """The reference chain block by block; stops where the trajectory error passes ``tol``
        (drift) or where the reference's own error passes ``REFERENCE_SHARE * tol`` (lost)."""
        n = self.system.n
        states, worst, drift, lost = [], (0.0, None), None, None
        own = 0.0
        for first, A, B in self.reference.chain(t, z[0], substeps):
            extent.add(B)
            scale = extent.scales(n)
            nodes = slice(first + 1, first + 1 + B.shape[0])
            if not np.all(np.isfinite(B)):
                lost = first + 1 + int(np.argmax(~np.all(np.isfinite(B), axis=1)))
                break
            own_rows = np.max(np.abs(A - B) / scale, axis=1)
            error = np.max(np.abs(z[nodes] - B) / scale, axis=1)
            budget = np.flatnonzero(own_rows > REFERENCE_SHARE * tol)
            over = np.flatnonzero(error > tol)
            stop = min(budget[0] if budget.size else B.shape[0], over[0] + 1 if over.size
                       else B.shape[0])
            states.append(B[:stop])
            own = max(own, float(np.max(own_rows[:stop], initial=0.0)))
            if stop and float(np.max(error[:stop])) > worst[0]:
                i = int(np.argmax(error[:stop]))
                worst = (float(error[i]), float(t[first + 1 + i]))
            if budget.size and (not over.size or budget[0] <= over[0]):
                lost = first + 1 + int(budget[0])
                break
            if over.size:
                drift = first + 1 + int(over[0])
                break
        states = np.vstack(states) if states else np.zeros((0, 2 * n))
        return {"states": states, "extent": extent, "drift": drift if lost is None else lost,
                "lost": None if lost is None else float(t[lost]), "error_max": worst[0],
                "error_max_t": worst[1], "reference_error": own / 255}

    def _measured(self, t, z, states, estimate, own, substeps) -> dict:
        """The same figures as `_scan` for reference states given whole (an exact
        solution)."""
        extent = _Extent(z)
        extent.add(states)
        scale = extent.scales(self.system.n)
        error = np.max(np.abs(z[1:] - states) / scale, axis=1)
        over = np.flatnonzero(error > self.tolerance.global_tol)
        i = int(np.argmax(error))
        return {"states": states, "extent": extent,
                "drift": int(over[0]) + 1 if over.size else None, "lost": None,
                "error_max": float(error[i]), "error_max_t": float(t[i + 1]),
                "reference_error": own, "estimate": estimate}

    # -- the steps ----------------------------------------------------------------------------
    def _local(self, t, z, scale, look):
        """The local error test: ``|z_{k+1} - Phi_{tau_k}(z_k)|_i <= rtol S_i (+ atol)`` for every
        step, ``Phi`` the reference flow with its own error held below a tenth of that bound.
        With a first look (a second-order march), the steps whose error against one RK4 step is
        below ``CANDIDATE`` times the bound in every component pass without being measured
        again. Returns the first failure (or None), ``|d_k|_inf`` and the largest
        ``max_i |d_k,i| / S_i``."""
        tol = self.tolerance
        limit = tol.rtol * scale + (tol.atol or 0.0)
        steps = t.size - 1
        local, relative, ratio = np.full(steps, np.inf), np.zeros(steps), np.zeros(steps)
        if look is not None:
            d = np.abs(look[0])
            local = np.max(d, axis=1)
            relative = np.max(d / scale, axis=1)
            ratio = np.max(d / limit, axis=1)
        todo = np.flatnonzero(~(ratio <= CANDIDATE)) if look is not None else \
            np.arange(steps)
        substeps = 1
        while todo.size:
            A, B = self.reference.maps(t[todo], z[todo], t[todo + 1] - t[todo], substeps)
            d = z[todo + 1] - B
            own = np.abs(A - B)
            unsure = np.any(own > 0.1 * limit, axis=1) & np.all(np.isfinite(own), axis=1)
            done = todo[~unsure] if 2 * substeps <= MAX_SUBSTEPS else todo
            keep = np.isin(todo, done)
            local[done] = np.max(np.abs(d[keep]), axis=1)
            relative[done] = np.max(np.abs(d[keep]) / scale, axis=1)
            ratio[done] = np.max(np.abs(d[keep]) / limit, axis=1)
            todo = np.setdiff1d(todo, done)
            substeps *= 2
        bad = np.flatnonzero(~(ratio <= 1.0))
        failure = None
        if bad.size:
            k = int(bad[0])
            failure = {"step": k, "t": float(t[k]), "test": "local error",
                       "value": float(relative[k]), "limit": tol.rtol}
        return failure, local, float(np.max(relative, initial=0.0))

    def _energies(self, t, z, H, energy: float, level: Level | None) -> dict:
        """The energy tests, relative to the energy scale: the level the first step sets
        against ``H`` of the exact flow at the first interval's clock, and (autonomous ``H``)
        the nodal ``H`` against ``H(z_0, t_0)``."""
        system, tol = self.system, self.tolerance
        H0 = float(H[0])
        figures = {"level": None, "level_reference": None, "level_error": None,
                   "energy_drift": None}
        failures = []
        if level is not None:
            reference = H0
            if system.time_dependent:  # H of the exact motion at the level's own clock
                state, _ = self.reference.flow(z[0], t[0], level.clock)
                _, at_clock = self.reference.at_nodes(np.array([level.clock]), state[None, :])
                reference = float(at_clock[0])
            error = abs(level.value - reference) / energy
            figures.update(level=float(level.value), level_reference=reference,
                           level_error=_finite_or_none(error))
            if not error <= tol.energy_tol:
                failures.append({"step": 0, "t": float(t[0]),
                                 "test": "energy level of the first step",
                                 "value": float(error), "limit": tol.energy_tol})
        if not system.time_dependent:
            drift = np.abs(H - H0) / energy
            figures["energy_drift"] = _finite_or_none(float(np.max(drift)))
            over = np.flatnonzero(~(drift <= tol.energy_tol))
            if over.size:
                k = int(over[0])
                failures.append({"step": max(k - 1, 0), "t": float(t[k]),
                                 "test": "nodal energy drift", "value": float(drift[k]),
                                 "limit": tol.energy_tol})
        return {"figures": figures, "failures": failures}


def _linear_figures(first_look: FirstLook | None) -> dict:
    """The first look's propagated estimate ``|e_k|_inf`` at the end and its largest value, in
    the units of ``z`` (reported, never deciding)."""
    if first_look is None or not first_look.linear.size:
        return {"linear_estimate_end": None, "linear_estimate_max": None}
    return {"linear_estimate_end": float(first_look.linear[-1]),
            "linear_estimate_max": float(np.max(first_look.linear))}


def describe(report: dict) -> str:
    """The verdict of a report in words, with the figure that decided it."""
    verdict = report["verdict"]
    if verdict == "inaccurate":
        failure = report["first_failure"]
        if failure.get("detail"):
            return f"{failure['test']}: {failure['detail']}"
        return (f"the {failure['test']} of step {failure['step']} (from t = "
                f"{failure['t']:.10g}) is {failure['value']:.3e} > {failure['limit']:.3e}")
    if verdict == "drifted":
        if report.get("reference_lost") is not None:
            return (f"the trajectory error cannot be measured past t = "
                    f"{report['reference_lost']:.6g} (the reference flow's own error passed "
                    f"its share of the tolerance there: the motion is too sensitive)")
        return (f"the trajectory error passes {report['global_tol']:g} of the motion's size at "
                f"t = {report['t_drift']:.6g} (largest {report['error_max']:.3e})")
    return (f"the trajectory error stays within {report['global_tol']:g} of the motion's size "
            f"(largest {report['error_max']:.3e})")


def apply_verdict(solution, report: dict, tolerance: Tolerance, advice: str = ADVICE) -> None:
    """The status of a solve that reached its end, from its verdict: ``inaccurate`` ends it as
    ``Status.INACCURATE`` (unless ``tolerance.stop`` is off), ``drifted`` as
    ``Status.DRIFTED`` when ``tolerance.require_accurate`` asks for an accurate trajectory;
    either way the message says what the check found (and, for a failed test, ``advice``)."""
    verdict = report["verdict"]
    if not solution.success or verdict == "accurate":
        return
    words = describe(report)
    if verdict == "inaccurate" and tolerance.stop:
        solution.status = Status.INACCURATE
        detailed = bool(report["first_failure"].get("detail"))
        solution.message = f"{Status.INACCURATE.value}: {words}" + \
            ("" if detailed or not advice else f"; {advice}")
    elif verdict == "drifted" and tolerance.require_accurate:
        solution.status = Status.DRIFTED
        solution.message = f"{Status.DRIFTED.value}: {words}"
    else:
        solution.message = f"{solution.message}; {verdict}: {words}"


class AccuracyMonitor:
    """The march's side of the check, a monitor of the step loop (``driver.py``, rule 5): it
    gathers the first look (`FirstLook`) the stepper computed with its steps, or
    computes it (`ErrorEstimates`), and the level the first step sets. It never stops a
    march: the verdict is made on the whole run (`report`), whose scale it needs.

    ``level`` is ``None`` for schemes without an energy level (fixed steps), else a function of
    the first two nodes ``(t, z)`` giving ``(level, clock)``."""

    def __init__(self, system, theta, tolerance: Tolerance, *, H0: float, level=None,
                 substeps: int = 1, compiler=None, cache_dir=None, errors=None):
        self.system = system
        self.theta = np.asarray(theta, float)
        self.tolerance = tolerance
        self.H0 = H0
        self.level_of = level
        self.level = None
        if errors is None:
            errors = ErrorEstimates(system, substeps, compiler=compiler, cache_dir=cache_dir)
        self.errors = errors
        self.compiler, self.cache_dir = compiler, cache_dir
        self.delta = _Series()  # delta_k of every step watched
        self.global_errors = _Series()  # |e_k|_inf

    def watch(self, nodes, first: int, advance):
        start = max(first - 1, 0)  # the new steps run from node start to nodes.count - 1
        t, z = nodes.t[start:nodes.count], nodes.z[start:nodes.count]
        if t.size < 2:
            return None
        if start == 0 and self.level_of is not None:
            self.level = Level(*self.level_of(t[:2], z[:2]))
        delta, _, _, globals_ = self._estimates(t, z, advance)
        self.delta.append(delta)
        self.global_errors.append(globals_)
        return None

    def _estimates(self, t, z, advance):
        """The stepper's own estimates of these steps if it computed them (a compiled chunk),
        else this check's; either way ``errors.e`` ends at the newest node."""
        values = advance.values if advance is not None else {}
        if "delta" in values and values["delta"].size == t.size - 1:
            self.errors.e = values["error"][-1].copy()
            return values["delta"], values["scale"], values["H_new"], values["global_error"]
        return self.errors(t, z, self.theta)

    def local_errors(self, steps: int) -> np.ndarray:
        """``delta_k`` of the first ``steps`` steps (the first look)."""
        return self.delta.head(steps)

    def global_error(self, steps: int) -> np.ndarray:
        """``|e_k|_inf`` at the nodes ``1 .. steps``: the first-order propagated estimate."""
        return self.global_errors.head(steps)

    def report(self, t, z, exact=None) -> tuple[dict, np.ndarray]:
        """The verdict on the march's nodes ``t``, ``z`` (`Judgement`)."""
        steps = t.size - 1
        look = FirstLook(self.global_error(steps))
        if look.linear.size != steps:
            look = None  # the monitor saw fewer nodes than the run kept: measure them all
        judge = Judgement(self.system, self.theta, self.tolerance, compiler=self.compiler,
                          cache_dir=self.cache_dir)
        return judge.report(t, z, level=self.level if steps else None, first_look=look,
                            exact=exact)


def assess(system, t, z, theta, tolerance: Tolerance, *, level=None, compiler=None,
           cache_dir=None, exact=None) -> tuple[dict, np.ndarray]:
    """The accuracy check on a finished trajectory of any method (``t`` (N,), ``z`` (N, 2n)):
    the report of `Judgement.report` and the local error of every step. ``level`` is the
    energy level the method keeps, if it keeps one (a `Level`); ``exact``, the motion's
    exact states at given times, if known (``exact(t) -> (N, 2n)``)."""
    return Judgement(system, theta, tolerance, compiler=compiler, cache_dir=cache_dir).report(
        t, z, level=level, exact=exact)
