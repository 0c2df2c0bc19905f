"""The work-precision figure draws the cost the rankings read (issue: the x axis was the median
wall time while ``summary.md`` and ``best`` ranked by the best of up to 3 calls); the CPU time
of the same call is shown, or drawn instead; a target-error run says its time includes its
pilot."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ddvp_nlp.io import figures
from ddvp_nlp.io.work_precision_figure import plot_work_precision


def kept(draw):
    target = figures.Keep()
    draw(target)
    return target.figure


def rows():
    """Two methods, three calls each; the machine loaded (wall twice CPU); vddvp at target
    errors, its coarser target costlier (its pilot)."""
    found = []
    for method, knob, values in (("vddvp", "target_error", (1e-2, 1e-3)),
                                 ("rk4", "tau", (0.02, 0.01, 0.005))):
        for i, value in enumerate(values):
            best = 0.01 * (i + 1) * (2 if method == "vddvp" and i == 0 else 1)
            found.append({"method": method, "knob": knob, "value": value, "status": "success",
                          "repeats": 3, "run_s": best, "run_s_median": 3 * best,
                          "run_s_max": 10 * best, "cpu_s": best / 2, "cpu_s_median": best / 2,
                          "cpu_s_max": best, "trajectory_error": value,
                          "energy_error": value ** 2})
    return found


def main_lines(fig):
    """``(label, line)`` of each method's line (an errorbar container's data line)."""
    return [(container.get_label(), container.lines[0]) for ax in fig.axes
            for container in ax.containers]


@pytest.mark.parametrize(("clock", "column"), [("wall", "run_s"), ("cpu", "cpu_s")])
def test_the_runs_are_drawn_at_the_cost_the_ranking_reads_and_the_axis_says_so(clock, column):
    data = rows()
    fig = kept(lambda target: plot_work_precision(data, target, title="t", clock=clock))
    assert len(main_lines(fig)) == 4
    for method, line in main_lines(fig):
        expected = [r[column] for r in data if method.startswith(r["method"])]
        assert list(line.get_xdata()) == pytest.approx(expected)
    label = fig.axes[-1].get_xlabel()
    assert ("wall" if clock == "wall" else "CPU") in label and "best of 3 calls" in label
    assert "median" not in label
    # the bars start at the drawn point and reach the slowest call, never below the best
    for ax in fig.axes:
        for collection in ax.collections:
            for segment in collection.get_segments():
                low, high = sorted(segment[:, 0])
                row = next(r for r in data if r[column] == pytest.approx(low))
                assert high == pytest.approx(row[f"{column}_max"])


def test_a_wall_figure_shows_each_runs_cpu_time_and_target_runs_include_their_pilot():
    data = rows()
    fig = kept(lambda target: plot_work_precision(data, target, title="t"))
    (legend,) = fig.legends
    texts = [t.get_text() for t in legend.get_texts()]
    assert any(t.startswith("vddvp") and "pilot" in t for t in texts)
    assert "rk4" in texts and not any(t.startswith("rk4") and "pilot" in t for t in texts)
    assert any("CPU" in t for t in texts)
    ax = fig.axes[0]
    open_markers = [line for line in ax.lines if line.get_linestyle() in ("None", "none")
                    and line.get_xdata().size and line.get_markerfacecolor() == "none"]
    shown = sorted(x for line in open_markers for x in line.get_xdata())
    assert shown == pytest.approx(sorted(r["cpu_s"] for r in data))


def test_rows_without_cpu_or_spread_draw_without_them_and_a_bad_clock_is_refused():
    data = [{**r, "cpu_s": math.nan, "run_s_max": math.nan} for r in rows()]
    fig = kept(lambda target: plot_work_precision(data, target, title="t"))
    assert not any("CPU" in t.get_text() for t in fig.legends[0].get_texts())
    assert not any(c.get_segments() for ax in fig.axes for c in ax.collections)
    with pytest.raises(ValueError, match="clock must be one of wall, cpu, got 'gpu'"):
        plot_work_precision(data, figures.Keep(), title="t", clock="gpu")


def test_best_ranks_by_the_clock_it_is_given():
    from types import SimpleNamespace as NS

    from ddvp_nlp.errors import InputError
    from ddvp_nlp.studies.work_precision import WorkPrecision

    data = rows()
    data[3]["cpu_s"] = 1e-6  # rk4's first run: slowest by wall than vddvp's, cheapest in CPU
    data[3]["run_s"] = 1.0
    result = WorkPrecision(data, NS(name="s"), None, None, [], None, 3, 3.0)
    assert result.best(0.05)["run_s"] == pytest.approx(np.min([r["run_s"] for r in data]))
    assert result.best(0.05, clock="cpu") is data[3]
    with pytest.raises(InputError, match="clock must be one of wall, cpu, got 'x'"):
        result.best(0.05, clock="x")
