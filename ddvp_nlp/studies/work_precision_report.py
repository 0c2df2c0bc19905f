"""Work-precision output: ``work_precision.csv``, ``work_precision.png`` and ``summary.md``.

`write_work_precision` runs a checked comparison (`ddvp_nlp.studies.work_precision`) into a
folder it creates (its rows go to the CSV as they finish), then draws the figure and writes the
summary from what the study returned. ``compare`` (``studies/comparison.py``, the public entry
that ``ddvp compare`` calls) and `work_precision` (the horizons study's) go through it.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping

from ..io import atomic
from ..io.markdown import failure_table, machine, seconds, yes_no
from ..io.run_folder import figure_writer
from ..io.work_precision_figure import plot_work_precision
from ..runner.journal import commit_journal, read_csv
from ..runner.tasks import Workers
from ..scenes import Scene
from ..solvers import Compilation
from .methods import METHODS
from .work_precision import (
    ADDED,
    ERROR_KINDS,
    ROWS,
    CompareOptions,
    WorkPrecision,
    WorkPrecisionPlan,
    methods_in,
    pareto,
    plan_work_precision,
    rankings,
    run_work_precision,
    time_ratios,
    winner_spans,
)


def work_precision(scene: Scene, *, out: str | os.PathLike,
                   overrides: Mapping[str, object] | None = None,
                   options: CompareOptions | None = None, compilation: Compilation | None = None,
                   workers: Workers | None = None, progress: bool = False,
                   interruptible=None) -> list[dict]:
    """Run the comparison and write ``work_precision.csv``, ``.png`` and ``summary.md`` in
    ``out`` (created). Returns the rows.

    Args:
        scene: the scene; ``overrides`` as for `Scene.resolve` (parameters, ``t_end``, ...).
        out: the folder.
        options: the methods, their sweeps, the timing and the reference
            (`CompareOptions`).
        compilation: for the compiled methods, as in `ddvp_nlp.march`.
        workers: where the runs go (`Workers`). The default
            runs them one after the other in this process, because the run times are what is
            compared: two runs at once on a 2-core machine slow each other down.
        progress: a progress bar on stderr.
    """
    plan = plan_work_precision(scene, overrides=overrides, options=options,
                               compilation=compilation, workers=workers)
    return write_work_precision(plan, out, progress=progress, interruptible=interruptible).rows


def write_work_precision(plan: WorkPrecisionPlan, out, *, progress: bool = False,
                         interruptible=None) -> WorkPrecision:
    """Run a checked comparison into the folder ``out`` (created now, once the input is known
    to be good): ``work_precision.csv``, ``.png`` and ``summary.md``. Returns what it
    measured."""
    scene = plan.scene
    with atomic.output_folder(out) as folder:
        result = run_work_precision(plan, folder / "work_precision.csv", progress=progress,
                                    commit=False)
        figure = figure_writer(folder, "work_precision.png", lambda handle: plot_work_precision(
            result.rows, handle, title=f"{scene.name}: error against run time",
            time_dependent=scene.system.time_dependent), interruptible)
        commit_journal(folder / "work_precision.csv", ROWS.columns, result.rows,
                    {"work_precision.png": figure, "summary.md": atomic.text(summary(result))},
                    {"command": "compare", "scene": scene.name,
                     "succeeded": sum(r["status"] == "success" for r in result.rows)})
    return result


def read_rows(path) -> list[dict]:
    """Rows of a ``work_precision.csv`` with numbers as numbers (a file written before a
    column was added reads it as not measured)."""
    return [ROWS.parse({**ADDED, **row}) for row in read_csv(path, missing_ok=False)]


def summary(result: WorkPrecision) -> str:
    """``summary.md``: the run, the methods, the cheapest method at each error level, vddvp
    against DOP853, the failed runs and the machine."""
    rows = result.rows
    methods = methods_in(rows)
    lines = [*_header(result), *_methods_table(rows, methods)]
    if result.left_out:
        lines += ["", "Left out on this scene: " + "; ".join(result.left_out) + "."]
    for kind, label in ERROR_KINDS.items():
        lines += _ranking_section(rows, kind, label.split(" max")[0])
        lines += ["", in_words(rows, kind, methods)]
    lines += ["", "## vddvp against DOP853 at equal energy error", "", _ratio_text(rows)]
    lines += failure_table(rows, "Runs that did not reach t_end",
                           ("method", lambda r: f"`{r['method']}`"),
                           ("knob", lambda r: f"{r['knob']} = {r['value']:.3g}"))
    lines += _limitation_note(result)
    lines += _residual_note(rows)
    lines += ["", "## Machine", "", machine(result.compiler or None), ""]
    return "\n".join(lines)


def _header(result: WorkPrecision) -> list[str]:
    scene, config, reference = result.scene, result.config, result.reference
    params = (", " + ", ".join(f"{k} = {v:g}" for k, v in config.params.items())
              if config.params else "")
    reference_cost = (f" ({reference.steps} steps, {reference.seconds:.1f} s)."
                      if reference.steps else ".")
    energy = ("the deviation of H(z_k, t_k) from the reference's H(z_ref(t_k), t_k) (H depends "
              "on t)." if scene.system.time_dependent else
              "the largest drift of H at the nodes, max |H(z_k) - H(z_0)|.")
    return [f"# Work-precision: `{scene.name}`", "", f"{scene.description}", "",
            f"Run: t from {config.t0:g} to {config.t_end:g}, q0 = {config.q0.tolist()}, "
            f"p0 = {config.p0.tolist()}" + params + ".",
            f"Reference: {reference.kind}" + reference_cost,
            "Energy error: " + energy,
            f"Run time: best of up to {result.repeats} calls after one warm-up (repeats stop "
            f"after {result.budget_s:g} s); build and compile time excluded; a run at a target "
            "error includes its pilot run. work_precision.png draws the same time (open "
            "markers: the CPU time of that call; `WorkPrecision.best(..., clock='cpu')` ranks "
            "by it).", ""]


def _methods_table(rows, methods) -> list[str]:
    lines = ["| method | order | symplectic | energy-conserving | knob | runs | failed |",
             "|---|---|---|---|---|---|---|"]
    for method in methods:
        m = METHODS[method]
        mine = [r for r in rows if r["method"] == method]
        failed = sum(r["status"] != "success" for r in mine)
        lines.append(f"| `{method}` | {m.order} | {yes_no(m.symplectic)} | "
                     f"{yes_no(m.energy_conserving)} | {m.knob} | {len(mine)} | {failed} |")
    return lines


def _ranking_section(rows, kind, name) -> list[str]:
    lines = ["", f"## Cheapest method at each {name} level", "",
             "| error at most | cheapest | run time | next | ratio |", "|---|---|---|---|---|"]
    for level, ranking in rankings(rows, kind):
        winner, time, bound = ranking[0]
        upper = "at most " if bound else ""
        next_text, ratio_text = "none reaches it", "-"
        if len(ranking) > 1:
            other, other_time, other_bound = ranking[1]
            next_text = f"`{other}`"
            # An "at most" time makes the ratio a bound (winner) or unknown (both).
            ratio_text = ("-" if bound else
                          f"{'<= ' if other_bound else ''}{other_time / time:.2g}x")
        lines.append(f"| {level:.0e} | `{winner}` | {upper}{seconds(time)} | {next_text} |"
                     f" {ratio_text} |")
    return lines


def in_words(rows, kind, methods) -> str:
    """Which method to use, per range of error levels, in one sentence each."""
    spans = winner_spans(rows, kind)
    if not spans:
        return "No method reached any error level in this sweep."
    parts = [f"`{w}` from {hi:.0e} down to {lo:.0e}" if hi != lo else f"`{w}` at {hi:.0e}"
             for w, hi, lo in spans]
    missing = [m for m in methods if not pareto(rows, m, kind)]
    text = "In words: cheapest is " + "; then ".join(parts) + "."
    if missing:
        text += " No successful run: " + ", ".join(f"`{m}`" for m in missing) + "."
    return text


def _ratio_text(rows) -> str:
    found = time_ratios(rows, "vddvp", "dop853", "energy_error")
    if found is None:
        return "Not measured here (both `vddvp` and `dop853` need successful runs)."
    if not found:
        return ("The two sweeps do not overlap in energy error (interpolated levels only), so no "
                "ratio at equal error is measured.")
    return "\n".join(["| energy error | vddvp | DOP853 | time ratio vddvp / DOP853 |",
                      "|---|---|---|---|",
                      *(f"| {level:.0e} | {seconds(a)} | {seconds(b)} | {a / b:.3g} |"
                        for level, a, b in found)])


def _limitation_note(result: WorkPrecision) -> list[str]:
    """Why a method with no successful run cannot run here, in the words of its integrator."""
    found = result.limitations()
    if not found:
        return []
    return ["", "## Methods that cannot run on this orbit", "",
            *(f"- `{name}`: {why}." for name, why in found.items())]


def _residual_note(rows) -> list[str]:
    residuals = [r for r in rows if r["status"] == "success"
                 and math.isfinite(r["scheme_energy_residual"])]
    if not residuals:
        return []
    worst = max(residuals, key=lambda r: r["scheme_energy_residual"])
    return ["", f"The energy-conserving schemes' own energy equations held to "
            f"{worst['scheme_energy_residual']:.1e} at worst (`{worst['method']}`, "
            f"{worst['knob']} = {worst['value']:.3g}); the energy error above is H at the "
            f"nodes, which these schemes keep within O(tau^2) without drift."]
