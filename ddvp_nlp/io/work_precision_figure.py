"""The work-precision figure of ``ddvp compare`` (``work_precision.png``): error against run
time, one panel per error kind, from the rows of the comparison (plain dicts with ``method``,
``status``, ``run_s`` and one column per error kind; ``cpu_s``, ``repeats``, ``knob`` and
``run_s_max``/``cpu_s_max``, the slowest of the timed calls, where measured).

Drawn for a journal's column by default (`figures.COLUMN_WIDTH`, the panels stacked, the
house style's 8-9 pt fonts at print size); ``width="text"`` puts them side by side across a
page. Each run is drawn at the cost the summary and `WorkPrecision.best` rank by, the fastest
of its timed calls (``clock="wall"``, the default) or that call's CPU time (``clock="cpu"``, the
cost to read on a machine other processes share, where wall time counts their turns too), with
a bar to the slowest call: the spread a single number hides. Drawn by wall time, each run's
CPU time is an open marker on the same row, so a loaded machine shows as a gap between them.
A run at a target error (``knob`` ``target_error``) costs its pilot run too; its legend entry
says so.
"""

from __future__ import annotations

import math

from . import figures

# The axis labels: exactly what the comparison measures (studies/work_precision.py's
# `errors`), the formula on the axis and its name above the panel. Both errors are absolute,
# in the units of z = (q, p) and of H: no scale divides them (the target errors of a march,
# by contrast, are relative to the motion's size).
AXIS_LABELS = {"trajectory_error": r"$\max_{k,i}\, |z_{k,i} - z_{\mathrm{ref},i}(t_k)|$",
               "energy_error": r"$\max_k\, |H(z_k) - H(z_0)|$"}
PANEL_TITLES = {"trajectory_error": "trajectory error (absolute, units of $q$, $p$)",
                "energy_error": "energy error (absolute, units of $H$)"}
# The energy error of a time-dependent H: against the reference's H at the same time.
TIME_DEPENDENT_ENERGY = r"$\max_k\, |H(z_k, t_k) - H(z_{\mathrm{ref}}(t_k), t_k)|$"
# The cost on the x axis: the column the rankings read (`work_precision.CLOCKS`) and its label.
CLOCK_COLUMNS = {"wall": ("run_s", "run_s_max"), "cpu": ("cpu_s", "cpu_s_max")}
CLOCK_LABELS = {"wall": "wall time [s]\nbest of {n}{bar}",
                "cpu": "CPU time [s] of the best of {n}\n{bar}"}
BAR_NOTE = " (bar: to the worst)"
PILOT_NOTE = "target error; time incl. pilot"
LONG_LABEL = 28  # characters of a legend entry two of which fit side by side in a column
CPU_MARKER = {"marker": "o", "mfc": "none", "ms": 3.5, "mew": 0.6, "linestyle": "none"}


def run_time_label(rows, clock: str = "wall") -> str:
    """The x axis' label: which clock, and of how many timed calls the fastest is drawn
    (``calls`` when the rows differ, e.g. a budget stopped some repeats early)."""
    counts = {int(r["repeats"]) for r in rows if r.get("repeats", 0) and r["status"] == "success"}
    calls = (f"{counts.pop()} calls" if len(counts) == 1 and min(counts, default=0) > 1 else
             "1 call" if counts == {1} else "the timed calls")
    slowest = CLOCK_COLUMNS[clock][1]
    spread = any(math.isfinite(r.get(slowest, math.nan)) for r in rows
                 if r["status"] == "success")
    return CLOCK_LABELS[clock].format(n=calls, bar=BAR_NOTE if spread else "").rstrip()

# One colour per method for up to a dozen methods (the house cycle, then four of Paul Tol's
# "muted" colours): with the cycle's eight, a ninth method took the first one's colour, and
# its failure crosses could not be told from the first's.
METHOD_COLOURS = ("C0", "C1", "C2", "C3", "C4", "C5", "C6", "C7",
                  "#332288", "#44AA99", "#882255", "#999933")
MARKERS = "os^vD<>ph*"
# The figure's size in inches: a column (panels stacked) or the text width (side by side).
WIDTHS = ("column", "text")
PANEL_HEIGHT = {"column": 2.0, "text": 2.9}


def panel_title(kind: str) -> str:
    """The name of an error axis' quantity and that it is absolute, for its panel's title."""
    return PANEL_TITLES.get(kind, kind)


def log_ticks(ax, axis: str = "x") -> None:
    """Ticks at 1, 2 and 5 of each decade (1 and 3 beyond 1.3 decades), each labelled, on a
    log axis whose data span less than two decades: a column-wide panel of one decade had a
    single labelled tick."""
    from matplotlib.ticker import LogFormatterSciNotation, LogLocator

    low, high = getattr(ax.dataLim, f"interval{axis}")
    if not (0 < low < high < 100 * low):
        return
    target = getattr(ax, f"{axis}axis")
    # 1, 2 and 5 of each decade over about a decade; 1 and 3 over two (six labels ran
    # together across a column's panel)
    subs = (1.0, 2.0, 5.0) if high < 20 * low else (1.0, 3.0)
    target.set_major_locator(LogLocator(subs=subs))
    # every tick labelled up to two decades (the formatter's default labels only the decades
    # from one decade up: a 1.2-decade CPU axis had two labels)
    target.set_major_formatter(LogFormatterSciNotation(labelOnlyBase=False,
                                                       minor_thresholds=(2, 2)))


def axis_label(kind: str, time_dependent: bool = False) -> str:
    """The label of an error axis: its formula (`panel_title` names it)."""
    if kind == "energy_error" and time_dependent:
        return TIME_DEPENDENT_ENERGY
    return AXIS_LABELS.get(kind, kind)


def plot_work_precision(rows, path, *, title, fmt: str = "png", width: str = "column",
                        time_dependent: bool = False, clock: str = "wall"):
    """Error against run time, one panel per error kind, one legend for both below them
    (never over the data): each method's successful runs as a line; a run that failed before
    ``t_end`` has no error to show (its partial run's error would flatter it) and is marked by
    a cross in its method's colour on the panel's top edge at its run time, named in the
    legend. ``width``: ``column`` (3.4 in, stacked panels) or ``text`` (7 in, side by
    side); ``clock``: ``wall`` or ``cpu``, the cost drawn (and ranked by, `WorkPrecision.best`).
    """
    if width not in WIDTHS:
        raise ValueError(f"width must be one of {', '.join(WIDTHS)}, got {width!r}")
    if clock not in CLOCK_COLUMNS:
        raise ValueError(f"clock must be one of {', '.join(CLOCK_COLUMNS)}, got {clock!r}")
    column = width == "column"
    methods = methods_of(rows)
    with figures.styled():
        labels = _legend_labels(rows, clock)
        # long entries (a target error's pilot note) one column fewer: two of them overran
        # the column's width
        ncol = (2 if column else 4) // (2 if max(map(len, labels), default=0)
                                        > LONG_LABEL else 1)
        legend_rows = math.ceil(len(labels) / ncol)
        height = (PANEL_HEIGHT[width] * (len(AXIS_LABELS) if column else 1)
                  + 0.35 + 0.16 * legend_rows)
        fig = figures.new_figure(figures.COLUMN_WIDTH if column else figures.TEXT_WIDTH,
                                 height)
        axes = fig.subplots(len(AXIS_LABELS), 1, sharex=True) if column else \
            fig.subplots(1, len(AXIS_LABELS))
        for ax, kind in zip(axes, AXIS_LABELS, strict=True):
            for i, method in enumerate(methods):
                plot_method(ax, rows, method, kind, i, clock=clock)
            ax.set_ylabel(axis_label(kind, time_dependent))
            ax.set_title(panel_title(kind), pad=7)  # clear of the failure crosses
            ax.grid(True, which="major")
            log_ticks(ax, "x")
        for ax in (axes[-1:] if column else axes):
            ax.set_xlabel(run_time_label(rows, clock))
        figure_legend(fig, axes, ncol=ncol)
        fig.suptitle(title)
        figures.save(fig, path, fmt)


def _legend_labels(rows, clock: str = "wall") -> list[str]:
    labels = []
    for method in methods_of(rows):
        mine = [r for r in rows if r["method"] == method]
        labels += [method_label(rows, method)] if any(r["status"] == "success"
                                                     for r in mine) else []
        labels += [f"{method} failed"] if any(r["status"] != "success" for r in mine) else []
    return labels + ([CPU_LABEL] if clock == "wall" and _cpu_measured(rows) else [])


CPU_LABEL = "open: CPU time of that call"


def method_label(rows, method) -> str:
    """A method's legend entry: its name, and for runs at target errors that their time
    includes the pilot run that chose the first step."""
    aims = any(r["method"] == method and r.get("knob") == "target_error" for r in rows)
    return f"{method} ({PILOT_NOTE})" if aims else method


def _cpu_measured(rows) -> bool:
    return any(r["status"] == "success" and math.isfinite(r.get("cpu_s", math.nan))
               for r in rows)


def figure_legend(fig, axes, ncol: int = 4) -> None:
    """One legend for the figure below its panels (outside every panel, so it covers no
    data), each entry once: the methods, then each method's failures."""
    entries = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            entries.setdefault(label, handle)
    if entries:
        labels = sorted(entries, key=lambda label: (label == CPU_LABEL, "failed" in label))
        fig.legend([entries[label] for label in labels], labels, loc="outside lower center",
                   ncol=min(ncol, len(labels)), fontsize="small")


def _spread(rows, clock: str = "wall") -> tuple[list[float], list[list[float]] | None]:
    """Where to draw each run (its fastest timed call, or that call's CPU time) and its bar
    (up to the slowest call), ``None`` where the slowest was not measured."""
    column, slowest = CLOCK_COLUMNS[clock]
    x = [r.get(column, math.nan) for r in rows]
    highest = [r.get(slowest, math.nan) for r in rows]
    if not all(math.isfinite(h) for h in highest):
        return x, None
    return x, [[0.0] * len(x), [max(h - v, 0.0) for h, v in zip(highest, x, strict=True)]]


def plot_method(ax, rows, method, kind, index, *, clock: str = "wall"):
    """One method on one panel: its successful runs as a line at the cost the rankings read
    (``clock``) with a bar to the slowest call (drawn by wall time, each run's CPU time as an
    open marker), its failures as crosses in its colour on the top edge (x: run time; y: the
    axes' top, not an error), named ``METHOD failed`` in the legend."""
    column = CLOCK_COLUMNS[clock][0]
    good = [r for r in rows if r["method"] == method and r["status"] == "success"
            and r[kind] > 0 and math.isfinite(r.get(column, math.nan))]
    failed = [r for r in rows if r["method"] == method and r["status"] != "success"
              and r.get(column, math.nan) > 0]
    colour = METHOD_COLOURS[index % len(METHOD_COLOURS)]
    if good:
        x, bars = _spread(good, clock)
        errors = [r[kind] for r in good]
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.errorbar(x, errors, xerr=bars, marker=MARKERS[index % len(MARKERS)],
                    label=method_label(rows, method), color=colour, elinewidth=0.6, capsize=0)
        cpu = [r.get("cpu_s", math.nan) for r in good]
        if clock == "wall" and any(math.isfinite(c) for c in cpu):
            ax.plot(cpu, errors, **CPU_MARKER, color=colour)
            ax.plot([], [], **CPU_MARKER, color="0.3", label=CPU_LABEL)
    if failed:
        ax.set_xscale("log")
        ax.plot([r[column] for r in failed], [1.0] * len(failed),
                **{**figures.FAILED, "color": colour}, transform=ax.get_xaxis_transform(),
                clip_on=False, label=f"{method} failed before $t_{{end}}$")


def methods_of(rows) -> list[str]:
    """The methods of the rows, in the order they first appear."""
    return list(dict.fromkeys(r["method"] for r in rows))
