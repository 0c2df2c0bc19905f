"""The unrolled Newton gives fast_newton's result to the last bit, whether or not its unrolled
iterations stop, and the compiled recheck gives the virtual machine's residuals."""

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import load_scene, march
from ddvp_nlp.discrete import equations
from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.solvers.chunk import FAST_NEWTON_OPTIONS, SMALL_UNROLL
from ddvp_nlp.solvers.compiler import compile_function, find_compiler
from ddvp_nlp.solvers.recheck import grid_residuals
from ddvp_nlp.solvers.steps import step_functions
from ddvp_nlp.solvers.unrolled import unrolled_newton


def _steps(name):
    """The step functions, theta and step inputs ``(w, guess)`` of ``name`` from the nodes of a
    short careful march: the predictor, and the predictor pushed off by 1e-3 .. 0.1, so that
    some steps stop within three iterations and some need a fourth update or more (measured:
    the residual after three iterations from 1e-17 to 1e-3)."""
    scene = load_scene(name)
    system, config = scene.system, scene.resolve({})
    solution = march(system, config.q0, config.p0, tau0=config.tau0,
                     t_end=config.t0 + 40 * config.tau0, params=config.params, fast=False,
                     check_accuracy=False)
    z = np.column_stack([solution.q, solution.p])
    functions = step_functions(system, Scheme.coerce("vddvp"))
    theta = system.parameter_vector(config.params)
    rng = np.random.default_rng(1)
    cases = []
    for k, push in zip(range(3, 40, 4), (0.0, 0.0, 1e-3, 3e-3, 1e-2, 3e-2, 0.1), strict=False):
        w = np.concatenate([solution.t[k - 1:k + 1], z[k - 1], z[k], theta, [0.0]])
        guess = np.asarray(functions.energy_predict(w, solution.t[k] - solution.t[k - 1]))
        cases.append((w, guess.ravel() + push * rng.uniform(-1, 1, guess.size)))
    return functions, cases


@pytest.mark.parametrize("iterations, check_after, inline",
                         [(1, False, False), (4, False, False), (3, True, True),
                          (1, True, True), (3, True, False), (2, False, True)])
def test_unrolled_newton_is_fast_newton_bit_for_bit(iterations, check_after, inline):
    functions, cases = _steps("paper_pendulum")
    reference = ca.rootfinder("reference", "fast_newton", functions.energy_residual,
                              FAST_NEWTON_OPTIONS)
    unrolled = unrolled_newton("unrolled", functions.energy_residual, FAST_NEWTON_OPTIONS,
                               iterations=iterations, check_after=check_after, inline=inline)
    for w, guess in cases:
        expected = np.asarray(reference(guess, w)).ravel()
        assert np.array_equal(np.asarray(unrolled(guess, w)).ravel(), expected)


def test_compiled_inlined_unrolled_newton_is_compiled_fast_newton(tmp_path):
    """Compiled, the inlined iterations with merged subexpressions and the residual test after
    them give fast_newton's bits, on steps that stop inside the unrolled part and on steps that
    go on to fast_newton."""
    compiler = find_compiler("auto")
    if compiler is None:
        pytest.skip("no C compiler")
    functions, cases = _steps("henon_heiles")
    root = ca.rootfinder("root", "fast_newton", functions.energy_residual, FAST_NEWTON_OPTIONS)
    x0 = ca.MX.sym("x0", functions.energy_residual.sparsity_in(0))
    w_sym = ca.MX.sym("w", functions.energy_residual.sparsity_in(1))
    reference = compile_function(ca.Function("fast_newton_step", [x0, w_sym],
                                             [root(x0, w_sym)]), compiler, tmp_path)
    unrolled = compile_function(unrolled_newton("unrolled", functions.energy_residual,
                                                FAST_NEWTON_OPTIONS, **SMALL_UNROLL),
                                compiler, tmp_path)
    for w, guess in cases:
        assert np.array_equal(np.asarray(unrolled(guess, w)).ravel(),
                              np.asarray(reference(guess, w)).ravel())


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
