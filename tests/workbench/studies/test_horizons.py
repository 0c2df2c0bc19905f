"""Long horizons: the exact references that make them affordable, the sweeps cut to what a
horizon affords, and the energy-only comparison where no reference can be afforded."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ddvp_nlp import load_scene
from ddvp_nlp.errors import InputError
from ddvp_nlp.studies.comparable import ComparisonReference
from ddvp_nlp.studies.horizons import affordable_knobs, reference_kind
from ddvp_nlp.studies.methods import get_methods, run_method
from ddvp_nlp.studies.work_precision import errors


def _dop853(rhs, z0, t):
    solution = solve_ivp(rhs, (t[0], t[-1]), z0, method="DOP853", rtol=1e-13, atol=1e-13,
                         t_eval=t)
    return solution.y.T


def _kepler_rhs(t, z):
    return np.r_[z[2:], -z[:2] / np.hypot(*z[:2]) ** 3]


@pytest.mark.parametrize("q0, p0", [((0.4, 0.0), (0.0, 2.0)),        # e = 0.6, periapsis
                                     ((0.1, 0.0), (0.0, np.sqrt(19))),  # e = 0.9
                                     ((0.3, 0.5), (-1.1, 0.4)),       # anywhere on the orbit
                                     ((0.3, 0.5), (1.1, -0.4)),       # clockwise
                                     ((1.0, 0.0), (0.0, 1.0))])       # circular
def test_kepler_exact_solution_matches_dop853(q0, p0):
    scene = load_scene("kepler")
    t = np.linspace(2.0, 32.0, 201)
    q, p = scene.exact(t, np.array(q0), np.array(p0), 2.0, e=0.5)
    expected = _dop853(_kepler_rhs, np.r_[q0, p0], t)
    assert np.max(np.abs(np.hstack([q, p]) - expected)) < 3e-9


def test_kepler_exact_solution_refuses_an_unbound_start_and_the_reference_falls_back():
    scene = load_scene("kepler")
    with pytest.raises(ValueError, match="not bound"):
        scene.exact(np.array([0.0]), np.array([1.0, 0.0]), np.array([0.0, 1.5]), 0.0, e=0.5)
    config = scene.resolve({"q0": [1.0, 0.0], "p0": [0.0, 1.5], "t_end": 1.0})
    assert ComparisonReference(scene, config).kind.startswith("the exact flow")
    assert ComparisonReference(scene, scene.resolve({"t_end": 1.0})).kind == "exact solution"


@pytest.mark.parametrize("q0, p0", [(0.5, 0.5), (-0.3, -0.9), (2.5, 0.1), (1.0, 0.0)])
def test_pendulum_exact_libration_matches_dop853(q0, p0):
    scene = load_scene("pendulum")
    t = np.linspace(3.0, 40.0, 151)
    q, p = scene.exact(t, [q0], [p0], 3.0)
    expected = _dop853(lambda t, z: [z[1], -np.sin(z[0])], [q0, p0], t)
    assert np.max(np.abs(np.hstack([q, p]) - expected)) < 1e-10
    with pytest.raises(ValueError, match="librations"):
        scene.exact(t, [0.0], [2.5], 3.0)  # a rotation


def test_the_exact_reference_stays_exact_over_a_hundred_thousand_periods():
    """The reference of the longest horizon: after 10^5 periods of Kepler e = 0.6 the exact
    solution is back at the periapsis start (the period is 2 pi) to round-off of the phase."""
    scene = load_scene("kepler")
    config = scene.resolve({"e": 0.6})
    q, p = scene.exact(np.array([2 * np.pi * 1e5]), config.q0, config.p0, 0.0, e=0.6)
    assert np.max(np.abs(np.r_[q[0] - config.q0, p[0] - config.p0])) < 1e-8


def test_without_a_reference_only_the_energy_error_is_measured():
    scene = load_scene("henon_heiles")
    config = scene.resolve({"t_end": 20.0})
    reference = ComparisonReference(scene, config, "none")
    assert not reference.measures_trajectory
    solution = run_method(scene, config, "leapfrog", 0.05, compiler=None, max_steps=10_000)
    trajectory, energy = errors(scene.system, reference, solution)
    assert np.isnan(trajectory)
    assert 0 < energy < 1e-2
    with pytest.raises(InputError, match="reference must be one of"):
        ComparisonReference(scene, config, "exactly")


def test_reference_kind_drops_the_numerical_reference_beyond_its_span():
    assert reference_kind(load_scene("henon_heiles"), 1e3, 1e4) == "auto"
    assert reference_kind(load_scene("henon_heiles"), 1e5, 1e4) == "none"
    assert reference_kind(load_scene("kepler"), 1e7, 1e4) == "auto"  # exact at any span


def test_a_long_horizon_trades_fine_steps_for_coarser_ones():
    scene = load_scene("kepler")
    config = scene.resolve({"e": 0.6, "tau0": 0.01})  # the default when this was written
    methods = get_methods(["leapfrog", "dop853"])
    short, left = affordable_knobs(methods, config, config.t0 + 100.0, 2, 100_000)
    assert short["leapfrog"] == [0.02, 0.01, 0.005] and not left
    long_, left = affordable_knobs(methods, config, config.t0 + 4000.0, 2, 100_000)
    # 0.04 is 10^5 steps exactly; 0.02 and 0.01 are not, and two coarser steps take their place
    assert long_["leapfrog"] == [0.16, 0.08, 0.04] and "max_steps" in left[0]
    assert long_["dop853"] == short["dop853"]


def test_runs_predicted_past_the_budget_are_left_out():
    scene = load_scene("kepler")
    config = scene.resolve({"e": 0.6})
    methods = get_methods(["dop853"])
    rows = [{"method": "dop853", "value": 10.0 ** -k, "run_s": 0.01 * 2 ** k}
            for k in range(3, 8)]  # the finer tolerances were not run at the short horizon
    knobs, left = affordable_knobs(methods, config, config.t0 + 1000.0, 2, 10**9,
                                   previous=(10.0, rows), run_budget_s=20.0)
    # 1e-3 .. 1e-4 fit (0.08 s, 0.16 s x 100), 1e-5 on is predicted at 32 s and more, and
    # every finer tolerance is left out with them
    assert knobs["dop853"] == [1e-3, 1e-4]
    assert "1e-05" in left[0] and "1e-12" in left[0]
