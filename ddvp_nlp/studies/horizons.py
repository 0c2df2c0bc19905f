"""Work-precision over several horizons, and the growth of each method's error with time.

A horizon ``T`` runs the comparison of :mod:`.compare` to ``t_end = t0 + T unit`` (``unit``: a
period, or the scene's own time unit). Long horizons cost what their steps cost, so a run whose
steps (``(t_end - t0) / knob``) would pass ``max_steps`` is left out of the sweep before it
runs (named in the plan's ``left_out``); DOP853's tolerance sweep is bounded by ``max_steps``.

Error growth (:func:`error_growth`): for each method one run at about equal cost (the run of
its sweep whose time is nearest, in log, to the common cost: the largest of the methods'
cheapest run times, so every method can afford it), rerun and measured at every node: the
energy error ``|H(z_k) - H(z_0)|`` and the trajectory error ``|z_k - z_ref(t_k)|_inf`` against
``t_k``, thinned to at most ``points`` nodes spaced evenly in ``log t``. The picture of Hairer,
Lubich and Wanner for Kepler: linear drift of ``H`` for the non-symplectic methods, bounded
error for the symplectic ones, round-off for the energy-conserving ones at their conserved
quantity; the trajectory error grows linearly (symplectic, conserving) or quadratically.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..validation import check_real
from .compare import succeeded
from .methods import METHODS
from .reference import reference_for


def parse_horizons(text: str | list) -> list[float]:
    """``"10,1000,100000"`` (or a list) as positive horizons, in order."""
    values = text if isinstance(text, list | tuple) else [v for v in str(text).split(",")
                                                           if v.strip()]
    try:
        horizons = [float(v) for v in values]
    except ValueError:
        raise InputError(f"horizons must be comma-separated numbers, got {text!r}") from None
    if not horizons:
        raise InputError("horizons must name at least one horizon")
    for value in horizons:
        check_real("horizon", value, positive=True)
    return horizons


def affordable_knobs(methods, config, t_end: float, halvings: int, max_steps: int):
    """Per method, the knob values of its sweep whose step count fits ``max_steps`` (the
    sweep of the default horizon, so the same steps are compared at every horizon), and the
    runs left out with why."""
    knobs, left_out = {}, []
    span = t_end - config.t0
    for method in methods:
        values = method.sweep(config, halvings)
        if method.knob == "rtol":
            knobs[method.name] = values
            continue
        kept = [v for v in values if span / v <= max_steps and v <= span]
        if len(kept) < len(values):
            left_out.append(f"`{method.name}` at {len(values) - len(kept)} of its steps (more "
                            f"than max_steps = {max_steps} to reach t = {t_end:g})")
        if kept:
            knobs[method.name] = kept
    return knobs, left_out


@dataclass
class Growth:
    """One method's errors against time, at its run of about the common cost."""

    method: str
    knob: str
    value: float
    run_s: float
    t: np.ndarray
    energy_error: np.ndarray
    trajectory_error: np.ndarray


def equal_cost_runs(rows) -> tuple[float, dict[str, dict]]:
    """The common cost (seconds) and, per method, its successful run nearest to it in log."""
    fronts = {}
    for row in rows:
        if row in succeeded(rows, row["method"]) and row["run_s"] > 0:
            fronts.setdefault(row["method"], []).append(row)
    if not fronts:
        return math.nan, {}
    target = max(min(r["run_s"] for r in runs) for runs in fronts.values())
    return target, {m: min(runs, key=lambda r: abs(math.log(r["run_s"] / target)))
                    for m, runs in fronts.items()}


def _thin(t: np.ndarray, points: int) -> np.ndarray:
    """Indices of at most ``points`` nodes, spread evenly in ``log t`` (``t > t_0``)."""
    later = np.flatnonzero(t > t[0])
    if later.size <= points:
        return later
    marks = np.geomspace(t[later[0]] - t[0], t[-1] - t[0], points) + t[0]
    return np.unique(np.clip(np.searchsorted(t, marks), later[0], t.size - 1))


def error_growth(scene, overrides, rows, *, compiler, cache_dir=None, max_steps: int,
                 points: int = 400) -> tuple[float, list[Growth]]:
    """The common cost and each method's :class:`Growth` (see the module docstring)."""
    config = scene.resolve(overrides)
    reference = reference_for(scene, overrides)
    system = scene.system
    target, chosen = equal_cost_runs(rows)
    found = []
    for name, row in chosen.items():
        solution = METHODS[name].run(system, config, row["value"], compiler=compiler,
                                     cache_dir=cache_dir, max_steps=max_steps)
        keep = _thin(solution.t, points)
        t, q, p = solution.t[keep], solution.q[keep], solution.p[keep]
        H = system.energy(q, p, t, reference.theta)
        H0 = system.energy(solution.q[:1], solution.p[:1], solution.t[:1], reference.theta)[0]
        z_error = np.max(np.abs(np.hstack([q, p]) - reference(t)), axis=1)
        found.append(Growth(name, row["knob"], row["value"], row["run_s"], t - config.t0,
                            np.abs(H - H0), z_error))
    return target, found
