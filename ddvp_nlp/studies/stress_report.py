"""Stress and sweep output: ``NAME.csv``, ``NAME.md`` and ``NAME.png``.

`stress` is the entry point of ``ddvp stress`` and ``ddvp sweep``: it checks the bounds,
creates the folder, runs the grid of `ddvp_nlp.studies.stress` (its rows go to the CSV as
they finish, which is what resume reads back), then writes the Markdown table and the figure
from what the study returned. The table's columns are the methods that ran.
"""

from __future__ import annotations

import math
import os

import numpy as np

from ..io import atomic
from ..io.markdown import failure_table, machine
from ..io.run_folder import figure_writer
from ..io.stress_figure import NOT_RUN, plot_stress
from ..runner.journal import commit_journal
from ..runner.tasks import Workers
from ..solvers import Compilation, StepControl
from .comparable import REFERENCE_RTOL
from .stress import (
    DOP853_RTOL,
    ROWS,
    StressCase,
    StressResult,
    breakdowns,
    plan_stress,
    prediction_for,
    run_stress,
)

DEFAULT_TITLE = "Stress cases: where each scheme breaks"
SHORT = {"success": "ok", "no_admissible_step": "no root", "newton_failed": "Newton",
         "non_finite": "NaN", "residual_too_large": "residual", "step_below_min": "tau<min",
         "step_above_max": "tau>max", "step_ratio": "ratio", "max_steps": "max steps",
         "time_limit": "time", "solver_failed": "failed", "energy_guard": "guard",
         "not_run": "not run"}


def stress(out: str | os.PathLike, *, quick: bool = False, cases: list[StressCase] | None = None,
           steps: StepControl | None = None, compilation: Compilation | None = None,
           workers: Workers | None = None, progress: bool = False, resume: bool = False,
           name: str = "stress", title: str = DEFAULT_TITLE, interruptible=None) -> list[dict]:
    """Run the grid and write ``NAME.csv``, ``NAME.md`` and ``NAME.png`` in ``out``.

    ``steps``: each run's ``max_steps`` and ``time_limit`` (default 2e6 steps, 60 s);
    ``workers``: where the runs go (`Workers`, default: in this
    process). ``resume``: keep the rows already in ``NAME.csv`` and run only the missing tasks.
    """
    plan = plan_stress(quick=quick, cases=cases, steps=steps, compilation=compilation,
                       workers=workers)
    with atomic.output_folder(out) as folder:  # only once the input is known to be good
        result = run_stress(plan, folder / f"{name}.csv", resume=resume, progress=progress,
                            commit=False)
        figure = figure_writer(folder, f"{name}.png",
                               lambda handle: plot_stress(result, handle, cells=cell_grid(result),
                                                         title=title),
                               interruptible)
        commit_journal(folder / f"{name}.csv", ROWS.columns, result.rows,
                    {f"{name}.png": figure,
                     f"{name}.md": atomic.text(report(result, title=title))},
                    {"command": name, "title": title,
                     "succeeded": sum(r["status"] == "success" for r in result.rows)})
    return result.rows


def read_rows(path) -> list[dict]:
    """Rows of a ``stress.csv`` or ``sweep.csv`` with numbers and flags typed."""
    return ROWS.read(path)


def _missing_cell(method) -> str:
    # lee is left out where H does not depend on t: there its equations are vddvp's
    return NOT_RUN[0] if method == "lee" else NOT_RUN[1]


def _cell(row, method="") -> str:
    if row is None:
        return _missing_cell(method)
    error = row["energy_error"]
    error_text = f"{error:.0e}" if math.isfinite(error) else "-"
    if row["status"] == "success":
        return f"ok {error_text}"
    return f"**{SHORT.get(row['status'], row['status'])}** t={row['t_reached']:.3g}"


def report(result: StressResult, *, title: str = DEFAULT_TITLE) -> str:
    """``NAME.md``: per group a table of cases by methods, predicted against observed
    breakdowns, where and why each failed run stopped, and the machine."""
    lines = [f"# {title}", "", _legend(result), ""]
    if result.quick:
        lines += ["*Quick grid (tests): short horizons, fewer cases.*", ""]
    lines += _case_tables(result)
    lines += _breakdown_section(result)
    lines += failure_table(result.rows, "Where and why each failed run stopped",
                           ("case", lambda r: f"{r['group']}: {r['case']}"),
                           ("method", lambda r: f"`{r['method']}`"))
    lines += _inaccurate_table(result.rows)
    lines += ["", "## Machine", "", machine(result.compiler or None), ""]
    return "\n".join(lines)


def _inaccurate_table(rows) -> list[str]:
    """The runs the accuracy check (``solvers/accuracy/judgement.py``) refuses, whatever their
    status: which method was inaccurate where, and the estimated global error at the end."""
    flagged = [r for r in rows if str(r.get("accuracy", "")).startswith("inaccurate")]
    if not flagged:
        return []
    lines = ["", "## Where each method was inaccurate", "",
             "The accuracy check on the returned nodes (one RK4 step of the exact flow per step, "
             "the first step's energy level, the nodal energy drift; default tolerances), "
             "whether or not the run reached t_end.", "",
             "| case | method | status | first failed test | trajectory error "
             "(of the motion's size) |",
             "|---|---|---|---|---|"]
    for r in flagged:
        lines.append(f"| {r['group']}: {r['case']} | `{r['method']}` | {r['status']} | "
                     f"{r['accuracy'].removeprefix('inaccurate: ')} | "
                     f"{r['error_estimate']:.2e} |")
    return lines


def _legend(result: StressResult) -> str:
    return ("Each cell: `ok` and the largest relative energy error "
            "max |H - H_ref| / max(1, |H0|), or the failure and the time it was reached "
            "(details below). Bounds per run: "
            f"{result.max_steps} steps, {result.time_limit:g} s. Steps: the case's tau "
            f"for every step method (for `vddvp`/`lee` the first step); DOP853 at rtol = atol = "
            f"{DOP853_RTOL:g}. Energy reference for time-dependent H: DOP853 at "
            f"{REFERENCE_RTOL:g}. `lee` runs only where H depends on t (elsewhere its equations"
            " are `vddvp`'s).")


def _case_tables(result: StressResult) -> list[str]:
    methods = result.methods
    header = "| case | tau | predicted for vddvp | " + " | ".join(f"`{m}`" for m in methods) + " |"
    rule = "|---|---|---|" + "---|" * len(methods)
    lines = []
    for group in dict.fromkeys(c.group for c in result.cases):
        lines += ["", f"## {group}", "", header, rule]
        for case in [c for c in result.cases if c.group == group]:
            cells = [_cell(result.row(case, m), m) for m in methods]
            lines.append(f"| {case.name} | {case.tau:.3g} | "
                         f"{_prediction_text(prediction_for(result, case))} | "
                         + " | ".join(cells) + " |")
    return lines


def _breakdown_section(result: StressResult) -> list[str]:
    lines = ["", "## Predicted and observed breakdowns of the energy step", "",
             "Prediction: a positive step needs c(z) to keep its sign along the orbit (sampled "
             "at DOP853's nodes).", "",
             "| case | c(z) changes sign along the orbit | smallest abs(w)/max abs(w) | vddvp "
             "observed | vddvp steps | agrees |", "|---|---|---|---|---|---|"]
    found = breakdowns(result)
    for b in found:
        lines.append(f"| {b.case.group}: {b.case.name} | "
                     f"{'yes' if b.prediction['breaks'] else 'no'} | "
                     f"{b.prediction['w_ratio']:.1e} | {_cell(b.row)} | "
                     f"{b.row['tau_min']:.3g} .. {b.row['tau_max']:.3g} | "
                     f"{'yes' if b.agrees else '**no**'} |")
    unexplained = [b for b in found if not b.agrees]
    if unexplained:
        lines += ["", "Where the sign of c(z) did not tell:", ""]
    for b in unexplained:
        what = (f"broke ({b.row['status']}) although c keeps its sign" if b.broke else
                "reached t_end although c changes sign along the orbit")
        lines.append(f"- {b.case.group}: {b.case.name}: {what}; steps from "
                     f"{b.row['tau_min']:.3g} to {b.row['tau_max']:.3g}.")
    return lines


def _prediction_text(prediction) -> str:
    if prediction is None:
        return "-"
    if prediction["breaks"]:
        return "breaks (c changes sign)"
    return f"runs (min abs(w)/max = {prediction['w_ratio']:.0e})"


def cell_grid(result: StressResult):
    """``log10`` of each cell's energy error (NaN unless it succeeded) and its text."""
    cases, methods = result.cases, result.methods
    values = np.full((len(cases), len(methods)), np.nan)
    texts = [["" for _ in methods] for _ in cases]
    for i, case in enumerate(cases):
        for j, m in enumerate(methods):
            r = result.row(case, m)
            if r is None:
                texts[i][j] = _missing_cell(m)
            elif r["status"] == "success":
                values[i, j] = math.log10(max(r["energy_error"], 1e-16))
                texts[i][j] = f"{r['energy_error']:.0e}"
            else:
                texts[i][j] = SHORT.get(r["status"], r["status"])
            if r is not None and str(r.get("accuracy", "")).startswith("inaccurate"):
                texts[i][j] += " (!)"  # the accuracy check refuses it (the report says where)
    return values, texts


