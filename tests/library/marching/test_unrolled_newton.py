"""The unrolled Newton with fast_newton's QR gives fast_newton's result to the last bit, whether
or not its unrolled iterations stop; with the elimination of the chunk's small systems it finds
the same root; and the compiled recheck gives the virtual machine's residuals."""

import functools

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import Compilation, load_scene, march
from ddvp_nlp.discrete import equations
from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.solvers.compiler import cache_folder, compile_function, find_compiler
from ddvp_nlp.solvers.marching.chunk import MEDIUM_UNROLL, SMALL_UNROLL
from ddvp_nlp.solvers.marching.recheck import recheck_residuals
from ddvp_nlp.solvers.marching.step_newton import NEWTON_OPTIONS, DenseLU, unrolled_newton
from ddvp_nlp.solvers.marching.steps import step_functions

# the first steps these were measured at: the scenes' defaults then (kepler, fpu and
# henon_heiles have smaller ones now, for an accurate trajectory at their defaults)
MEASURED_AT = {"fpu": {"tau0": 0.01}, "henon_heiles": {"tau0": 0.05}, "kepler": {"tau0": 0.01}}


@functools.cache  # once per scene for the module: its tests only read what it returns
def _steps(name):
    """The step functions, theta and step inputs ``(w, guess)`` of ``name`` from the nodes of a
    short careful march: the predictor, and the predictor pushed off by 1e-3 .. 0.1, so that
    some steps stop within three iterations and some need a fourth update or more (measured:
    the residual after three iterations from 1e-17 to 1e-3)."""
    scene = load_scene(name)
    system, config = scene.system, scene.resolve(MEASURED_AT.get(name, {}))
    solution = march(
        system,
        config.q0,
        config.p0,
        (0.0, config.t0 + 40 * config.tau0),
        tau0=config.tau0,
        params=config.params,
        accuracy=None,
        compilation=Compilation(fast=False),
    )
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
    reference = ca.rootfinder(
        "reference", "fast_newton", functions.energy_residual, dict(NEWTON_OPTIONS)
    )
    unrolled = unrolled_newton("unrolled", functions.energy_residual, NEWTON_OPTIONS,
                               iterations=iterations, check_after=check_after, inline=inline)
    for w, guess in cases:
        expected = np.asarray(reference(guess, w)).ravel()
        assert np.array_equal(np.asarray(unrolled(guess, w)).ravel(), expected)


def test_compiled_inlined_unrolled_newton_is_compiled_fast_newton():
    """Compiled, the inlined iterations with merged subexpressions and the residual test after
    them give fast_newton's bits, on steps that stop inside the unrolled part and on steps that
    go on to fast_newton."""
    compiler = find_compiler("auto")
    if compiler is None:
        pytest.skip("no C compiler")
    functions, cases = _steps("henon_heiles")
    root = ca.rootfinder("root", "fast_newton", functions.energy_residual, dict(NEWTON_OPTIONS))
    # the default cache: a library is named by the hash of its code, compiler and flags
    x0 = ca.MX.sym("x0", functions.energy_residual.sparsity_in(0))
    w_sym = ca.MX.sym("w", functions.energy_residual.sparsity_in(1))
    reference = compile_function(ca.Function("fast_newton_step", [x0, w_sym],
                                             [root(x0, w_sym)]), compiler, cache_folder())
    unrolled = compile_function(unrolled_newton("unrolled", functions.energy_residual,
                                                NEWTON_OPTIONS,
                                                **{**SMALL_UNROLL, "linear": "qr"}),
                                compiler, cache_folder())
    for w, guess in cases:
        assert np.array_equal(np.asarray(unrolled(guess, w)).ravel(),
                              np.asarray(reference(guess, w)).ravel())


@pytest.mark.parametrize("name, options", [("paper_pendulum", SMALL_UNROLL),
                                           ("henon_heiles", SMALL_UNROLL),
                                           ("fpu", MEDIUM_UNROLL)])
def test_unrolled_elimination_finds_fast_newtons_root(name, options):
    """The chunk's unrolling (elimination instead of QR) lands on fast_newton's root to
    round-off, from the predictor and from guesses pushed off by up to 0.1 (which go on to
    fast_newton after the unrolled iterations), with a residual at round-off as fast_newton's
    (fpu's energy row ends between 4e-14 and 8e-13 either way)."""
    functions, cases = _steps(name)
    assert options["linear"] == "lu"
    reference = ca.rootfinder(
        "reference", "fast_newton", functions.energy_residual, dict(NEWTON_OPTIONS)
    )
    unrolled = unrolled_newton("unrolled", functions.energy_residual, NEWTON_OPTIONS,
                               **options)
    for w, guess in cases:
        x = np.asarray(unrolled(guess, w)).ravel()
        expected = np.asarray(reference(guess, w)).ravel()
        np.testing.assert_allclose(x, expected, rtol=0, atol=1e-13)
        residual = np.max(np.abs(np.asarray(functions.energy_residual(x, w))))
        floor = np.max(np.abs(np.asarray(functions.energy_residual(expected, w))))
        assert residual <= max(1e-12, 4 * floor), (residual, floor)


def test_dense_elimination_solves_like_numpy():
    """DenseLU on a pattern with structural zeros (skipped) and fill-in, against numpy."""
    rng = np.random.default_rng(3)
    pattern = ca.Sparsity.dense(5, 5)
    dense = np.eye(5) + 0.3 * rng.uniform(-1, 1, (5, 5))
    dense[3, 0] = dense[4, 1] = dense[0, 4] = 0.0
    pattern = ca.DM(dense).sparsity()  # the zeros are structural
    solver = DenseLU(pattern)
    a = ca.SX.sym("a", pattern.nnz())
    b = ca.SX.sym("b", 5)
    x = solver.solve(solver.factor([a[k] for k in range(pattern.nnz())]),
                     [b[i] for i in range(5)])
    solve = ca.Function("solve", [a, b], [ca.vertcat(*x)])
    rhs = rng.uniform(-1, 1, 5)
    values = np.asarray(ca.DM(dense).nonzeros())
    np.testing.assert_allclose(np.asarray(solve(values, rhs)).ravel(),
                               np.linalg.solve(dense, rhs), rtol=1e-13, atol=1e-14)
    # a zero leading pivot of a regular matrix gives a non-finite update (the chunk's
    # acceptance test then rejects the step), never a wrong finite one
    swapped = np.array([[0.0, 1.0], [1.0, 0.0]])
    small = DenseLU(ca.Sparsity.dense(2, 2))
    a2, b2 = ca.SX.sym("a", 4), ca.SX.sym("b", 2)
    x2 = small.solve(small.factor([a2[k] for k in range(4)]), [b2[0], b2[1]])
    out = np.asarray(ca.Function("s", [a2, b2], [ca.vertcat(*x2)])(
        swapped.T.ravel(), [1.0, 2.0])).ravel()
    assert not np.all(np.isfinite(out))


@pytest.mark.slow_when(lambda name, **_: name == "fpu", why="repetition")
@pytest.mark.parametrize("name, rule", [("pendulum", "vddvp"), ("paper_pendulum", "vddvp"),
                                        ("henon_heiles", "lee"), ("fpu", "fixed"),
                                        ("kepler", "vddvp")])
def test_compiled_recheck_equals_the_virtual_machine(name, rule):
    """The compiled recheck (pieces of nodes with merged subexpressions) gives the bits of the
    separate mapped functions on the virtual machine, over several blocks and a partial one."""
    compiler = find_compiler("auto")
    if compiler is None:
        pytest.skip("no C compiler")
    scene = load_scene(name)
    system = scene.system
    scheme = Scheme.coerce(rule)
    rng = np.random.default_rng(2)
    t = np.cumsum(rng.uniform(0.05, 0.1, 1500))
    n = system.n
    q, p = rng.uniform(-1, 1, (1500, n)), rng.uniform(-1, 1, (1500, n))
    theta = system.parameter_vector(scene.resolve({}).params)
    expected = equations.grid_residuals(system, scheme, t, q, p, theta)
    found = recheck_residuals(system, scheme, t, q, p, theta, compiler=compiler,
                           cache_dir=None)
    for a, b in zip(found, expected, strict=True):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("options", [SMALL_UNROLL, {"iterations": 2}])
def test_values_at_the_root_are_those_of_the_returned_iterate(options):
    """``at_root`` (the chunk's step check) comes out of the unrolled Newton equal to the
    check of the returned root, where the unrolled iterations stop and where fast_newton goes
    on (the pushed guesses)."""
    functions, cases = _steps("henon_heiles")
    check = functions.energy_check
    unrolled = unrolled_newton("unrolled", functions.energy_residual, NEWTON_OPTIONS,
                               at_root=check, **options)
    plain = unrolled_newton("plain", functions.energy_residual, NEWTON_OPTIONS, **options)
    for w, guess in cases:
        x, *values = unrolled.call([guess, w])
        assert np.array_equal(np.asarray(x), np.asarray(plain(guess, w)))
        expected = check.call([x, w])
        assert len(values) == check.n_out()
        for value, want in zip(values, expected, strict=True):
            assert float(value) == float(want)


@functools.cache  # once per offset (offset 0 is every case's reference): only read
def _azimuth_steps(offset: float):
    """A spherical pendulum in angles, ``H = p_1^2/2 + p_2^2 / (2 sin^2 q_1) - cos q_1``,
    whose azimuth ``q_2`` is cyclic: the step inputs of a short careful march from
    ``q_2 = offset``."""
    from ddvp_nlp import HamiltonianSystem

    def H(q, p, t):
        return p[0] ** 2 / 2 + p[1] ** 2 / (2 * ca.sin(q[0]) ** 2) - ca.cos(q[0])

    system = HamiltonianSystem(H, 2, name="spherical_angles")
    solution = march(system, [2.0, offset], [0.0, 1.2], (0.0, 1.0), tau0=0.05, accuracy=None,
                     compilation=Compilation(fast=False))
    z = np.column_stack([solution.q, solution.p])
    functions = step_functions(system, Scheme.coerce("vddvp"))
    cases = []
    for k in range(2, solution.t.size - 1, 3):
        w = np.concatenate([solution.t[k - 1:k + 1], z[k - 1], z[k], [0.0]])
        guess = np.asarray(functions.energy_predict(w, solution.t[k] - solution.t[k - 1]))
        cases.append((w, guess.ravel()))
    return functions, cases


@pytest.mark.parametrize("offset", [0.0, 1e3, 1e5])
def test_the_update_test_is_relative_to_the_iterates_round_off(offset):
    """A cyclic coordinate far from zero (a winding azimuth, an offset) puts the Newton updates'
    floor at its round-off, above ``abstolStep``: the absolute test alone never passed there and
    every step ran all ``max_iter`` iterations (7-13 us a step against 1.8, issue 49). The
    unrolled iterations stop within four updates from the predictor at every offset, and the
    root is the same motion: the step lengths agree with those at offset 0 to round-off."""
    from ddvp_nlp.solvers.marching.step_newton import newton_iteration

    functions, cases = _azimuth_steps(offset)
    _, at_zero = _azimuth_steps(0.0)
    jacobian = ca.rootfinder("r", "fast_newton", functions.energy_residual,
                             dict(NEWTON_OPTIONS)).get_function("jac_g_x")
    iteration = newton_iteration(DenseLU(jacobian.sparsity_out(0)),
                                 abstol=NEWTON_OPTIONS["abstol"],
                                 abstol_step=NEWTON_OPTIONS["abstolStep"])
    unrolled = unrolled_newton("unrolled", functions.energy_residual, NEWTON_OPTIONS,
                               **SMALL_UNROLL, border=1)
    assert len(cases) >= 5
    for (w, guess), (w0, guess0) in zip(cases, at_zero, strict=True):
        x, stopped, updates = guess, 0.0, 0
        while not stopped and updates < 5:
            x, stopped = iteration(*jacobian(x, w), x, stopped)
            stopped, updates = float(stopped), updates + 1
        assert stopped, f"no stop after {updates} updates at offset {offset}"
        tau = float(np.asarray(unrolled(guess, w)).ravel()[-1])
        tau0 = float(np.asarray(unrolled(guess0, w0)).ravel()[-1])
        # the inputs differ by the offset's round-off: tau agrees to a few units of it
        assert abs(tau - tau0) <= 1e-12 * max(1.0, offset) * tau0
