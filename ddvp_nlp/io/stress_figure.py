"""The figure of ``ddvp stress`` and ``ddvp sweep`` (``NAME.png``): the grid of runs coloured by
each successful run's energy error, failed runs red with their status, runs not made grey; a
sweep over two axes as a map per method. It draws a study's result (its ``cases``, ``methods``
and ``row(case, method)``) and the cells' values and texts the study computed."""

from __future__ import annotations

import numpy as np

from . import figures

NOT_RUN = ("= vddvp", "n/a")  # cells of a method that did not run on a case


def plot_stress(result, path, *, cells, title: str, fmt: str = "png"):
    """The grid as a picture, coloured by each successful run's relative energy error on a log
    colour scale spanning the errors measured (``figures.log_norm``: it does not saturate).
    A sweep over two axes is drawn as a map per method (the axes' values as coordinates);
    anything else as cases by methods. Failed runs are red cells with their status, runs not
    made grey; titled by ``title`` (the stress cases' or the sweep's); ``cells`` is
    ``(values, texts)`` of the case-by-method grid."""
    plane = _plane(result.cases)
    with figures.styled():
        if plane is None:
            fig = _case_grid(result, cells, title)
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


def _case_grid(result, cells, title: str):
    cases, methods = result.cases, result.methods
    values, texts = cells
    fig = figures.new_figure(2.4 + 1.1 * len(methods), 1.3 + 0.24 * len(cases))
    ax = fig.subplots()
    norm = figures.log_norm(10.0 ** values)
    image = ax.imshow(np.ma.masked_invalid(10.0 ** values), cmap=_error_colours(), norm=norm,
                      aspect="auto", interpolation="nearest")
    for i, case in enumerate(cases):
        for j, method in enumerate(methods):
            row = result.row(case, method)
            if row is not None and row["status"] == "success" and _verdict_of(row):
                _mark_verdict(ax, j, (i - 0.5, i + 0.5), _verdict_of(row), 10.0 ** values[i, j],
                              norm, named=False)
    _label_cells(ax, values, texts, norm)
    ax.set_xticks(range(len(methods)), methods, rotation=20)
    ax.set_yticks(range(len(cases)), [f"{c.group}: {c.name}" for c in cases], fontsize=7)
    ax.minorticks_off()
    ax.tick_params(top=False, right=False)
    fig.colorbar(image, ax=ax, label="relative energy error (red: failed; grey: not run)")
    ax.set_title(f"{title}: status and energy error;\n(!) the accuracy check refuses the run; "
                 "hatched: judged drifted (/) or inaccurate (x)")
    return fig


def _error_colours():
    import matplotlib

    return matplotlib.colormaps["viridis"].with_extremes(bad="#CC3311")


def _sweep_maps(result, plane, title: str):
    """One panel per method over the two swept axes, one cell per swept value (the values are
    the grid's categories, ticked by their value, not points of a continuous axis): the
    energy error as colour (log scale, one colour bar for all), failed runs red with their
    status, runs not made grey; a run that reached its end but that the accuracy check judged
    drifted or inaccurate hatched and named in its cell (its colour alone read as a good run).
    A method whose run does not depend on a swept ``tau0`` (DOP853's rtol) is drawn once
    across that axis, its knob in its title."""
    x_name, xs, y_name, ys, index = plane
    methods = result.methods
    grids = {method: _method_grid(result, method, plane) for method in methods}
    norm = figures.log_norm(np.concatenate([g.ravel() for g, *_ in grids.values()]))
    fig = figures.new_figure(0.6 + max(2.5, 0.45 * len(xs) + 1.0) * len(methods),
                             max(2.9, 0.3 * len(ys) + 1.8))
    axes = np.atleast_1d(fig.subplots(1, len(methods), sharey=True))
    colours = _error_colours().with_extremes(bad=NOT_RUN_COLOUR)
    for ax, method in zip(axes, methods, strict=True):
        grid, failed, verdicts, unused = grids[method]
        rows_drawn = 1 if unused else len(ys)
        image = ax.pcolormesh(np.arange(len(xs) + 1) - 0.5,
                              np.linspace(-0.5, len(ys) - 0.5, rows_drawn + 1),
                              np.ma.masked_invalid(grid[:rows_drawn]), cmap=colours, norm=norm)
        for (i, j), status in failed.items():
            ax.add_patch(_cell(j, i, FAILED_COLOUR))
            ax.text(j, i, status.replace("_", "\n", 1), ha="center", va="center",
                    fontsize=5.5, color="white")
        for (i, j), verdict in verdicts.items():
            _mark_verdict(ax, j, (i - 0.5, i + 0.5) if not unused else (-0.5, len(ys) - 0.5),
                          verdict, grid[i, j], norm)
        ax.set_xticks(range(len(xs)), [f"{x:g}" for x in xs])
        ax.set_yticks(range(len(ys)), [f"{y:g}" for y in ys])
        ax.minorticks_off()
        ax.tick_params(top=False, right=False, length=0)
        ax.set_title(method if not unused else
                     f"{method}: {unused} at every {_axis_label(y_name)}")
        ax.set_xlabel(_axis_label(x_name))
    axes[0].set_ylabel(_axis_label(y_name))
    fig.colorbar(image, ax=list(axes), label="relative energy error")
    _sweep_legend(fig, grids)
    fig.suptitle(title)
    return fig


# How a run that reached its end is marked when the accuracy check did not call it accurate.
VERDICT_HATCHES = {"drifted": "////", "inaccurate": "xxxx"}


def _verdict_of(row) -> str | None:
    """``drifted`` or ``inaccurate`` for a successful run the accuracy check judged so, else
    ``None`` (accurate, or not checked)."""
    found = str(row.get("accuracy", "") or "")
    return next((name for name in VERDICT_HATCHES if found.startswith(name)), None)


def _method_grid(result, method, plane):
    """``(errors, failed, verdicts, unused)`` of one method's panel: the energy errors by
    ``(y, x)`` cell, the failed cells' statuses, the successful cells judged drifted or
    inaccurate, and, when the plane's y axis is ``tau0`` and the method's run does not depend
    on it (its knob is not the step and its value is the same along it), ``"knob = value"``
    (the panel draws one row), else ``None``."""
    x_name, xs, y_name, ys, index = plane
    grid = np.full((len(ys), len(xs)), np.nan)
    failed, verdicts, knobs = {}, {}, set()
    for (x, y), case in index.items():
        row = result.row(case, method)
        if row is None:
            continue
        cell = ys.index(y), xs.index(x)
        knobs.add((row.get("knob"), row.get("value"), x))
        if row["status"] == "success":
            grid[cell] = max(row["energy_error"], 1e-300)
            if _verdict_of(row):
                verdicts[cell] = _verdict_of(row)
        else:
            failed[cell] = row["status"]
    names = {knob for knob, _, _ in knobs}
    unused = None
    if (y_name == "tau0" and len(names) == 1 and None not in names
            and not names & {"tau0", "tau"} and len(knobs) == len(xs) and not failed
            and len({value for _, value, _ in knobs}) == 1):
        knob, value, _ = next(iter(knobs))
        unused = f"{knob} = {value:g}"
        verdicts = {cell: v for cell, v in verdicts.items() if cell[0] == 0}
    return grid, failed, verdicts, unused


def _mark_verdict(ax, column, span, verdict, value, norm, *, named: bool = True) -> None:
    """A cell the accuracy check did not pass: hatched in a colour that shows on its own
    (white on the dark end of the colour scale, black on the light end), its verdict
    written in it, on a light box over the hatching."""
    from matplotlib.patches import Rectangle

    light = np.isfinite(value) and norm(value) > 0.55
    ink = "black" if light else "white"
    low, high = span
    ax.add_patch(Rectangle((column - 0.5, low), 1, high - low, fill=False,
                           hatch=VERDICT_HATCHES[verdict], edgecolor=ink, lw=0))
    if named:
            ax.text(column, 0.5 * (low + high), verdict, ha="center", va="center", fontsize=6,
                color="black", bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "none",
                                     "alpha": 0.85})


def _sweep_legend(fig, grids) -> None:
    from matplotlib.patches import Patch

    keys = ([Patch(color=FAILED_COLOUR, label="failed (its status)")]
            if any(f for _, f, _, _ in grids.values()) else [])
    if any(np.isnan(g).sum() > len(f) for g, f, _, _ in grids.values()):
        keys.append(Patch(color=NOT_RUN_COLOUR, label="not run"))
    found = {v for _, _, verdicts, _ in grids.values() for v in verdicts.values()}
    keys += [Patch(facecolor="white", edgecolor="black", hatch=VERDICT_HATCHES[name], lw=0.5,
                   label=f"reached $t_{{end}}$, judged {name}")
             for name in VERDICT_HATCHES if name in found]
    if keys:
        fig.legend(handles=keys, loc="outside lower center", ncol=len(keys),
                   fontsize="small")


FAILED_COLOUR, NOT_RUN_COLOUR = figures.FAILED["color"], "#DDDDDD"


def _cell(column, row, colour):
    from matplotlib.patches import Rectangle

    return Rectangle((column - 0.5, row - 0.5), 1, 1, color=colour, lw=0)


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
