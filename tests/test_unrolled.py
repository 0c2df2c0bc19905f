"""The unrolled Newton gives fast_newton's result to the last bit, whether or not its unrolled
iterations stop, and the compiled recheck gives the virtual machine's residuals."""

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import load_scene
from ddvp_nlp.discrete import equations
from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.solvers.chunk import FAST_NEWTON_OPTIONS
from ddvp_nlp.solvers.compiler import find_compiler
from ddvp_nlp.solvers.recheck import grid_residuals
from ddvp_nlp.solvers.steps import step_functions
from ddvp_nlp.solvers.unrolled import unrolled_newton


@pytest.mark.parametrize("iterations", [1, 4])
def test_unrolled_newton_is_fast_newton_bit_for_bit(iterations):
    scene = load_scene("paper_pendulum")
    system, config = scene.system, scene.resolve({})
    functions = step_functions(system, Scheme.coerce("vddvp"))
    theta = system.parameter_vector(config.params)
    reference = ca.rootfinder("reference", "fast_newton", functions.energy_residual,
                              FAST_NEWTON_OPTIONS)
    unrolled = unrolled_newton("unrolled", functions.energy_residual, FAST_NEWTON_OPTIONS,
                               iterations=iterations)
    rng = np.random.default_rng(1)
    for _ in range(5):
        z_prev = rng.uniform(-1, 1, 2)
        z_mid = z_prev + 0.05 * rng.uniform(-1, 1, 2)
        w = np.concatenate([[0.0, 0.1], z_prev, z_mid, theta, [0.0]])
        guess = np.asarray(functions.energy_predict(w, 0.1)).ravel()
        expected = np.asarray(reference(guess, w)).ravel()
        assert np.array_equal(np.asarray(unrolled(guess, w)).ravel(), expected)


def test_compiled_recheck_equals_the_virtual_machine(tmp_path):
    compiler = find_compiler("auto")
    if compiler is None:
        pytest.skip("no C compiler")
    scene = load_scene("pendulum")
    system = scene.system
    scheme = Scheme.coerce("vddvp")
    rng = np.random.default_rng(2)
    t = np.cumsum(rng.uniform(0.05, 0.1, 1500))
    q, p = rng.uniform(-1, 1, (1500, 1)), rng.uniform(-1, 1, (1500, 1))
    theta = system.parameter_vector(None)
    expected = equations.grid_residuals(system, scheme, t, q, p, theta)
    found = grid_residuals(system, scheme, t, q, p, theta, compiler=compiler,
                           cache_dir=tmp_path)
    for a, b in zip(found, expected, strict=True):
        assert np.array_equal(a, b)
