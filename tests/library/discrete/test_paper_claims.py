"""The paper's claims, measured at sizes that fit CI (issue 5, items 1-4)."""

import numpy as np
import pytest

from ddvp_nlp import load_scene
from ddvp_nlp.cli import main
from ddvp_nlp.studies import paper_claims as paper
from ddvp_nlp.studies.reproduce import report as reproduce_report


@pytest.fixture(scope="module")
def example():
    return paper.paper_example(t_end=2000.0)


def test_step_length_periods_and_extremes(example):
    """Section 5: the step length's long period is the perturbation's 2 pi/0.02; its short one is
    half the pendulum's (a minimum at each passage through theta = 0); the smallest steps fall
    near theta = 0 and the largest near the turning points."""
    assert abs(example["long_period"] / (2 * np.pi / 0.02) - 1) < 0.02
    assert abs(example["short_period"] / example["pendulum_period"] - 0.5) < 0.05
    assert example["extremes"]["at_smallest_steps"] < 0.3
    assert example["extremes"]["at_largest_steps"] > 0.8
    assert example["extremes"]["minima"] >= 4 and example["extremes"]["maxima"] >= 4


def test_the_spacing_of_the_minima_is_the_period_where_the_spectrum_has_no_single_line():
    """A fast oscillation phase-modulated by a slow one at the first zero of J0: its carrier
    line vanishes and the strongest line of its spectrum is a sideband, while its minima keep
    the fast period (the step length of section 5 is such a signal)."""
    t = np.sort(np.random.default_rng(2).uniform(0, 10000, 40000))
    values = np.sin(2 * np.pi * t / 3.3 + 2.405 * np.sin(2 * np.pi * t / 314.0))
    spacing, count = paper.minima_spacing(t, values)
    assert abs(spacing / 3.3 - 1) < 1e-3 and abs(count - 10000 / 3.3) <= 2
    assert abs(paper.dominant_period(t, values, shorter_than=50) / 3.3 - 1) > 5e-3


def test_dominant_period_of_a_known_signal():
    t = np.sort(np.random.default_rng(1).uniform(0, 1000, 5000))
    values = np.sin(2 * np.pi * t / 97.0) + 0.3 * np.sin(2 * np.pi * t / 3.1)
    assert abs(paper.dominant_period(t, values, longer_than=20) - 97.0) < 0.5
    assert abs(paper.dominant_period(t, values, shorter_than=20) - 3.1) < 0.01


@pytest.mark.slow_when(lambda q0, **_: q0 == [1.0], why="study")
@pytest.mark.parametrize("system, q0, p0", [(load_scene("pendulum").system, [0.5], [0.5]),
                                            (paper.quartic_system(), [1.0], [0.0])])
def test_site_density_is_constant_up_to_order_tau(system, q0, p0):
    data = paper.site_density_spread(system, q0, p0, (0.05, 0.025, 0.0125), t_end=10.0)
    assert 0.9 < data["slope_node"] < 1.1
    assert 1.8 < data["slope_midpoint"] < 2.2
    # the steps themselves do not settle: their spread stays put while the product's shrinks
    assert min(data["tau_spread"]) > 10 * max(data["node"])


@pytest.mark.slow(why="study")
def test_gauge_term():
    data = paper.gauge_differences(t_end=50.0)
    assert data["vddvp"]["success"] and data["lee"]["success"]
    assert data["vddvp"]["t"] < 1e-10 and data["vddvp"]["q"] < 1e-10
    assert data["lee"]["t"] > 1e-3


def test_time_dependent_steps_spread_under_vddvp_not_lee():
    rows = paper.step_ratio_sweep((0.5, 0.05, 0.005))["rows"]
    assert all(r["status"] == "success" for r in rows)
    spread = {(r["rule"], r["tau0"]): r["ratio_max"] / r["ratio_min"] for r in rows}
    assert spread["vddvp", 0.005] > spread["vddvp", 0.05] > 1.0
    assert spread["vddvp", 0.005] > 1.5
    assert all(spread["lee", tau0] < 1.07 for tau0 in (0.5, 0.05, 0.005))


def test_symplecticity_fixed_steps_and_lee_in_extended_phase_space():
    data = paper.symplecticity(samples=3)
    for name in ("pendulum", "paper_pendulum"):
        assert data[name]["fixed_phase_space"] < 1e-13
        assert data[name]["lee_extended"] < 1e-13
        assert data[name]["explicit_euler_control"] > 1e-4  # the measure can fail
    assert data["paper_pendulum"]["time_dependent"]


def test_energy_residual_does_not_grow_with_the_number_of_steps():
    rows = paper.energy_residual_growth((1000, 20_000))["rows"]
    assert all(r["max_residual"] < 1e-14 and r["running_sum"] < 1e-14 for r in rows)


@pytest.mark.slow(why="study")
def test_reproduce_writes_report_and_figures(tmp_path, capsys):
    assert main(["reproduce", "--quick", "--out", str(tmp_path)]) == 0
    report = (tmp_path / "report.md").read_text()
    for heading in ("## 1. Section 5", "## 2. Section 4: site density", "## 3. Section 3",
                    "## 4. Section 4: step lengths", "## 5. Symplecticity", "## 6. Discrete"):
        assert heading in report
    assert "have not landed" not in report and "`pendulum_lagrangian`" in report
    assert "## 5. Symplecticity and energy" in report and "explicit Euler" in report
    for figure in ("paper_figures.png", "site_density.png", "step_ratios.png"):
        assert (tmp_path / figure).stat().st_size > 10_000


def _measurements(good: bool) -> dict:
    """Fabricated measurements: every claim holds (``good``) or every claim fails."""
    solution = type("Nodes", (), {"t": np.array([0.0, 2000.0])})()
    bad = not good
    sweep_rows = [{"rule": rule, "tau0": tau0, "status": "success", "steps": 40,
                   "t_reached": 16.0, "ratio_min": 1.0,
                   "ratio_max": {("vddvp", 0.5): 1.2, ("vddvp", 0.05): 1.1 if bad else 1.9,
                                 ("lee", 0.5): 1.01, ("lee", 0.05): 1.3 if bad else 1.02}
                   [rule, tau0]} for rule in ("vddvp", "lee") for tau0 in (0.5, 0.05)]
    site = {"tau0": [0.05, 0.025], "tau_spread": [0.3, 0.3], "node": [1e-2, 5e-3],
            "midpoint": [1e-3, 2.5e-4], "slope_node": 0.2 if bad else 1.0,
            "slope_midpoint": 2.0}
    return {
        "example": {"solution": solution, "steps": 4000, "tau_range": (0.45, 0.53),
                    "long_period": 250.0 if bad else 314.5, "short_period": 3.3,
                    "pendulum_period": 3.3 if bad else 6.6,
                    "extremes": {"at_smallest_steps": 0.9 if bad else 0.1,
                                 "at_largest_steps": 0.95, "minima": 5, "maxima": 5}},
        "site": {"pendulum": site, "quartic": site},
        "gauge": {"vddvp": {"t": 1e-2 if bad else 1e-14, "q": 1e-14},
                  "lee": {"t": 1e-2, "q": 1e-2}},
        "sweep": {"rows": sweep_rows},
        "symplectic": {"pendulum": {"time_dependent": False,
                                    "fixed_phase_space": 1e-6 if bad else 1e-16,
                                    "lee_extended": 1e-6 if bad else 1e-16,
                                    "explicit_euler_control": 1e-2}},
        "growth": {"rows": [{"steps": 1000, "t": 500.0, "max_residual": 1e-16,
                             "running_sum": 1e-9 if bad else 1e-16}]},
        "legendre": {rule: {"t": 1e-3 if bad else 1e-10, "q": 1e-10, "p": 1e-10,
                            "steps": (400, 400), "success": True}
                     for rule in ("vddvp", "lee", "fixed")},
    }


def test_report_verdicts_follow_the_measurements():
    good, bad = reproduce_report(_measurements(True)), reproduce_report(_measurements(False))
    assert "Not confirmed" not in good
    verdicts = 10  # periods 2, extremes, site, gauge, sweep, symplectic 2, growth, legendre
    assert good.count("Confirmed (threshold:") == verdicts
    assert bad.count("**Not confirmed** (threshold:") == verdicts
    assert "(threshold: vddvp changes at most 1e-10, lee's node times at least 0.001)" in bad
