"""Every figure type drawn on a constant-step (or constant-period) case and on a failed one, and
checked on what a referee looks at (issue 40): no text over a title, the verdict in the run
figure's title, legends inside the figure and off the data, failure markers coloured as their
legend entries, category ticks on a sweep's axes, no empty panel. Synthetic data: nothing is
solved."""

from __future__ import annotations

from types import SimpleNamespace as NS

import numpy as np
import pytest

from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.io import figures
from ddvp_nlp.io.orbit_figures import plot_followed_family
from ddvp_nlp.io.orbit_files import plot_family, plot_orbit
from ddvp_nlp.io.run_figure import plot_trajectory
from ddvp_nlp.io.section_files import plot_section
from ddvp_nlp.io.stress_figure import plot_stress
from ddvp_nlp.io.work_precision_figure import plot_work_precision
from ddvp_nlp.solution import Solution, Status, Verdict


def run(status=Status.SUCCESS, verdict="drifted", nodes=400):
    """A harmonic run of constant steps (round-off in their last bits)."""
    rng = np.random.default_rng(0)
    t = np.concatenate([[0.0], np.cumsum(0.05 + 1e-17 * rng.standard_normal(nodes - 1))])
    return Solution(t=t, q=np.cos(t)[:, None], p=-np.sin(t)[:, None], status=status,
                    message="", scheme="vddvp", energy_residual=np.zeros(nodes - 2),
                    canonical_residual=np.zeros(nodes - 1),
                    verdict=None if verdict is None else Verdict(
                        name=verdict, first_failure=None, t_drift=3.0, drift_step=None,
                        error_max=0.0, error_max_t=None, estimate="", reference_until=None,
                        reference_error=None, reference_lost=None, scale=None,
                        energy_scale=None, local_error_max=0.0, level=None,
                        level_reference=None, level_error=None, energy_drift=None,
                        steps=nodes - 1, rtol=1e-2, atol=None, energy_tol=0.1,
                        global_tol=1e-2, require_accurate=False))


def kept(draw) -> object:
    target = figures.Keep()
    draw(target)
    return target.figure


def run_figure(solution, **options):
    scene = NS(name="harmonic", system=NS(time_dependent=False))
    h = 0.5 + 1e-6 * np.sin(solution.t)
    return kept(lambda target: plot_trajectory(solution, scene, Scheme(), target,
                                               energies=(h, h[:-1]), **options))


def check(fig) -> None:
    """What every figure keeps: no visible text over a title, legends inside the figure and
    off their panel's data, no empty panel."""
    renderer = fig.canvas.get_renderer()
    titles = [ax.title for ax in fig.axes if ax.get_title()]
    if fig._suptitle is not None:
        titles.append(fig._suptitle)
    texts = [text for ax in fig.axes for text in
             (*ax.texts, ax.xaxis.get_offset_text(), ax.yaxis.get_offset_text(),
              ax.xaxis.label, ax.yaxis.label)]
    texts += [text for legend in [*fig.legends, *(ax.get_legend() for ax in fig.axes)]
              if legend for text in legend.get_texts()]
    for title in titles:
        box = title.get_window_extent(renderer)
        for text in texts:
            if text is not title and text.get_visible() and text.get_text():
                assert not box.overlaps(text.get_window_extent(renderer)), (
                    title.get_text(), text.get_text())
    whole = fig.bbox
    for ax in fig.axes:
        assert ax.lines or ax.collections or ax.images or ax.patches, ax.get_title()
        legend = ax.get_legend()
        if legend is None:
            continue
        box = legend.get_window_extent(renderer)
        assert whole.x0 <= box.x0 and box.x1 <= whole.x1 and whole.y0 <= box.y0 <= whole.y1
        for line in ax.lines:  # off the data (a line's own points)
            if line.get_transform() == ax.transData and line.get_xdata().size:
                xy = line.get_transform().transform(line.get_xydata())
                xy = xy[np.isfinite(xy).all(axis=1)]
                inside = ((box.x0 < xy[:, 0]) & (xy[:, 0] < box.x1) & (box.y0 < xy[:, 1])
                          & (xy[:, 1] < box.y1))
                assert not inside.any(), (ax.get_ylabel(), line.get_label())
    for legend in fig.legends:
        box = legend.get_window_extent(renderer)
        assert whole.contains(box.x0, box.y0) and whole.contains(box.x1, box.y1)
        for ax in fig.axes:
            assert not box.overlaps(ax.get_window_extent(renderer))


def constant_axis(ax, axis="y") -> None:
    """Data constant to round-off shown as a constant: a range of about its size, no
    offset."""
    low, high = ax.get_ylim() if axis == "y" else ax.get_xlim()
    assert high - low > 1e-3 * max(abs(low), abs(high))
    assert not ax.yaxis.get_offset_text().get_visible() or not \
        ax.yaxis.get_offset_text().get_text()


@pytest.mark.parametrize(("status", "verdict", "said"), [
    (Status.SUCCESS, "drifted", "drifted from"), (Status.SUCCESS, "accurate", "accurate"),
    (Status.INACCURATE, "inaccurate", "inaccurate"),
    (Status.NEWTON_FAILED, None, "failed: newton_failed")])
def test_the_run_figure_says_its_verdict_and_draws_constant_steps_as_constant(
        status, verdict, said):
    fig = run_figure(run(status, verdict))
    check(fig)
    title = fig._suptitle.get_text()
    assert said in title and (status is not Status.SUCCESS or "success" not in title)
    constant_axis(next(ax for ax in fig.axes if "τ" in ax.get_ylabel()))
    # every label of the run figure is plain text (figures.unicode_labels): no mathtext
    labels = [title, *(text.get_text() for ax in fig.axes for text in
                       (ax.xaxis.label, ax.yaxis.label, ax.title, *ax.texts))]
    assert not any("$" in label for label in labels), labels


def test_a_fixed_end_run_marks_both_ends_and_claims_no_fixed_momentum():
    """q is prescribed at the ends, p is solved for: the squares (the legend's "fixed ends")
    mark q only; the phase plane's ends are plain dots (a user read its squares as fixed p)."""
    fig = run_figure(run(verdict="accurate"), fixed_ends=True)
    check(fig)
    q = next(ax for ax in fig.axes if ax.get_ylabel() == figures.unicode_math("$q$"))
    phase = next(ax for ax in fig.axes if ax.get_title() == "phase portrait")
    (ends,) = [line for line in q.lines if line.get_marker() == "s"]
    assert ends.get_xdata().size == 2
    assert "fixed ends" in [t.get_text() for t in q.get_legend().get_texts()]
    assert not [line for line in phase.lines if line.get_marker() == "s"]
    (dots,) = [line for line in phase.lines if line.get_marker() == "o"]
    assert dots.get_xdata().size == 2
    assert [t.get_text() for t in phase.texts] == ["start", "end"]
    p = next(ax for ax in fig.axes if ax.get_ylabel() == figures.unicode_math("$p$"))
    assert not [line for line in p.lines if line.get_marker() == "s"]


@pytest.mark.slow_when(lambda success, **_: success, why="repetition")
@pytest.mark.parametrize("success", [True, False])
def test_an_orbit_and_a_family_of_constant_steps_and_periods(success):
    solution = run(Status.SUCCESS if success else Status.SOLVER_FAILED)
    fig = kept(lambda target: plot_orbit(solution, "harmonic", target))
    check(fig)
    constant_axis(fig.axes[1])
    rows = [{"energy": e, "period": 2 * np.pi * (1 + 1e-15 * k), "nodes": 201,
             "status": "success" if success or k else "max_iterations"}
            for k, e in enumerate([0.2, 0.4, 0.6, 0.8])]
    fig = kept(lambda target: plot_family(rows, "harmonic", target,
                                          reference=lambda e: np.full_like(e, 2.01 * np.pi)))
    check(fig)
    constant_axis(fig.axes[1])


def test_a_family_without_nontrivial_multipliers_draws_its_trivial_pair():
    solution = run()
    members = [NS(energy=e, orbit=NS(q=solution.q, p=solution.p, steps=200,
                                     orbit=NS(period=2 * np.pi)),
                  stability=NS(verdict="stable", indices=np.zeros(0),
                               trivial=np.array([1.0, 1.0])))
               for e in (0.5, 0.7, 0.9)]
    family = NS(members=members, bifurcations=[])
    fig = kept(lambda target: plot_followed_family(family, "harmonic", target))
    check(fig)
    indices = fig.axes[2]
    assert indices.get_xlim() == fig.axes[1].get_xlim()
    assert any(len(line.get_xdata()) == 6 for line in indices.lines)  # 3 members x 2


def test_work_precision_failures_are_coloured_as_their_legend():
    rows = [{"method": m, "status": s, "run_s": r, "trajectory_error": e, "energy_error": e}
            for m, s, r, e in [("vddvp", "success", 0.01, 1e-3), ("vddvp", "success", 0.1, 1e-5),
                               ("rk4", "success", 0.02, 1e-4), ("rk4", "non_finite", 0.005, 0.0),
                               ("lee_left", "non_finite", 0.003, 0.0)]]
    fig = kept(lambda target: plot_work_precision(rows, target, title="kepler"))
    check(fig)
    (legend,) = fig.legends
    colours = {text.get_text(): handle.get_color()
               for text, handle in zip(legend.get_texts(), legend.legend_handles, strict=True)}
    for ax in fig.axes:
        crosses = [line for line in ax.lines if line.get_marker() == "x"]
        assert len(crosses) == 2
        for line in crosses:
            assert colours[line.get_label()] == line.get_color()


def test_a_sweep_map_has_category_ticks_and_failed_cells_red():
    cases = [NS(group="sweep", name=f"tau0={t}, e={e}") for e in (0.1, 0.9)
             for t in (0.01, 0.1, 2.0)]

    def row(case, method):
        if method == "rk4" and "tau0=2.0" in case.name:
            return {"status": "non_finite", "energy_error": float("nan")}
        return {"status": "success", "energy_error": 1e-8 * (1 + cases.index(case))}

    result = NS(cases=cases, methods=["vddvp", "rk4"], row=row)
    fig = kept(lambda target: plot_stress(result, target, cells=None, title="sweep"))
    check(fig)
    rk4 = next(ax for ax in fig.axes if ax.get_title() == "rk4")
    assert list(rk4.get_xticks()) == [0, 1, 2]
    assert [t.get_text() for t in rk4.get_xticklabels()] == ["0.01", "0.1", "2"]
    assert [t.get_text() for t in fig.axes[0].get_yticklabels()] == ["0.1", "0.9"]
    red = [p for p in rk4.patches if p.get_facecolor()[:3] == pytest.approx((0.8, 0.2, 0.067),
                                                                            abs=0.01)]
    assert len(red) == 2 and "failed" in fig.legends[0].get_texts()[0].get_text()


def test_a_section_has_visible_dots_and_its_energy_boundary():
    angle = np.linspace(0, 2 * np.pi, 60)
    points = np.column_stack([0 * angle, 0.3 * np.cos(angle), 0 * angle, 0.3 * np.sin(angle)])
    x = y = np.linspace(-1, 1, 81)
    X, Y = np.meshgrid(x, y)
    section = NS(points=points, orbit=np.zeros(60, dtype=int), starts=points[:2],
                 statuses=["success", "newton_failed"], section="q1=0", direction="+",
                 energy=0.125, boundary=(x, y, 0.25 - X ** 2 - Y ** 2))
    fig = kept(lambda target: plot_section(section, target))
    check(fig)
    (ax,) = fig.axes
    assert ax.lines[0].get_markersize() >= 1.5 and ax.collections  # the boundary's contour
    assert ax.get_xlim()[1] < 0.6  # limits of the curve, not of the contour's grid


def test_a_thinned_march_figure_counts_its_steps_and_draws_samples_not_a_path():
    """A ``--keep-every`` march's figure counted kept nodes as steps and plotted the kept
    nodes' spacing (4.3) as the step length (really 0.035-0.05) (issue 45): its title gives the
    steps marched, the nodes kept and the steps' range, it has no step row, and the kept nodes
    are dots."""
    from ddvp_nlp.solution import MarchRecord

    solution = run(nodes=22)
    solution.march = MarchRecord(theta=[], kept={
        "keep_every": 100, "keep": "nodes", "nodes_marched": 2013, "nodes_kept": 22,
        "windows": 3, "tau_min": 0.0484, "tau_max": 0.0505, "canonical_residual_max": 0.0,
        "energy_residual_max": 0.0})
    fig = run_figure(solution)
    title = fig._suptitle.get_text()
    assert "2012 steps (22 nodes kept, tau in [0.0484, 0.0505])" in title
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert not any("tau" in label for label in labels)
    lines = [line for ax in fig.axes for line in ax.get_lines() if line.get_xdata().size > 2]
    assert lines and all(line.get_linestyle() in ("None", "none", "") for line in lines)
    check(fig)


@pytest.mark.parametrize("values", [[-1.9, 0.5, 32.7], [-2500.0, -30.0, 1.2, 1970.0]])
def test_a_log_index_axis_labels_the_stability_bounds_and_every_decade_it_shows(values):
    """The symmetric log scale had labelled 1 and 0 and left the negative side bare."""
    import matplotlib.pyplot as plt

    from ddvp_nlp.io import orbit_figures

    fig, axes = plt.subplots()
    data = np.array(values)
    orbit_figures.index_limits(axes, [data], float(np.max(np.abs(data))))
    low, high = axes.get_ylim()
    ticks = axes.get_yticks()
    labels = [label.get_text() for label in axes.get_yticklabels()]
    plt.close(fig)
    assert {-2.0, 0.0, 2.0} <= set(ticks) and all(labels)
    assert all(low <= t <= high for t in ticks)
    for sign, reach in ((1, high), (-1, -low)):  # every decade inside the limits, no other
        decades = {t for t in ticks if sign * t >= 10}
        assert len(decades) == (int(np.floor(np.log10(reach))) if reach >= 10 else 0)
