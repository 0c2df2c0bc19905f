"""The figures of ``ddvp compare --horizons``: work-precision at each horizon
(``horizons.png``) and the growth of each method's error with time (``growth.png``)."""

from __future__ import annotations

import math

from . import figures
from .work_precision_figure import (
    AXIS_LABELS,
    axis_label,
    figure_legend,
    log_ticks,
    methods_of,
    plot_method,
)

# Each row's quantity, above its formula on the first column's axis.
SHORT_NAMES = {"trajectory_error": "trajectory error (absolute)",
               "energy_error": "energy error (absolute)"}


def plot_horizons(results: dict, path, *, title: str, unit: float,
                  time_dependent: bool = False, fmt: str = "png") -> None:
    """A column per horizon, a row per error kind, every method's runs as in the single
    report (each at the fastest of its timed calls, the cost the rankings read, a bar to the
    slowest, an open marker at its CPU time)."""
    with figures.styled():
        fig = figures.new_figure(min(figures.TEXT_WIDTH, 2.1 * len(results) + 1.0), 5.2)
        axes = fig.subplots(len(AXIS_LABELS), len(results), squeeze=False, sharey="row")
        _horizon_panels(axes, results, unit, time_dependent)
        figure_legend(fig, axes.ravel())
        fig.suptitle(f"{title}\n{_time_note(results)}")
        figures.save(fig, path, fmt)


def _time_note(results: dict) -> str:
    """What the panels' run time is: the best timed call (as the rankings read it), with
    what the rows measured beside it (the slowest call's bar, the CPU time's open marker)."""
    rows = [r for found in results.values() for r in found if r["status"] == "success"]
    extras = [text for column, text in (("run_s_max", "bar: to the worst"),
                                        ("cpu_s", "open: its CPU time"))
              if any(math.isfinite(r.get(column, math.nan)) for r in rows)]
    return f"(errors absolute; run time: the best call{'; ' if extras else ''}" \
        f"{'; '.join(extras)})"


def _horizon_panels(axes, results: dict, unit: float, time_dependent: bool = False) -> None:
    kinds = list(AXIS_LABELS)
    names = list(dict.fromkeys(m for rows in results.values() for m in methods_of(rows)))
    for column, (horizon, rows) in enumerate(results.items()):
        for row_index, kind in enumerate(kinds):
            ax = axes[row_index][column]
            for method in methods_of(rows):
                plot_method(ax, rows, method, kind, names.index(method))
            if row_index == 0:
                ax.set_title(f"$T = {horizon:g}$" + (rf"$\,\times\,{unit:.4g}$"
                                                     if unit != 1 else ""),
                             pad=7)  # clear of the failure crosses on the top edge
            log_ticks(ax, "x")
            ax.set_xlabel("wall time [s]" if row_index == len(kinds) - 1 else "")
            ax.set_ylabel(f"{SHORT_NAMES[kind]}\n{axis_label(kind, time_dependent)}"
                          if column == 0 else "")
            ax.grid(True, which="major")


def plot_growth(growth, path, *, title: str) -> None:
    """Energy and trajectory error against ``t - t0``, log-log, one line per method."""
    with figures.styled():
        fig = figures.new_figure(figures.TEXT_WIDTH, 3.2)
        axes = fig.subplots(1, 2)
        for ax, kind in zip(axes, ("energy_error", "trajectory_error"), strict=True):
            for item in growth:
                ax.loglog(item.t, figures.positive(getattr(item, kind)),
                          label=f"{item.method} ({item.knob} = {item.value:.3g})")
            ax.set_xlabel("$t - t_0$")
            ax.set_ylabel(r"$|H(z_k) - H(z_0)|$ (absolute)" if kind == "energy_error" else
                          r"$\max |z_k - z_{\mathrm{ref}}|$ (absolute)")
            ax.grid(True, which="major")
            ax.legend(loc="upper left", fontsize="small")
        fig.suptitle(title)
        figures.save(fig, path)
