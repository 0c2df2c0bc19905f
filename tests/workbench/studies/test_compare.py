"""The comparison: each method's scheme, its fitted order, and the work-precision report."""

import csv
import math

import casadi as ca
import numpy as np
import pytest
from helpers.common import fitted_order

from ddvp_nlp import Compilation, HamiltonianSystem, InputError, Scene, load_scene
from ddvp_nlp.cli import main
from ddvp_nlp.solvers.baselines.dop853 import flow_callable
from ddvp_nlp.solvers.baselines.fixed_step import fixed_step_run
from ddvp_nlp.solvers.baselines.lee_left_stepper import lee_left_march
from ddvp_nlp.studies.methods import METHODS, get_methods
from ddvp_nlp.studies.work_precision import (
    COLUMNS,
    CompareOptions,
    ComparisonReference,
    default_methods,
    errors,
    pareto,
    time_to_reach,
)
from ddvp_nlp.studies.work_precision_report import read_rows, work_precision


def _run(name, scene_name, value, overrides=None):
    scene = load_scene(scene_name)
    config = scene.resolve(overrides or {})
    solution = METHODS[name].run(scene.system, config, value, compiler=None, cache_dir=None,
                                 max_steps=10**6)
    return scene, config, solution


@pytest.mark.parametrize("name, order", [("vddvp", 2), ("lee", 2), ("midpoint", 2),
                                         ("stormer_verlet", 2), ("rk4", 4)])
def test_fitted_order_on_harmonic_matches_the_trait(name, order):
    steps = [0.1 / 2**j for j in range(4)]
    found = []
    for tau in steps:
        scene, config, solution = _run(name, "harmonic", tau, {"t_end": 5.0})
        assert solution.success, solution.message
        found.append(errors(scene.system, ComparisonReference(scene, config), solution)[0])
    assert METHODS[name].order == order
    assert abs(fitted_order(steps, found) - order) < 0.1, found


def test_dop853_error_falls_with_its_tolerance():
    found = []
    for rtol in (1e-4, 1e-6, 1e-8, 1e-10):
        scene, config, solution = _run("dop853", "harmonic", rtol)
        assert solution.success
        found.append(errors(scene.system, ComparisonReference(scene, config), solution)[0])
    assert all(b < a / 20 for a, b in zip(found, found[1:], strict=False)), found


def test_stormer_verlet_and_rk4_are_the_textbook_steps_on_a_time_dependent_scene():
    scene = load_scene("paper_pendulum")
    eps, omega, tau = 0.1, 0.02, 0.25
    theta = scene.system.parameter_vector({})

    def force(q, t):  # -dV/dq
        return -np.sin(q) * (1 - eps * np.sin(omega * t))

    def flow(t, z):
        return np.array([z[1], force(z[0], t)])

    sv = fixed_step_run(scene.system, "stormer_verlet", [0.5], [0.5], tau=tau, t_end=50.0,
                        t0=0.0, theta=theta, compiler=None)
    rk = fixed_step_run(scene.system, "rk4", [0.5], [0.5], tau=tau, t_end=50.0, t0=0.0,
                        theta=theta, compiler=None)
    q, p = 0.5, 0.5
    z = np.array([0.5, 0.5])
    for k in range(200):
        t = k * tau
        p_half = p + tau / 2 * force(q, t)
        q = q + tau * p_half
        p = p_half + tau / 2 * force(q, t + tau)
        k1 = flow(t, z)
        k2 = flow(t + tau / 2, z + tau / 2 * k1)
        k3 = flow(t + tau / 2, z + tau / 2 * k2)
        k4 = flow(t + tau, z + tau * k3)
        z = z + tau / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    assert sv.steps == rk.steps == 200
    assert abs(sv.q[-1, 0] - q) < 1e-12 and abs(sv.p[-1, 0] - p) < 1e-12
    assert np.max(np.abs(np.array([rk.q[-1, 0], rk.p[-1, 0]]) - z)) < 1e-12


def test_lee_left_point_scheme_against_its_closed_form_and_its_breakdown():
    """On the harmonic oscillator each step of Lee's scheme is a quadratic in tau_k:
    v_k = v_{k-1} - tau_k q_k and v_k^2/2 + q_k^2/2 = v_{k-1}^2/2 + q_{k-1}^2/2."""
    scene = load_scene("harmonic")
    theta = scene.system.parameter_vector({})
    tau0 = 0.05
    solution = lee_left_march(scene.system, [1.0], [0.0], tau0=tau0, t_end=20.0, t0=0.0,
                              theta=theta, compiler=None)
    assert not solution.success
    assert solution.status.code == "no_admissible_step"
    v = 0.0 - tau0 * 1.0  # p0 = v0 + tau0 V'(q0)
    q_prev, q, t, tau = 1.0, 1.0 + tau0 * v, tau0, tau0
    expected_t, expected_q = [0.0, t], [1.0, q]
    while True:
        a, b, c = q**2 / 2, -v * q, (q**2 - q_prev**2) / 2
        disc = b * b - 4 * a * c
        if disc < 0:
            break
        roots = [(-b - math.sqrt(disc)) / (2 * a), (-b + math.sqrt(disc)) / (2 * a)]
        tau = min(roots, key=lambda r: abs(r - tau))  # the root that continues the steps
        if tau <= 0:
            break
        v = v - tau * q
        q_prev, q, t = q, q + tau * v, t + tau
        expected_t.append(t)
        expected_q.append(q)
    # The march stops where the closed form's continuing root turns negative: as q_k passes near
    # 0 the kick vanishes and the energy cannot balance (the other root is a step of about 416).
    assert solution.t.size == len(expected_t)
    assert np.max(np.abs(solution.t - expected_t)) < 1e-9
    assert np.max(np.abs(solution.q[:, 0] - expected_q)) < 1e-9
    assert np.max(np.abs(solution.energy_residual)) < 1e-12


def test_flow_callable_is_the_hamiltonian_vector_field():
    scene = load_scene("kepler")
    flow = flow_callable(scene.system, scene.system.parameter_vector({}))
    z = np.array([0.3, -0.8, 0.2, 0.9])
    r3 = np.hypot(*z[:2]) ** 3
    assert np.allclose(flow(0.0, z), [z[2], z[3], -z[0] / r3, -z[1] / r3], rtol=1e-14)


def test_work_precision_writes_the_documented_report(tmp_path):
    scene = load_scene("harmonic")
    rows = work_precision(scene, out=tmp_path, compilation=Compilation(compiler=None),
                          options=CompareOptions(methods=["lee_left", "rk4", "dop853"],
                                                 knobs={"lee_left": [0.1, 0.05],
                                                        "rk4": [0.2, 0.1, 0.05],
                                                        "dop853": [1e-6, 1e-8]},
                                                 repeats=1))
    with open(tmp_path / "work_precision.csv", newline="") as handle:
        assert next(csv.reader(handle)) == COLUMNS
    np.testing.assert_equal(read_rows(tmp_path / "work_precision.csv"), rows)  # NaN == NaN
    assert [(r["method"], r["value"]) for r in rows] == [
        ("lee_left", 0.1), ("lee_left", 0.05), ("rk4", 0.2), ("rk4", 0.1), ("rk4", 0.05),
        ("dop853", 1e-6), ("dop853", 1e-8)]
    # Lee's left-point scheme fails on every point; each failure keeps its row and the sweep
    # goes on to the next point and the next method.
    for row in rows[:2]:
        assert row["status"] != "success" and row["message"].startswith(
            ("Newton's method", "the step equations have no root with tau > 0"))
        assert 0 < row["t_reached"] < 20 and row["steps"] > 0
    assert all(r["status"] == "success" for r in rows[2:])
    assert all(r["run_s"] > 0 and r["repeats"] == 1 for r in rows)
    assert rows[4]["trajectory_error"] < rows[3]["trajectory_error"] / 10
    assert math.isnan(rows[2]["scheme_energy_residual"])
    summary = (tmp_path / "summary.md").read_text()
    assert "| `lee_left` | 1 | yes | yes | tau0 | 2 | 2 |" in summary
    assert "## Runs that did not reach t_end" in summary
    assert "In words: cheapest is" in summary
    assert (tmp_path / "work_precision.png").stat().st_size > 10_000


def test_a_step_beyond_max_steps_is_a_row_not_a_crash(tmp_path):
    rows = work_precision(load_scene("harmonic"), out=tmp_path,
                          compilation=Compilation(compiler=None),
                          options=CompareOptions(methods="rk4", knobs={"rk4": [0.1, 0.001]},
                                                 repeats=1, max_steps=1000))
    assert rows[0]["status"] == "success"
    assert rows[1]["status"] == "not_run"
    assert rows[1]["message"] == ("tau = 0.001 needs 20000 steps to reach t_end, more than "
                                  "max_steps = 1000")


def _nonseparable(q, p, t):
    return p[0] ** 2 / 2 * (1 + q[0] ** 2 / 4) + q[0] ** 2 / 2


def test_methods_that_do_not_apply_are_left_out_with_the_reason():
    scene = Scene(_nonseparable, n=1, q0=[1.0], p0=[0.0], tau0=0.1, t_end=5.0, name="bent")
    chosen, left_out = default_methods(scene.system)
    assert [m.name for m in chosen] == ["vddvp", "midpoint", "avf", "rk4", "dop853"]
    not_separable = "dH/dp depends on q or t, so H is not T(p) + V(q, t)"
    assert left_out == [
        "`lee`: for autonomous H its energy equation is the vddvp one (H_k = H_{k-1})",
        f"`stormer_verlet`: {not_separable}", f"`leapfrog`: {not_separable}",
        f"`verlet_adaptive`: {not_separable}", f"`lee_left`: {not_separable}",
        "`rattle`: needs a system with holonomic constraints; 'bent' has none",
        "`shake`: needs a system with holonomic constraints; 'bent' has none"]
    paper = load_scene("paper_pendulum").system
    constrained_only = ("rattle", "shake")
    assert [m.name for m in default_methods(paper)[0]] == \
        [name for name in METHODS if name not in constrained_only]
    with pytest.raises(InputError, match="method 'stormer_verlet' does not apply to scene "
                                         "'bent': dH/dp depends on q or t"):
        work_precision(scene, out="unused", options=CompareOptions(methods=["stormer_verlet"]))


def test_quartic_kinetic_energy_is_refused_by_lee_left_only():
    system = HamiltonianSystem(lambda q, p, t: p[0] ** 4 / 4 + ca.cos(q[0]), 1, name="quartic")
    assert METHODS["stormer_verlet"].applies(system) is None
    assert METHODS["lee_left"].applies(system) == ("H is not quadratic in p (d2H/dp2 is not "
                                                   "constant)")


@pytest.mark.parametrize("kwargs, message", [
    ({"methods": "rk4,euler"}, "unknown method 'euler' (choose from vddvp, lee, midpoint, "
                               "stormer_verlet, leapfrog, verlet_adaptive, avf, rk4, dop853, "
                               "lee_left, rattle, shake)"),
    ({"methods": []}, "methods must name at least one method"),
    ({"methods": "rk4", "knobs": {"vddvp": [0.1]}},
     "knobs given for method 'vddvp', which is not compared"),
    ({"methods": "rk4", "knobs": {"rk4": [-0.1]}}, "tau of method 'rk4' must be > 0, got -0.1"),
    ({"methods": "rk4", "knobs": {"rk4": [50.0]}},
     "tau of method 'rk4' must not exceed t_end - t0 = 20.0, got 50.0"),
    ({"halvings": -1}, "halvings must be an integer >= 0, got -1"),
    ({"repeats": 0}, "repeats must be an integer >= 1, got 0"),
    ({"overrides": {"x": 1.0}}, "scene 'harmonic' has no parameter 'x'"),
])
def test_bad_comparison_input_is_refused_before_anything_runs(tmp_path, kwargs, message):
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        overrides = kwargs.pop("overrides", None)
        work_precision(load_scene("harmonic"), out=tmp_path / "never", overrides=overrides,
                       options=CompareOptions(**kwargs))
    assert not (tmp_path / "never").exists()


def test_get_methods_keeps_the_order_given_and_drops_repeats():
    assert [m.name for m in get_methods("rk4, vddvp,rk4")] == ["rk4", "vddvp"]


def test_time_to_reach_interpolates_on_the_pareto_front():
    rows = [{"method": "m", "status": "success", "run_s": s, "trajectory_error": e}
            for s, e in [(1.0, 1e-2), (2.0, 1e-3), (3.0, 5e-3), (4.0, 1e-5)]]
    front = pareto(rows, "m", "trajectory_error")
    assert front == [(1.0, 1e-2), (2.0, 1e-3), (4.0, 1e-5)]  # (3 s, 5e-3) is beaten
    seconds, bound = time_to_reach(front, 1e-4)
    assert not bound and seconds == pytest.approx(math.sqrt(2 * 4))
    assert time_to_reach(front, 0.5) == (1.0, True)
    assert time_to_reach(front, 1e-6) is None


def test_compare_command(tmp_path, capsys):
    code = main(["compare", "harmonic", "--methods", "stormer_verlet,rk4", "--halvings", "1",
                 "--repeats", "1", "--no-compile", "--no-progress", "--out", str(tmp_path)])
    assert code == 0
    out = capsys.readouterr().out
    assert out.startswith("harmonic compare: 4 runs, 0 did not reach t_end")
    assert {p.name for p in tmp_path.iterdir()} == {"work_precision.csv", "work_precision.png",
                                                    "summary.md", "meta.json"}
    assert main(["compare", "harmonic", "--methods", "euler"]) == 2
    assert "ddvp compare: error: unknown method 'euler'" in capsys.readouterr().err
