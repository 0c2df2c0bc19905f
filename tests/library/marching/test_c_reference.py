"""The C references of scripts/benchmarks/bench_march.py: the fast C march solves the same
equations as the first one (same steps, same nodes up to the accumulated round-off) with few
Newton iterations, whichever predictor it starts from."""

import ctypes
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from ddvp_nlp import load_scene
from ddvp_nlp.solvers.accuracy.node_values import NodeValues

SCRIPTS = Path(__file__).resolve().parents[3] / "scripts" / "benchmarks"


@pytest.fixture(scope="module")
def library(tmp_path_factory):
    if shutil.which("gcc") is None:
        pytest.skip("no C compiler")
    sys.path.insert(0, str(SCRIPTS))
    try:
        from bench_march import c_march_library
    finally:
        sys.path.remove(str(SCRIPTS))
    return c_march_library(tmp_path_factory.mktemp("c_march"))


def _scene(name, overrides):
    """The system, its resolved configuration and its parameters padded to the C march's four."""
    scene = load_scene(name)
    config = scene.resolve(overrides)
    theta = np.zeros(4)
    values = scene.system.parameter_vector(config.params)
    theta[:values.size] = values
    return scene.system, config, theta


@pytest.mark.parametrize("name, kind, overrides, iterations",
                         [("paper_pendulum", 0, {}, 4.0),
                          ("fpu", 1, {"t_end": 20.0, "tau0": 0.01}, 6.0)])
def test_fast_c_march_solves_the_same_equations(library, name, kind, overrides, iterations):
    system, config, theta = _scene(name, overrides)
    n = system.n
    z0 = np.concatenate([config.q0, config.p0])
    capacity = 30_000

    def arrays():
        return np.empty(capacity + 1), np.empty((capacity + 1, 2 * n)), np.empty(capacity + 1)

    t, z, H = arrays()
    steps = library.c_march(kind, n, theta, z0, config.t0, config.tau0, config.t_end, capacity,
                            1e-10, t, z, H)
    assert steps > 1000
    for predictor in (0, 1, 2):
        count = ctypes.c_long(0)
        t2, z2, H2 = arrays()
        fast = library.c_march_fast(kind, n, theta, z0, config.t0, config.tau0, config.t_end,
                                    capacity, 1e-10, predictor, t2, z2, H2, ctypes.byref(count))
        assert fast == steps
        assert np.max(np.abs(t2[:steps + 1] - t[:steps + 1])) < 1e-2
        assert np.max(np.abs(z2[:steps + 1] - z[:steps + 1])) < 1e-2
        assert np.max(np.abs(H2[:steps + 1] - H[:steps + 1])) < 1e-4
        assert count.value <= iterations * steps  # Newton updates in all


@pytest.mark.slow_when(lambda name, **_: name == "fpu", why="repetition")
@pytest.mark.parametrize("name, kind, overrides", [("paper_pendulum", 0, {"t_end": 2000.0}),
                                                   ("fpu", 1, {"t_end": 20.0, "tau0": 0.01})])
def test_c_checks_compute_what_the_march_checks(library, name, kind, overrides):
    """c_march_checks (the C row that does march()'s extra work) computes the march's own
    numbers on the march's nodes: the recheck's residuals, the accuracy check's estimates and
    the solvability weight (w = -8 c)."""
    from ddvp_nlp import march

    system, config, theta = _scene(name, overrides)
    n = system.n
    solution = march(
        system, config.q0, config.p0, (0.0, config.t_end), tau0=config.tau0, params=config.params
    )
    steps = solution.steps
    t = np.ascontiguousarray(solution.t)
    z = np.ascontiguousarray(np.column_stack([solution.q, solution.p]))
    canonical, energy = np.empty((steps, 2 * n)), np.zeros(steps)
    delta, scale, error, w = np.empty(steps), np.empty(steps), np.empty(steps), np.empty(steps + 1)
    library.c_march_checks(kind, n, theta, steps, t, z, canonical, energy, delta, scale, error, w)
    size = np.maximum(1.0, np.max(np.abs(z), axis=1))
    np.testing.assert_allclose(np.max(np.abs(canonical), axis=1), solution.canonical_residual,
                               rtol=0, atol=1e-13 * size.max())
    np.testing.assert_allclose(energy[1:], solution.energy_residual, rtol=0, atol=1e-13)
    # the accuracy check's first look (one RK4 step of the exact flow per step; the verdict then
    # measures the steps near their bound again with the exact flow, which the C row does not)
    d, _, _ = NodeValues(system, system.parameter_vector(config.params)).first_look(t, z)
    np.testing.assert_allclose(delta, np.max(np.abs(d), axis=1), rtol=1e-6, atol=1e-15)
    np.testing.assert_allclose(w, -8 * solution.solvability, rtol=1e-9,
                               atol=1e-12 * np.max(np.abs(w)))
    assert np.all(np.isfinite(error))


@pytest.mark.parametrize("azimuth", [0.0, 1e5])
def test_c_sphere_march_solves_the_same_equations(library, azimuth):
    """c_march_sphere (bench_step_cost.py's C row) marches the spherical pendulum in angles by
    the library's equations: the careful march's number of steps, its nodes up to accumulated
    round-off, H at every node, and few Newton updates per step from either predictor,
    also with the azimuth offset by 1e5 (the round-off-relative step test)."""
    import casadi as ca

    from ddvp_nlp import Compilation, HamiltonianSystem, march

    def spherical(q, p, t):
        return p[0] ** 2 / 2 + p[1] ** 2 / (2 * ca.sin(q[0]) ** 2) - ca.cos(q[0])

    sphere = HamiltonianSystem(spherical, 2, name="spherical_pendulum_angles")
    z0 = np.array([2.0, azimuth, 0.0, 1.2])
    solution = march(sphere, z0[:2], z0[2:], (0.0, 10.0), tau0=0.05, accuracy=None,
                     compilation=Compilation(fast=False))
    capacity = 1000
    bound = 1e-9 * max(1.0, azimuth)  # round-off of the iterate, accumulated over 253 steps
    for predictor in (0, 2):
        t, z, H = np.empty(capacity + 1), np.empty((capacity + 1, 4)), np.empty(capacity + 1)
        count = ctypes.c_long(0)
        steps = library.c_march_sphere(z0, 0.0, 0.05, 10.0, capacity, 1e-10, predictor, t, z,
                                       H, ctypes.byref(count))
        assert steps == solution.steps
        assert np.max(np.abs(t[:steps + 1] - solution.t)) < bound
        assert np.max(np.abs(z[:steps + 1, :2] - solution.q)) < bound
        assert np.max(np.abs(z[:steps + 1, 2:] - solution.p)) < bound
        s = np.sin(z[:steps + 1, 0])
        H_here = (z[:steps + 1, 2] ** 2 / 2 + z[:steps + 1, 3] ** 2 / (2 * s**2)
                  - np.cos(z[:steps + 1, 0]))
        assert np.max(np.abs(H[:steps + 1] - H_here)) < 1e-13
        assert count.value <= 4.5 * steps  # Newton updates in all
