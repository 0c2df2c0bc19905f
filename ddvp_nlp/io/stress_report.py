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

from ..solvers.options import Compilation, StepControl
from ..studies.grid import Workers, commit_grid
from ..studies.reference import REFERENCE_RTOL
from ..studies.stress import (
    DOP853_RTOL,
    ROWS,
    Case,
    StressResult,
    breakdowns,
    plan_stress,
    prediction_for,
    run_stress,
)
from . import atomic, figures
from .markdown import failure_table, machine
from .runs import figure_writer

DEFAULT_TITLE = "Stress cases: where each scheme breaks"
SHORT = {"success": "ok", "no_admissible_step": "no root", "newton_failed": "Newton",
         "non_finite": "NaN", "residual_too_large": "residual", "step_below_min": "tau<min",
         "step_above_max": "tau>max", "step_ratio": "ratio", "max_steps": "max steps",
         "time_limit": "time", "solver_failed": "failed", "energy_guard": "guard",
         "not_run": "not run"}
NOT_RUN = ("= vddvp", "n/a")  # cells of a method that did not run on a case


def stress(out: str | os.PathLike, *, quick: bool = False, cases: list[Case] | None = None,
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
                               lambda handle: plot_stress(result, handle, title=title),
                               interruptible)
        commit_grid(folder / f"{name}.csv", ROWS.columns, result.rows,
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
    lines += ["", "## Machine", "", machine(result.compiler), ""]
    return "\n".join(lines)


def _inaccurate_table(rows) -> list[str]:
    """The runs the accuracy check (``solvers/accuracy.py``) refuses, whatever their status:
    which method was inaccurate where, and the estimated global error at the end."""
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


def _grid_cells(result: StressResult):
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


def plot_stress(result: StressResult, path, *, title: str = DEFAULT_TITLE, fmt: str = "png"):
    """The grid as a picture, coloured by each successful run's relative energy error on a log
    colour scale spanning the errors measured (``figures.log_norm``: it does not saturate).
    A sweep over two axes is drawn as a map per method (the axes' values as coordinates);
    anything else as cases by methods. Failed runs are red cells with their status, runs not
    made grey; titled by ``title`` (the stress cases' or the sweep's)."""
    plane = _plane(result.cases)
    with figures.styled():
        if plane is None:
            fig = _case_grid(result, title)
        else:
            fig = _sweep_maps(result, plane, title)
        figures.save(fig, path, fmt)


def _plane(cases) -> tuple | None:
    """``(x_name, xs, y_name, ys, index)`` when the cases are the full product of two axes
    (a sweep's names read ``a=1, b=2``), ``index[(x, y)]`` the case there; else ``None``."""
    if len({c.group for c in cases}) != 1:
        return None
    points = []
    for case in cases:
        try:
            pairs = [item.split("=") for item in case.name.split(", ")]
            points.append({k: float(v) for k, v in pairs})
        except ValueError:
            return None
    if not points or any(len(p) != 2 or list(p) != list(points[0]) for p in points):
        return None
    x_name, y_name = list(points[0])
    xs = sorted({p[x_name] for p in points})
    ys = sorted({p[y_name] for p in points})
    index = {(p[x_name], p[y_name]): case for p, case in zip(points, cases, strict=True)}
    if len(xs) < 2 or len(ys) < 2 or len(index) != len(xs) * len(ys):
        return None
    return x_name, xs, y_name, ys, index


def _case_grid(result: StressResult, title: str):
    cases, methods = result.cases, result.methods
    values, texts = _grid_cells(result)
    fig = figures.new_figure(2.4 + 1.1 * len(methods), 1.3 + 0.24 * len(cases))
    ax = fig.subplots()
    norm = figures.log_norm(10.0 ** values)
    image = ax.imshow(np.ma.masked_invalid(10.0 ** values), cmap=_error_colours(), norm=norm,
                      aspect="auto", interpolation="nearest")
    _label_cells(ax, values, texts, norm)
    ax.set_xticks(range(len(methods)), methods, rotation=20)
    ax.set_yticks(range(len(cases)), [f"{c.group}: {c.name}" for c in cases], fontsize=7)
    ax.minorticks_off()
    ax.tick_params(top=False, right=False)
    fig.colorbar(image, ax=ax, label="relative energy error (red: failed; grey: not run)")
    ax.set_title(f"{title}: status and energy error;\n(!) the accuracy check refuses the run")
    return fig


def _error_colours():
    import matplotlib

    return matplotlib.colormaps["viridis"].with_extremes(bad="#CC3311")


def _sweep_maps(result: StressResult, plane, title: str):
    """One panel per method over the two swept axes: the energy error as colour (log scale,
    one colour bar for all), failed points as red cells marked with a cross."""
    x_name, xs, y_name, ys, index = plane
    methods = result.methods
    grids = {}
    for method in methods:
        grid = np.full((len(ys), len(xs)), np.nan)
        failed = np.zeros(grid.shape, dtype=bool)
        for (x, y), case in index.items():
            row = result.row(case, method)
            if row is None:
                continue
            if row["status"] == "success":
                grid[ys.index(y), xs.index(x)] = max(row["energy_error"], 1e-300)
            else:
                failed[ys.index(y), xs.index(x)] = True
        grids[method] = (grid, failed)
    norm = figures.log_norm(np.concatenate([g.ravel() for g, _ in grids.values()]))
    fig = figures.new_figure(0.6 + 2.5 * len(methods), 2.9)
    axes = np.atleast_1d(fig.subplots(1, len(methods), sharey=True))
    for ax, method in zip(axes, methods, strict=True):
        grid, failed = grids[method]
        image = ax.pcolormesh(_edges(xs), _edges(ys), np.ma.masked_invalid(grid),
                              cmap=_error_colours().with_extremes(bad="#DDDDDD"), norm=norm)
        rows, columns = np.nonzero(failed)
        ax.plot(np.asarray(xs)[columns], np.asarray(ys)[rows], **figures.FAILED)
        ax.set_title(method)
        ax.set_xlabel(_axis_label(x_name))
        ax.minorticks_off()
    axes[0].set_ylabel(_axis_label(y_name))
    if failed_any := any(f.any() for _, f in grids.values()):
        figures.failed_legend(axes[-1], "failed")
    if failed_any:
        axes[-1].legend(loc="upper right")
    fig.colorbar(image, ax=list(axes), label="relative energy error (grey: not run)")
    fig.suptitle(title)
    return fig


def _edges(values) -> np.ndarray:
    """Cell edges around the points ``values``: midpoints, and half a spacing beyond the ends
    (on a log scale when the points are spread over more than a decade)."""
    v = np.asarray(values, dtype=float)
    logarithmic = v.min() > 0 and v.max() / v.min() > 10
    w = np.log10(v) if logarithmic else v
    inner = (w[1:] + w[:-1]) / 2
    edges = np.concatenate([[w[0] - (inner[0] - w[0])], inner, [w[-1] + (w[-1] - inner[-1])]])
    return 10.0 ** edges if logarithmic else edges


def _axis_label(name: str) -> str:
    """A swept setting as an axis label, Greek and indices typeset (``tau0`` -> ``$\\tau_0$``)."""
    greek = {"tau0": r"$\tau_0$", "omega": r"$\omega$", "eps": r"$\varepsilon$",
             "alpha": r"$\alpha$", "e": "$e$", "t_end": r"$t_{\mathrm{end}}$"}
    return greek.get(name, name)


def _label_cells(ax, values, texts, norm):
    from matplotlib.patches import Rectangle

    middle = np.sqrt(norm.vmin * norm.vmax)
    for i, row in enumerate(texts):
        for j, text in enumerate(row):
            skipped = text in NOT_RUN  # not run: grey, not failed red
            if skipped:
                ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, color="#dddddd"))
            dark = (np.isnan(values[i, j]) and not skipped) or 10.0 ** values[i, j] < middle
            ax.text(j, i, text, ha="center", va="center", fontsize=6,
                    color="white" if dark else "black")
