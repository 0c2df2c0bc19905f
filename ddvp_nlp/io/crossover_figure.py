"""The crossover figure of ``compare(..., horizons=...)`` (``crossover.png``): for each error
level, which method is cheapest to reach it along the horizon ``T``, one panel per error kind,
stacked for a journal's column. Each level is a band coloured by its cheapest method; a short
black bar marks each crossover (the horizon from which another method is cheapest), dotted
lines the horizons measured (between them the costs are interpolated in ``log T``; the rule is
``studies/horizons_choice.py``'s)."""

from __future__ import annotations

from . import figures
from .work_precision_figure import METHOD_COLOURS, axis_label, panel_title

NONE_COLOUR = "#DDDDDD"
COST_LABELS = {"run_s": "wall time, best of repeats", "cpu_s": "CPU time of the best call",
               "steps": "steps"}
BAND_WIDTH = 5.0  # points
PANEL_HEIGHT = 1.75  # inches


def plot_crossover(maps: dict, methods: list[str], horizons: list[float], path, *,
                   title: str, unit: float = 1.0, cost: str = "run_s",
                   time_dependent: bool = False, fmt: str = "png") -> None:
    """``maps``: ``{kind: [(error, [(horizon, winner or None), ...]), ...]}`` (the winners of
    `HorizonComparison.winners`); ``methods`` fixes each method's colour (as in the
    work-precision figures)."""
    kinds = [kind for kind, levels in maps.items() if levels] or list(maps)[:1]
    with figures.styled():
        fig = figures.new_figure(figures.COLUMN_WIDTH, PANEL_HEIGHT * len(kinds) + 0.9)
        axes = fig.subplots(len(kinds), 1, sharex=True, squeeze=False)[:, 0]
        shown = set()
        for ax, kind in zip(axes, kinds, strict=True):
            shown |= _panel(ax, maps[kind], methods, horizons)
            ax.set_ylabel(axis_label(kind, time_dependent))
            ax.set_title(panel_title(kind))
        axes[-1].set_xlabel("horizon $T$" + (f" [x {unit:.4g}]" if unit != 1 else
                                            " (time units)"))
        _legend(fig, methods, shown)
        fig.suptitle(f"{title}\n(cost: {COST_LABELS.get(cost, cost)})")
        figures.save(fig, path, fmt)


def _panel(ax, levels, methods, horizons) -> set:
    """The bands of one error kind; returns the winners drawn (``None`` for no method)."""
    ax.set_xscale("log")
    ax.set_yscale("log")
    if levels:  # the limits first: a single level autoscaled to an empty interval
        errors = [e for e, _ in levels]
        ax.set_ylim(min(errors) / 3, max(errors) * 3)
    shown = set()
    for error, winners in levels:
        runs = _runs(winners)
        for index, (start, end, method) in enumerate(runs):
            colour = NONE_COLOUR if method is None else \
                METHOD_COLOURS[methods.index(method) % len(METHOD_COLOURS)]
            ax.hlines(error, start, end, colors=colour, linewidth=BAND_WIDTH,
                      capstyle="butt")
            shown.add(method)
            if index:
                ax.plot([start], [error], marker="|", color="black", markersize=BAND_WIDTH + 3,
                        markeredgewidth=1.0, linestyle="none")
    for horizon in horizons:
        ax.axvline(horizon, color="0.5", linewidth=0.5, linestyle=":")
    ax.set_xlim(min(horizons) / 1.3, max(horizons) * 1.3)
    ax.minorticks_off()
    return shown


def _runs(winners) -> list[tuple[float, float, str | None]]:
    """``(from, to, method)`` for each stretch of horizons with one cheapest method."""
    runs = []
    for horizon, method in winners:
        if runs and runs[-1][2] == method:
            runs[-1][1] = horizon
        elif runs:
            runs[-1][1] = horizon
            runs.append([horizon, horizon, method])
        else:
            runs.append([horizon, horizon, method])
    return [tuple(run) for run in runs]


def _legend(fig, methods, shown) -> None:
    from matplotlib.lines import Line2D

    entries = [(Line2D([], [], color=METHOD_COLOURS[i % len(METHOD_COLOURS)],
                       linewidth=BAND_WIDTH), m) for i, m in enumerate(methods) if m in shown]
    if None in shown:
        entries.append((Line2D([], [], color=NONE_COLOUR, linewidth=BAND_WIDTH),
                        "none reaches it"))
    entries.append((Line2D([], [], color="black", marker="|", linestyle="none",
                           markersize=BAND_WIDTH + 3), "crossover"))
    fig.legend([e[0] for e in entries], [e[1] for e in entries], loc="outside lower center",
               ncol=3, fontsize="small")
