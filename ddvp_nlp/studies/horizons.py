"""Work-precision over several horizons, and the growth of each method's error with time.

A horizon ``T`` runs the comparison of `.compare` to ``t_end = t0 + T unit`` (``unit``: a
period, or the scene's own time unit). Long horizons cost what their steps cost, so the sweeps
are cut before they run (`affordable_knobs`, each cut named in the report): steps that
would pass ``max_steps`` give way to coarser ones, and runs predicted from the shorter horizon
to take longer than a budget are left out. The reference of a long horizon is the scene's exact
solution where it has one (Kepler, pendulum, harmonic); otherwise DOP853 at 1e-13 up to
`reference_kind`'s span, and beyond it none: the energy error is still measured, the
trajectory error is not (over 10^5 time units of a chaotic orbit it would measure nothing).

Error growth (`error_growth`): for each method one run at about equal cost (the run of
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
from .comparable import reference_for
from .methods import METHODS
from .work_precision import succeeded


def parse_horizons(text: str | list) -> list[float]:
    """``"10,1000,100000"`` (or a list) as positive, finite horizons, shortest first (each
    horizon's sweeps are cut by what the shorter one measured); a horizon given twice is
    refused."""
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        text = [text]
    values = list(text) if isinstance(text, list | tuple) else \
        [v for v in str(text).split(",") if v.strip()]
    try:
        horizons = [float(v) for v in values]
    except (TypeError, ValueError):
        raise InputError(f"horizons must be comma-separated numbers, got {text!r}") from None
    if not horizons:
        raise InputError(f"horizons must name at least one horizon, got {text!r}")
    for value in horizons:
        check_real("horizon", value, positive=True)
    seen = set()
    for value in horizons:
        if value in seen:
            raise InputError(f"horizons give {value:g} twice; give each horizon once")
        seen.add(value)
    return sorted(horizons)


def check_horizons(horizons, unit: float, config) -> None:
    """Each horizon ``T`` (``t_end = t0 + T unit``) must hold at least one of the scene's
    first steps ``tau0``: a shorter one is not a run of that scene, its sweep's every step
    would be cut to fit it."""
    unit = check_real("time unit", unit, positive=True)
    for horizon in horizons:
        if horizon * unit < config.tau0:
            raise InputError(f"horizon {horizon:g} (t_end - t0 = {horizon * unit:g}) is shorter "
                             f"than the scene's first step tau0 = {config.tau0:g}; give "
                             f"horizons of at least {config.tau0 / unit:g}")


def affordable_knobs(methods, config, t_end: float, halvings: int, max_steps: int, *,
                     previous: tuple[float, list[dict]] | None = None,
                     run_budget_s: float | None = None, coarsenings: int = 4):
    """Per method, the knob values to run to ``t_end``, and the runs left out with why.

    A step method takes its default sweep (that of the scene's own horizon, so the same steps
    are compared at every horizon) without the steps that would pass ``max_steps``; where that
    leaves fewer than ``halvings + 1`` values, coarser steps (twice, four times, ... the
    coarsest, at most ``coarsenings`` doublings) fill the sweep up, so that a long horizon
    still has a front to draw. With ``previous = (span, rows)``, a shorter horizon's
    measured runs, a run whose time scaled by the span (run time is linear in it) would pass
    ``run_budget_s`` is left out too; that is what bounds DOP853's tolerance sweep."""
    knobs, left_out = {}, []
    span = t_end - config.t0
    for method in methods:
        values = method.sweep(config, halvings)
        kept = values
        if method.knob != "rtol":
            kept = [v for v in values if span / v <= max_steps and v <= span]
            coarsest = max(values)
            for _ in range(coarsenings):
                if len(kept) >= len(values):
                    break
                coarsest *= 2
                if span / coarsest <= max_steps and coarsest <= span / 4:
                    kept.insert(0, coarsest)
            dropped = [v for v in values if v not in kept]
            if dropped:
                left_out.append(f"`{method.name}` at {method.knob} <= {max(dropped):.3g} "
                                f"(more than max_steps = {max_steps} to reach t = {t_end:g})")
        kept, slow = _within_budget(method, kept, span, previous, run_budget_s)
        if slow:
            left_out.append(f"`{method.name}` at {method.knob} = "
                            + ", ".join(f"{v:.3g}" for v in slow)
                            + f" (predicted from the shorter horizon to take more than "
                              f"{run_budget_s:g} s)")
        if kept:
            knobs[method.name] = kept
    return knobs, left_out


def _within_budget(method, values, span, previous, budget_s):
    """``values`` split into those predicted to fit ``budget_s`` and those that do not: a
    value's run time at the shorter horizon, times ``span / previous span``; a value not run
    there is kept if a coarser one fitted (a sweep is run coarse to fine)."""
    if previous is None or budget_s is None:
        return list(values), []
    short_span, rows = previous
    measured = {r["value"]: r["run_s"] for r in rows
                if r["method"] == method.name and r["run_s"] == r["run_s"]}
    kept, slow = [], []
    for value in values:
        predicted = measured.get(value)
        if predicted is not None and predicted * span / short_span > budget_s:
            slow.append(value)
        elif predicted is None and slow:
            slow.append(value)
        else:
            kept.append(value)
    return kept, slow


def reference_kind(scene, span: float, reference_span: float) -> str:
    """``auto`` (exact, or the exact flow) for a horizon of ``span`` time units up to
    ``reference_span``, or when the scene has an exact solution; beyond it ``none``."""
    return "auto" if scene.exact is not None or span <= reference_span else "none"


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
                 points: int = 400, reference: str = "auto") -> tuple[float, list[Growth]]:
    """The common cost and each method's `Growth` (see the module docstring)."""
    config = scene.resolve(overrides)
    reference = reference_for(scene, overrides, reference)
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
