"""The alternatives users weigh: leapfrog (drift-kick-drift), reversible adaptive Verlet, AVF.

Their fitted orders, AVF's energy at the nodes, adaptive Verlet's bounded energy on an eccentric
orbit, and SUNDIALS' published leapfrog numbers for Kepler reproduced to 1%.
"""

import functools

import numpy as np
import pytest
from helpers.common import fitted_order

from ddvp_nlp import load_scene
from ddvp_nlp.discrete import RULES
from ddvp_nlp.solvers.baselines.fixed_step import fixed_step_run
from ddvp_nlp.solvers.compiler import find_compiler
from ddvp_nlp.studies.methods import METHODS
from ddvp_nlp.studies.work_precision import ComparisonReference, errors

# each built-in scene loaded once for the module: a solver's functions are built once per
# system (ddvp_nlp/cache.py), so the tests of one scene share them
SCENES = functools.cache(load_scene)


def _run(name, scene_name, value, overrides=None, compiler=None):
    scene = SCENES(scene_name)
    config = scene.resolve(overrides or {})
    solution = METHODS[name].run(scene.system, config, value, compiler=compiler,
                                 cache_dir=None, max_steps=10**7)
    return scene, config, solution


@pytest.mark.parametrize("name", ["avf", "verlet_adaptive", "leapfrog"])
@pytest.mark.parametrize("scene_name, overrides, first", [
    ("harmonic", {"t_end": 5.0}, 0.1),
    ("kepler", {"e": 0.6, "t_end": 2 * np.pi}, 0.01),
])
def test_fitted_order_is_two(name, scene_name, overrides, first):
    steps = [first / 2**j for j in range(4)]
    found = []
    for tau in steps:
        scene, config, solution = _run(name, scene_name, tau, overrides)
        assert solution.success, solution.message
        found.append(errors(scene.system, ComparisonReference(scene, config), solution)[0])
    assert METHODS[name].order == 2
    assert abs(fitted_order(steps, found) - 2) < 0.15, found


def test_avf_keeps_the_cubic_henon_heiles_energy_at_the_nodes():
    scene, config, solution = _run("avf", "henon_heiles", 0.1, {"t_end": 100.0})
    assert solution.success and solution.steps == 1000
    theta = scene.system.parameter_vector(config.params)
    H = scene.system.energy(solution.q, solution.p, solution.t, theta)
    assert np.max(np.abs(H - H[0])) < 1e-13
    # the same steps of Stormer-Verlet drift by 1e-4: the bound above is not round-off luck
    _, _, verlet = _run("stormer_verlet", "henon_heiles", 0.1, {"t_end": 100.0})
    H_verlet = scene.system.energy(verlet.q, verlet.p, verlet.t, theta)
    assert np.max(np.abs(H_verlet - H_verlet[0])) > 1e-5


def test_verlet_adaptive_keeps_the_energy_of_an_eccentric_kepler_orbit_bounded():
    compiler = find_compiler("auto")
    period = 2 * np.pi
    scene, config, solution = _run("verlet_adaptive", "kepler", 0.01,
                                   {"e": 0.9, "t_end": 100 * period}, compiler=compiler)
    assert solution.success, solution.message
    theta = scene.system.parameter_vector(config.params)
    drift = np.abs(scene.system.energy(solution.q, solution.p, solution.t, theta) + 0.5)
    first_orbit = drift[solution.t <= period].max()
    assert drift.max() < 0.3
    assert drift.max() < 1.05 * first_orbit  # bounded: 100 orbits no worse than the first
    # steps follow r^{3/2}: long at aphelion, short at perihelion, and far fewer than fixed ones
    tau = np.diff(solution.t)
    assert tau.max() / tau.min() > 10
    assert solution.steps < 100 * period / 0.01 / 5
    # fixed-step Stormer-Verlet on as many steps loses the orbit
    fixed = fixed_step_run(scene.system, "stormer_verlet", config.q0, config.p0,
                           tau=config.t_end / solution.steps, t_end=config.t_end, t0=0.0,
                           theta=theta, compiler=compiler)
    H_fixed = scene.system.energy(fixed.q, fixed.p, fixed.t, theta)
    assert np.max(np.abs(H_fixed + 0.5)) > 10 * drift.max()


# SUNDIALS examples/arkode/C_serial/ark_kepler.c, leapfrog (ARKODE_SPRK_LEAPFROG_2_2), e = 0.6,
# q0 = (0.4, 0), p0 = (0, 2), to T = 50: H(T) - H0 as published in its output files.
ARK_KEPLER = {1e-3: -1.0321e-7, 5e-4: -2.583e-8, 2.5e-4: -6.460e-9, 1.25e-4: -1.615e-9,
              6.25e-5: -4.037e-10}


def _ark_kepler(dt):
    scene = SCENES("kepler")
    theta = scene.system.parameter_vector({"e": 0.6})
    solution = fixed_step_run(scene.system, "leapfrog", np.array([0.4, 0.0]),
                              np.array([0.0, 2.0]), tau=dt, t_end=50.0, t0=0.0, theta=theta,
                              compiler=find_compiler("auto"))
    assert solution.success and solution.steps == round(50 / dt)
    return float(scene.system.energy(solution.q[-1:], solution.p[-1:], solution.t[-1:],
                                     theta)[0]) + 0.5


@pytest.mark.parametrize("dt", [1e-3, 5e-4, 2.5e-4])
def test_leapfrog_reproduces_sundials_ark_kepler(dt):
    assert _ark_kepler(dt) == pytest.approx(ARK_KEPLER[dt], rel=0.01)


@pytest.mark.slow(why="study")
@pytest.mark.parametrize("dt", [1.25e-4, 6.25e-5])
def test_leapfrog_reproduces_sundials_ark_kepler_fine_steps(dt):
    assert _ark_kepler(dt) == pytest.approx(ARK_KEPLER[dt], rel=0.01)


def test_kick_drift_kick_is_not_sundials_leapfrog():
    # the two Stormer-Verlet forms differ at T = 50 by a factor of about -31 in H(T) - H0
    scene = SCENES("kepler")
    theta = scene.system.parameter_vector({"e": 0.6})
    solution = fixed_step_run(scene.system, "stormer_verlet", np.array([0.4, 0.0]),
                              np.array([0.0, 2.0]), tau=1e-3, t_end=50.0, t0=0.0, theta=theta,
                              compiler=find_compiler("auto"))
    H = float(scene.system.energy(solution.q[-1:], solution.p[-1:], solution.t[-1:], theta)[0])
    assert H + 0.5 > 0 > ARK_KEPLER[1e-3]


@pytest.mark.smoke  # one run per scheme and compared method: the quick tier
@pytest.mark.parametrize("name", list(METHODS))
def test_every_compared_method_marches_from_the_command_line(name, tmp_path, capsys):
    import json

    from ddvp_nlp.cli import main

    out = tmp_path / name
    flag = "--scheme" if name in RULES else "--method"  # the energy rules are schemes
    if name in ("rattle", "shake"):  # constrained systems only: refused, exit 2, no folder
        assert main(["march", "harmonic", flag, name, "--out", str(out), "--no-progress",
                     "--no-plot"]) == 2
        assert "needs a system with holonomic constraints" in capsys.readouterr().err
        assert not out.exists()
        return
    code = main(["march", "harmonic", flag, name, "--set", "t_end=3", "--out", str(out),
                 "--no-progress", "--no-plot"])
    meta = json.loads((out / "meta.json").read_text())
    assert (out / "result.npz").is_file()
    assert meta["scheme"] == name
    assert f"harmonic march [{name}]" in capsys.readouterr().out
    if name != "lee_left":  # Lee's left-point scheme breaks down on harmonic (theory section 3)
        assert code == 0 and meta["status"] == "success", meta["message"]
    residual = meta.get("own_residual_max", meta["canonical_residual_max"])
    if name == "dop853":
        assert residual is None  # no equation on its nodes: nothing to recheck
    else:
        assert residual <= 1e-10 and meta["canonical_residual_max"] <= 1e-10


def test_a_step_that_fails_its_own_equation_turns_the_run_into_a_failure():
    from ddvp_nlp.solution import Status
    from ddvp_nlp.studies.methods import run_method

    scene = SCENES("harmonic")
    config = scene.resolve({"t_end": 1.0})
    solution = run_method(scene, config, "rk4", 0.1, compiler=None, max_steps=100, tol=0.0)
    # rk4's own recheck is round-off, not zero: a tolerance of zero must catch it
    assert solution.status is Status.RESIDUAL_TOO_LARGE and "max(|z|, Z)" in solution.message


@pytest.mark.slow(why="study")
def test_compare_over_horizons_writes_a_panel_per_horizon_and_the_growth(tmp_path, capsys):
    from ddvp_nlp.cli import main

    out = tmp_path / "hz"
    assert main(["compare", "harmonic", "--horizons", "2,4", "--time-unit", "3.14159",
                 "--methods", "rk4,avf,stormer_verlet", "--halvings", "1", "--repeats", "1",
                 "--max-steps", "200", "--out", str(out), "--no-progress"]) == 0
    for name in ("horizons.png", "growth.png", "horizons.md", "horizon_2/summary.md",
                 "horizon_4/work_precision.csv"):
        assert (out / name).is_file(), name
    text = (out / "horizons.md").read_text()
    assert "## T = 2" in text and "## T = 4" in text and "| `avf` |" in text
    # at T = 4 (t_end = 12.6) tau = 0.1 needs 126 steps, 0.2 needs 63: both fit 200;
    # the growth table's avf keeps H to round-off
    growth_row = next(line for line in text.splitlines() if line.startswith("| `avf` |"))
    assert float(growth_row.split("|")[5]) < 1e-13
    assert "compare, T = 4: 6 runs" in capsys.readouterr().out
