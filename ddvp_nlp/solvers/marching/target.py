"""A march that chooses its own first step for a trajectory error asked for (``march(...,
target_error=E)``, ``ddvp march --target-error E``).

For the energy rules ``tau0`` sets every later step through the energy level, and the steps
scale with it; every scheme here is of second order, so the trajectory error at a time ``T``
behaves like ``C(T) tau0^2``. The choice:

1. **Pilot**: a march at the given ``tau0`` over the first part of the span (``PILOT_SHARE`` of
   it, at least ``PILOT_STEPS`` steps, at most the whole span), its trajectory error measured
   at every node against the exact flow (``exact/reference.py``, an independent reference, in
   units of the motion's scales as the accuracy check measures it), as its running maximum
   ``e(t)``, read up to the last node where it is below ``LINEAR_LIMIT`` (``T_p``: past that
   a phase error has gone round and saturates).
2. **Growth**: the exponent ``beta`` of ``e(t) ~ t^beta`` fitted over ``[T_p / 2, T_p]`` (a
   phase error grows like ``t``, a secular drift faster), at least 1; the error predicted at
   the end of the span is ``e(T_p) (T / T_p)^beta`` (a pilot wrong from its first steps: an
   eighth of its step).
3. **Step**: ``tau0 (SAFETY E / e_predicted)^(1/2)``, at most ``MAX_GROWTH`` times the pilot's
   (a longer first step can leave the energy step's range of solvability).
4. **The run**, judged by the accuracy check at ``global_tol = E``; where its verdict is not
   ``accurate`` (a chaotic orbit's error grows faster than the pilot showed), one more run with
   the step the verdict asks for: from a drift at ``t_drift`` the same growth law to the end,
   from a failed local or energy test a quarter of the step.

The solution carries the choice and its cost in ``march.target_error``: the pilot (span,
steps, error, fitted growth, CPU), each run (``tau0``, verdict, steps, CPU) and the total CPU.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from ...errors import InputError
from ...validation import check_real
from ..accuracy.judgement import SMALLEST_GLOBAL_TOL, exact_states, motion_scales
from ..columns import column_extremes, row_max_ratio
from ..options import EXACT_TOLERANCE

__all__ = ["march_to_error"]

PILOT_SHARE = 1 / 4  # of the span, for the pilot march
PILOT_STEPS = 256  # at least this many pilot steps (if the span has them)
SAFETY = 0.5  # the predicted error aimed at, as a share of the target
MAX_GROWTH = 8.0  # the chosen step at most this many times the pilot's
ORDER = 2  # every scheme of the march is of second order
REFERENCE_RTOL = EXACT_TOLERANCE.flow_rtol  # the pilot measured against the exact flow
# past this trajectory error (units of the motion's size) the error saturates (a phase that has
# gone round): the pilot's growth is read below it
LINEAR_LIMIT = 0.1


def check_target(target_error, accuracy) -> float:
    """``target_error``: a trajectory error relative to the motion's size, in
    ``[SMALLEST_GLOBAL_TOL, 1)`` (below it the exact-flow reference cannot measure the error:
    no run could be judged to reach it); the accuracy check must be on to judge it."""
    value = check_real("target_error", target_error, positive=True)
    if not value < 1:
        raise InputError(f"target_error is relative to the motion's size and must be below 1, "
                         f"got {value!r}")
    if not value >= SMALLEST_GLOBAL_TOL:
        raise InputError(f"target_error = {value!r} is below what the check can measure: the "
                         f"exact-flow reference's own error floor puts the smallest judgeable "
                         f"trajectory error at {SMALLEST_GLOBAL_TOL:g} of the motion's size")
    if accuracy is None:
        raise InputError("target_error needs the accuracy check (accuracy=None turns it off)")
    return value


def march_to_error(run, system, z0, t0: float, t_end: float, tau0: float, theta,
                   target: float, accuracy):
    """The march of ``run(tau0, span, accuracy)`` with its first step chosen for ``target``
    (module docstring); ``run`` is `march` with everything else fixed."""
    started = time.process_time()
    span = t_end - t0
    pilot_end = t0 + min(span, max(span * PILOT_SHARE, PILOT_STEPS * tau0))
    cpu = time.process_time()
    pilot = run(tau0, (t0, pilot_end), None)
    pilot_cpu = time.process_time() - cpu
    record = {"target": target, "pilot": {"t_end": pilot_end, "steps": pilot.steps,
                                          "tau0": tau0, "cpu_s": pilot_cpu}, "runs": []}
    if not pilot.success or pilot.steps < 1:  # the pilot's nodes and status are the result
        return _pilot_failed(pilot, tau0, record, started)
    error, reach, beta = _pilot_error(system, theta, pilot)
    predicted = error * (span / (reach - t0)) ** beta
    record["pilot"].update(error=error, measured_to=reach, growth=beta, predicted=predicted)
    step = _scaled(tau0, target, predicted) if math.isfinite(predicted) else tau0 / 8
    tolerance = dataclasses.replace(accuracy, global_tol=target)
    solution = None
    for attempt in range(2):
        cpu = time.process_time()
        solution = run(step, (t0, t_end), tolerance)
        verdict = solution.verdict.name if solution.verdict is not None else None
        record["runs"].append({"tau0": step, "steps": solution.steps, "verdict": verdict,
                               "status": solution.status.code,
                               "cpu_s": time.process_time() - cpu})
        if verdict == "accurate" or attempt == 1 or solution.status.code == "interrupted":
            break  # an interrupted run is not retried: its stop was asked for
        step = _retried(step, solution.verdict, t0, t_end, target, beta)
    record["tau0"] = record["runs"][-1]["tau0"]
    record["cpu_s"] = time.process_time() - started
    solution.march.target_error = record
    return solution


def _pilot_failed(pilot, tau0: float, record: dict, started: float):
    """The pilot's own solution, its failure status kept (a breakdown, an interrupt): no run
    was chosen, so no verdict is claimed for the span; the message says so."""
    pilot.message = (f"target_error: the pilot march at tau0 = {tau0:g} ended "
                     f"{pilot.status.code} ({pilot.message}); no run was made"
                     + ("" if pilot.status.code == "interrupted" else
                        "; give a smaller tau0 to start from"))
    record["tau0"] = None
    record["cpu_s"] = time.process_time() - started
    pilot.march.target_error = record
    return pilot


def _pilot_error(system, theta, pilot) -> tuple[float, float, float]:
    """The pilot's trajectory error against the exact flow (units of the motion's scales) as
    its running maximum: its value at the last node where it is still below ``LINEAR_LIMIT``
    (past that the error saturates and says nothing of the step), that node's time, and the
    growth exponent of the running maximum over the second half up to there."""
    t = pilot.t
    z = np.column_stack([pilot.q, pilot.p])
    states = exact_states(system, z[0], t, theta, rtol=REFERENCE_RTOL)
    scale = motion_scales(*column_extremes(np.vstack([z, states])), system.n)
    running = np.maximum.accumulate(row_max_ratio(np.abs(z - states), scale))
    linear = np.flatnonzero(running <= LINEAR_LIMIT)
    if linear.size < 2:
        return math.inf, float(t[1]), 1.0
    last = int(linear[-1])
    error, reach = float(running[last]), float(t[last])
    usable = (t >= t[0] + (reach - t[0]) / 2) & (t <= reach) & (running > 0)
    beta = 1.0
    if np.count_nonzero(usable) >= 4:
        slope = float(np.polyfit(np.log(t[usable] - t[0]), np.log(running[usable]), 1)[0])
        if math.isfinite(slope):
            beta = max(1.0, slope)
    return max(error, np.finfo(float).eps), reach, beta


def _scaled(tau0: float, target: float, predicted: float) -> float:
    factor = (SAFETY * target / predicted) ** (1 / ORDER)
    return tau0 * min(factor, MAX_GROWTH)


def _retried(step: float, verdict, t0: float, t_end: float, target: float,
             beta: float) -> float:
    """The step a second run takes after a verdict other than accurate (``verdict``: the
    run's `Verdict`, ``None`` if it was not judged)."""
    t_drift = verdict.t_drift if verdict is not None else None
    if verdict is not None and verdict.drifted and t_drift is not None and t_drift > t0:
        predicted = target * ((t_end - t0) / (t_drift - t0)) ** beta
        return _scaled(step, target, predicted)
    return step / 4
