"""Work-precision at several horizons and the error-growth figure: ``horizons.png``,
``growth.png``, ``horizons.md``, and each horizon's own report in ``horizon_T/``.

`work_precision_horizons` runs `work_precision` once per
horizon (``t_end = t0 + T unit``), with the sweeps cut to what ``max_steps`` affords
(`affordable_knobs`), then reruns each method at about equal
cost over the longest horizon and draws its errors against time.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import replace

from ..io import atomic
from ..io.horizons_figure import plot_growth, plot_horizons
from ..io.markdown import machine
from ..io.run_folder import figure_writer
from ..runner.tasks import Workers
from ..scenes import Scene
from ..solvers import Compilation, find_compiler
from .horizons import affordable_knobs, error_growth, parse_horizons, reference_kind
from .methods import get_methods
from .work_precision import ERROR_KINDS, CompareOptions, default_methods, methods_in
from .work_precision_report import in_words, work_precision


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
    ``growth.png`` (errors against time at equal cost, longest horizon) and ``horizons.md``.
    Returns the rows per horizon.

    ``options``: as for `work_precision` (default
    ``max_steps`` here 2e6); its ``knobs`` and ``reference`` are chosen per horizon:
    ``options.max_steps`` and ``run_budget_s`` cut each horizon's sweeps
    (`affordable_knobs`), and a scene without an exact
    solution gets no trajectory reference beyond ``reference_span`` time units
    (`reference_kind`)."""
    options = options if options is not None else CompareOptions(max_steps=2_000_000)
    compilation = compilation or Compilation()
    horizons = parse_horizons(horizons)
    overrides = dict(overrides or {})
    config = scene.resolve(overrides)
    chosen = default_methods(scene.system)[0] if options.methods is None \
        else get_methods(options.methods)
    with atomic.output_folder(out) as folder:
        return _horizons(scene, horizons, folder, unit, overrides, options, compilation,
                         workers, run_budget_s, reference_span, progress, config, chosen)


def _horizons(scene, horizons, out, unit, overrides, options, compilation, workers,
              run_budget_s, reference_span, progress, config, chosen):
    """The comparisons at each horizon (each its own folder), then the set of the horizons'
    figures and summary."""
    results, notes, previous = {}, {}, None
    for horizon in horizons:
        t_end = config.t0 + horizon * unit
        knobs, left_out = affordable_knobs(chosen, config, t_end, options.halvings,
                                           options.max_steps, previous=previous,
                                           run_budget_s=run_budget_s)
        kind = reference_kind(scene, t_end - config.t0, reference_span)
        results[horizon] = work_precision(
            scene, overrides={**overrides, "t_end": t_end}, out=out / f"horizon_{horizon:g}",
            options=replace(options, methods=list(knobs), knobs=knobs, reference=kind),
            compilation=compilation, workers=workers, progress=progress)
        notes[horizon] = left_out + ([f"the trajectory error (no exact solution, and the "
                                      f"DOP853 reference is computed only up to "
                                      f"{reference_span:g} time units)"]
                                     if kind == "none" else [])
        previous = (t_end - config.t0, results[horizon])
    longest = horizons[-1]
    span = longest * unit
    target, growth = error_growth(scene, {**overrides, "t_end": config.t0 + span},
                                  results[longest],
                                  compiler=find_compiler(compilation.compiler),
                                  max_steps=options.max_steps,
                                  reference=reference_kind(scene, span, reference_span))
    out.commit({
        "horizons.png": figure_writer(out, "horizons.png", lambda handle: plot_horizons(
            results, handle, title=f"{scene.name}: error against run time", unit=unit)),
        "growth.png": figure_writer(out, "growth.png", lambda handle: plot_growth(
            growth, handle,
            title=f"{scene.name}: errors against time at about {target:.2g} s each")),
        "horizons.md": atomic.text(horizons_summary(scene, results, notes, growth, target,
                                                    unit))},
        {"command": "compare", "scene": scene.name, "horizons": list(results)})
    return results


def horizons_summary(scene, results, notes, growth, target, unit) -> str:
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
    lines += ["", f"Run times measured on: {machine()}", "", "![horizons](horizons.png)", "",
              "![growth](growth.png)", ""]
    return "\n".join(lines)


__all__ = ["horizons_summary", "plot_growth", "plot_horizons",
           "work_precision_horizons"]
