"""The run figure as a paper needs it: exact zeros on a log panel at a bottom tick labelled 0
(they were gaps, though the guide promised the tick); a thinned run's samples readable when
they outnumber the pixels (they were a block of overlapping dots); no state panel squeezed
into a strip (a cart pendulum's configuration); the second column's axis named as the first
where it carries an offset (it read ``value / 10⁻³``)."""

from __future__ import annotations

from types import SimpleNamespace as NS

import numpy as np
import pytest

from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.io import figures
from ddvp_nlp.io.run_figure import SAMPLE_DOT, plot_trajectory
from ddvp_nlp.solution import MarchRecord, Solution, Status


def solution(t, q, p, tau=None):
    t = np.asarray(t, dtype=float)
    return Solution(t=t, q=np.asarray(q, dtype=float).reshape(t.size, -1),
                    p=np.asarray(p, dtype=float).reshape(t.size, -1), status=Status.SUCCESS,
                    message="", scheme="vddvp", energy_residual=np.zeros(t.size - 2),
                    canonical_residual=np.zeros(t.size - 1), verdict=None)


def figure(run, energies):
    target = figures.Keep()
    scene = NS(name="test", system=NS(time_dependent=False))
    plot_trajectory(run, scene, Scheme(), target, energies=energies)
    return target.figure


def energy_panel(fig):
    return next(ax for ax in fig.axes if ax.get_yscale() == "log")


def test_exact_zeros_on_a_log_panel_sit_on_a_tick_labelled_0_not_in_gaps():
    t = np.linspace(0.0, 10.0, 200)
    h = 1.0 + np.where(np.arange(200) % 3 == 0, 0.0, 1e-13 * (1 + np.sin(t)))
    fig = figure(solution(t, np.cos(t), -np.sin(t)), (h, None))
    ax = energy_panel(fig)
    (line,) = [line for line in ax.lines if line.get_xdata().size == 200]
    y = np.asarray(line.get_ydata(), dtype=float)
    assert np.isfinite(y[1:]).all()  # no gaps (the first node's drift is zero by definition)
    floor = np.nanmin(y)
    assert ax.get_ylim()[0] == pytest.approx(floor)
    assert floor < 1e-13 * 0.5  # below every nonzero error, a decade down
    ticks = dict(zip(ax.get_yticks(), [t.get_text() for t in ax.get_yticklabels()],
                     strict=True))
    assert any(abs(loc - floor) < 1e-9 * floor and text == "0" for loc, text in ticks.items())
    assert list(ticks.values()).count("0") == 1


def test_the_first_nodes_drift_zero_by_definition_is_not_drawn_as_an_exact_zero():
    t = np.linspace(0.0, 10.0, 200)
    h = 1.0 + 1e-9 * np.sin(t)  # |H - H0| is 0 at t0 only, as for every run
    fig = figure(solution(t, np.cos(t), -np.sin(t)), (h, None))
    labels = [t.get_text() for t in energy_panel(fig).get_yticklabels()]
    assert "0" not in labels


def thinned(nodes):
    t = np.linspace(0.0, 3000.0, nodes)
    run = solution(t, np.column_stack([np.cos(t), np.sin(t)]),
                   np.column_stack([-np.sin(t), np.cos(t)]))
    run.march = MarchRecord(theta=[], kept={
        "keep_every": 100, "keep": "nodes", "nodes_marched": 100 * nodes, "nodes_kept": nodes,
        "windows": 3, "tau_min": 0.0099, "tau_max": 0.0105, "canonical_residual_max": 0.0,
        "energy_residual_max": 0.0})
    return run


def test_a_thinned_run_denser_than_the_pixels_draws_its_samples_envelope_not_a_block():
    run = thinned(3000)
    fig = figure(run, (1.0 + 1e-7 * np.sin(run.t), None))
    q_panel = fig.axes[0]
    assert q_panel.collections  # the samples' min-max band
    assert not [line for line in q_panel.lines if line.get_marker() == "."]
    titles = [ax.get_title() for ax in fig.axes]
    assert "phase portrait, kept nodes" in titles


def test_a_sparse_thinned_run_draws_small_dots():
    run = thinned(300)
    fig = figure(run, (1.0 + 1e-7 * np.sin(run.t), None))
    dots = [line for line in fig.axes[0].lines if line.get_marker() == "."]
    assert len(dots) == 2 and all(d.get_markersize() <= SAMPLE_DOT for d in dots)


def test_a_configuration_of_unequal_ranges_keeps_a_square_box_at_equal_aspect():
    t = np.linspace(0.0, 20.0, 1500)
    q = np.column_stack([0.22 * np.sin(3 * t), 0.5 * np.cos(2 * t), -0.9 + 0.05 * np.cos(t)])
    fig = figure(solution(t, q, np.gradient(q, axis=0)), (np.ones(1500), None))
    configuration = next(ax for ax in fig.axes if ax.get_title() == "configuration")
    assert configuration.get_aspect() == 1.0
    box = configuration.get_position()
    width, height = box.width * fig.get_figwidth(), box.height * fig.get_figheight()
    assert 0.8 < width / height < 1.25  # not a strip
    x0, x1 = configuration.get_xlim()
    y0, y1 = configuration.get_ylim()
    assert (x1 - x0) / (y1 - y0) == pytest.approx(width / height, rel=0.02)  # equal aspect


def test_the_second_columns_step_axis_is_named_as_the_first_when_it_carries_an_offset():
    nodes = 6000  # a zoom column: the first 300 steps, nearly constant
    tau = 0.01 * (1 + 0.05 * np.linspace(0.0, 1.0, nodes - 1) ** 3)
    t = np.concatenate([[0.0], np.cumsum(tau)])
    fig = figure(solution(t, np.cos(t), -np.sin(t)), (1.0 + 1e-9 * np.sin(t), None))
    whole, zoom = [ax for ax in fig.axes if "step" in ax.get_ylabel()]
    assert zoom.yaxis.label.get_visible() and whole.get_ylabel() in zoom.get_ylabel()
    assert "/" in zoom.get_ylabel() or "\N{MINUS SIGN}" in zoom.get_ylabel()
    others = [ax for ax in fig.axes if ax.yaxis.get_label_position() == "right"]
    assert len(others) == 4 and sum(ax.yaxis.label.get_visible() for ax in others) == 1
