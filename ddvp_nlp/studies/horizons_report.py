"""Work-precision at several horizons and the error-growth figure: ``horizons.png``,
``growth.png``, ``horizons.md``, and each horizon's own report in ``horizon_T/``.

`horizons_study` runs the comparison once per horizon (``t_end = t0 + T unit``), with the
sweeps cut to what ``max_steps`` affords (`affordable_knobs`), and returns a
`HorizonComparison` (``compare(..., horizons=...)`` returns it); with a folder
(`work_precision_horizons`, ``ddvp compare --horizons``) it also reruns each method at about
equal cost over the longest horizon, draws its errors against time and the crossover figure.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Mapping
from dataclasses import replace

from ..io import atomic
from ..io.horizons_figure import plot_growth, plot_horizons
from ..io.markdown import machine
from ..io.run_folder import figure_writer
from ..runner.tasks import Workers
from ..scenes import Scene
from ..solvers import Compilation, find_compiler
from .horizons import (
    affordable_knobs,
    check_horizons,
    error_growth,
    parse_horizons,
    reference_kind,
)
from .horizons_choice import HorizonComparison
from .methods import get_methods
from .work_precision import (
    ERROR_KINDS,
    CompareOptions,
    default_methods,
    methods_in,
    plan_work_precision,
    run_work_precision,
)
from .work_precision_report import in_words, write_work_precision


def work_precision_horizons(scene: Scene, horizons, *, out: str | os.PathLike,
                            unit: float = 1.0, overrides: Mapping[str, object] | None = None,
                            options: CompareOptions | None = None,
                            compilation: Compilation | None = None,
                            workers: Workers | None = None,
                            run_budget_s: float | None = 120.0,
                            reference_span: float = 10_000.0,
                            progress: bool = False) -> dict[float, list[dict]]:
    """Compare at each horizon ``T`` (to ``t_end = t0 + T unit``); write ``out/horizon_T/``
    (the usual report), ``horizons.png`` (a column per horizon, a row per error kind),
    ``growth.png`` (errors against time at equal cost, longest horizon), ``crossover.png``
    (which method is cheapest at each error level and horizon) and ``horizons.md``.
    Returns the rows per horizon (`horizons_study` returns the whole study).

    ``options``: as for `work_precision` (default
    ``max_steps`` here 2e6); its ``knobs`` and ``reference`` are chosen per horizon:
    ``options.max_steps`` and ``run_budget_s`` cut each horizon's sweeps
    (`affordable_knobs`), and a scene without an exact
    solution gets no trajectory reference beyond ``reference_span`` time units
    (`reference_kind`)."""
    study = horizons_study(scene, horizons, out=out, unit=unit, overrides=overrides,
                           options=options, compilation=compilation, workers=workers,
                           run_budget_s=run_budget_s, reference_span=reference_span,
                           progress=progress)
    return {horizon: result.rows for horizon, result in study.results.items()}


def horizons_study(scene: Scene, horizons, *, out: str | os.PathLike | None = None,
                   unit: float = 1.0, overrides: Mapping[str, object] | None = None,
                   options: CompareOptions | None = None,
                   compilation: Compilation | None = None, workers: Workers | None = None,
                   run_budget_s: float | None = 120.0, reference_span: float = 10_000.0,
                   progress: bool = False) -> HorizonComparison:
    """The comparison at each horizon, as a `HorizonComparison`; with ``out`` its reports and
    figures too (`work_precision_horizons`). Every horizon is checked (`check_horizons`)
    before anything runs."""
    options = options if options is not None else CompareOptions(max_steps=2_000_000)
    compilation = compilation or Compilation()
    horizons = parse_horizons(horizons)
    overrides = dict(overrides or {})
    config = scene.resolve(overrides)
    check_horizons(horizons, unit, config)
    chosen = default_methods(scene.system)[0] if options.methods is None \
        else get_methods(options.methods)
    run = (scene, overrides, options, compilation, workers, progress)
    if out is None:
        results, notes = _horizons(run, horizons, None, unit, run_budget_s, reference_span,
                                   config, chosen)
        return HorizonComparison(results, unit, notes)
    with atomic.output_folder(out) as folder:
        results, notes = _horizons(run, horizons, folder, unit, run_budget_s, reference_span,
                                   config, chosen)
        study = HorizonComparison(results, unit, notes)
        _write_figures(scene, study, folder, overrides, options, compilation, reference_span,
                       config)
    return study


def _horizons(run, horizons, folder, unit, run_budget_s, reference_span, config, chosen):
    """The comparisons at each horizon (each its own folder ``horizon_T`` in ``folder``, or
    none) and what each left out."""
    scene, overrides, options, compilation, workers, progress = run
    results, notes, previous = {}, {}, None
    for horizon in horizons:
        t_end = config.t0 + horizon * unit
        knobs, left_out = affordable_knobs(chosen, config, t_end, options.halvings,
                                           options.max_steps, previous=previous,
                                           run_budget_s=run_budget_s)
        kind = reference_kind(scene, t_end - config.t0, reference_span)
        plan = plan_work_precision(
            scene, overrides={**overrides, "t_end": t_end},
            options=replace(options, **_sweeps(chosen, knobs, options.target_errors),
                            reference=kind),
            compilation=compilation, workers=workers)
        results[horizon] = _run(plan, folder, f"horizon_{horizon:g}", progress)
        notes[horizon] = left_out + ([f"the trajectory error (no exact solution, and the "
                                      f"DOP853 reference is computed only up to "
                                      f"{reference_span:g} time units)"]
                                     if kind == "none" else [])
        previous = (t_end - config.t0, results[horizon].rows)
    return results, notes


def _sweeps(chosen, knobs, targets) -> dict:
    """The methods and knob values of one horizon: each method's affordable sweep, except
    that with target errors the methods that aim at an error run at those instead."""
    aiming = {m.name for m in chosen if targets and m.aims}
    return {"methods": [m.name for m in chosen if m.name in knobs or m.name in aiming],
            "knobs": {name: values for name, values in knobs.items() if name not in aiming}}


def _run(plan, folder, name, progress):
    if folder is not None:
        return write_work_precision(plan, folder / name, progress=progress)
    with tempfile.TemporaryDirectory(prefix="ddvp-horizon-") as scratch:
        return run_work_precision(plan, os.path.join(scratch, "work_precision.csv"),
                                  progress=progress)


def _write_figures(scene, study, out, overrides, options, compilation, reference_span,
                   config):
    """Rerun each method at about equal cost over the longest horizon, then commit the
    horizons', growth and crossover figures and ``horizons.md``."""
    results, unit = study.results, study.unit
    longest = max(results)
    span = longest * unit
    target, growth = error_growth(scene, {**overrides, "t_end": config.t0 + span},
                                  results[longest].rows,
                                  compiler=find_compiler(compilation.compiler),
                                  max_steps=options.max_steps,
                                  reference=reference_kind(scene, span, reference_span))
    rows = {horizon: result.rows for horizon, result in results.items()}
    out.commit({
        "horizons.png": figure_writer(out, "horizons.png", lambda handle: plot_horizons(
            rows, handle, title=f"{scene.name}: error against run time", unit=unit,
            time_dependent=scene.system.time_dependent)),
        "growth.png": figure_writer(out, "growth.png", lambda handle: plot_growth(
            growth, handle,
            title=f"{scene.name}: errors against time at about {target:.2g} s each")),
        "crossover.png": figure_writer(out, "crossover.png", lambda handle: study.plot_crossover(
            handle, title=f"{scene.name}: cheapest method")),
        "horizons.md": atomic.text(horizons_summary(scene, rows, study.notes, growth, target,
                                                    unit, study))},
        {"command": "compare", "scene": scene.name, "horizons": list(results)})


def horizons_summary(scene, results, notes, growth, target, unit, study=None) -> str:
    """``horizons.md``: per horizon the cheapest method at each error level in words, what was
    left out, and the equal-cost error growth with the machine it was timed on."""
    lines = [f"# Work-precision over horizons: `{scene.name}`", "",
             f"Horizons in units of {unit:g}; each has its own report in `horizon_T/`.", ""]
    for horizon, rows in results.items():
        lines += [f"## T = {horizon:g}", ""]
        for kind, label in ERROR_KINDS.items():
            lines += [f"- {label.split(' max')[0]}: "
                      + in_words(rows, kind, methods_in(rows)).removeprefix("In words: ")]
        if notes[horizon]:
            lines += ["- Left out: " + "; ".join(notes[horizon]) + "."]
        lines.append("")
    lines += [f"## Error growth at about equal cost ({target:.3g} s), longest horizon", "",
              "| method | knob | run time | final energy error | largest energy error | "
              "final trajectory error |", "|---|---|---|---|---|---|"]
    for item in growth:
        lines.append(f"| `{item.method}` | {item.knob} = {item.value:.3g} | {item.run_s:.3g} s | "
                     f"{item.energy_error[-1]:.2e} | {item.energy_error.max():.2e} | "
                     f"{item.trajectory_error[-1]:.2e} |")
    if study is not None:
        lines += ["", "## Crossovers", "", *study.crossover_words(), "",
                  "![crossover](crossover.png)"]
    lines += ["", f"Run times measured on: {machine()}", "", "![horizons](horizons.png)", "",
              "![growth](growth.png)", ""]
    return "\n".join(lines)


__all__ = ["horizons_study", "horizons_summary", "plot_growth", "plot_horizons",
           "work_precision_horizons"]
