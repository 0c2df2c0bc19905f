"""Fixed ends of a constrained system (solvers/bvp/constrained_ends.py): the Cartesian pendulum
against the angle pendulum's fixed-end solution (trajectories and end momenta mapped), order 2
against the continuous constrained solution, Newton and IPOPT on the same rows, the verdict
against an independently computed exact motion, bad input refused by name, and metamorphic
relations (time offset, lengths and gravity scaled, coordinates swapped)."""

import functools
import warnings

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from ddvp_nlp import AtEnergy, GridOptions, HamiltonianSystem, Shooting, solve_bvp
from ddvp_nlp.errors import InputError
from ddvp_nlp.solution import Status


def pendulum_h(q, p, t, a, b, L):
    """Unit mass under the force -(a, b): gravity along any direction (parameters, so that
    every test shares one built problem per node count)."""
    return (p[0] ** 2 + p[1] ** 2) / 2 + a * q[0] + b * q[1]


def rod(q, t, a, b, L):
    return q[0] ** 2 + q[1] ** 2 - L ** 2


CARTESIAN = HamiltonianSystem(pendulum_h, 2, {"a": 0.0, "b": 1.0, "L": 1.0},
                              name="cartesian", constraints=rod)
ANGLE = HamiltonianSystem(lambda q, p, t: p[0] ** 2 / 2 - ca.cos(q[0]), 1, name="angle")
# a libration (0.3 -> -0.5 in 2 time units) and a rotation (0 -> 2.5 in 1; E > 2)
LIBRATION = (0.3, -0.5, 2.0)
ROTATION = (0.0, 2.5, 1.0)


def point(angle, length=1.0):
    return np.array([length * np.sin(angle), -length * np.cos(angle)])


def angle_of(q):
    return np.arctan2(q[:, 0], -q[:, 1])


def angular_momentum(q, p):
    return q[:, 0] * p[:, 1] - q[:, 1] * p[:, 0]


def solve(ends, nodes, **keywords):
    a0, a1, T = ends
    return solve_bvp(CARTESIAN, point(a0), point(a1), (0.0, T), nodes=nodes, **keywords)


@functools.cache
def solved(ends, nodes, scheme):
    """``solve(ends, nodes, scheme=scheme)`` once for the module: the order, metamorphic and
    verdict tests compare with the same solutions (they only read them)."""
    return solve(ends, nodes, scheme=scheme)


def test_fixed_ends_follow_the_angle_pendulum_and_keep_the_constraints():
    a0, a1, T = LIBRATION
    cartesian = solved(LIBRATION, 81, "fixed")
    angle = solve_bvp(ANGLE, [a0], [a1], (0.0, T), nodes=81, scheme="fixed")
    assert cartesian.status is Status.SUCCESS and angle.status is Status.SUCCESS
    assert cartesian.verdict.name == "accurate"
    # two second-order discretisations of one motion: O(tau^2) apart (measured 2.9e-5 in the
    # angle, 8.5e-5 and 5.4e-5 in the end momenta at tau = 0.025)
    np.testing.assert_allclose(cartesian.t, angle.t, rtol=0, atol=1e-14)
    assert np.max(np.abs(angle_of(cartesian.q) - angle.q[:, 0])) <= 1e-4
    momentum = angular_momentum(cartesian.q, cartesian.p)
    assert abs(momentum[0] - angle.p[0, 0]) <= 2e-4
    assert abs(momentum[-1] - angle.p[-1, 0]) <= 2e-4
    record = cartesian.constraints
    assert record.constraint_residual.max() <= 1e-14 and record.hidden_residual.max() <= 1e-14
    assert record.multipliers.shape == (80, 2)
    assert record.ends_moved == {"q_start": 0.0, "q_end": 0.0}
    assert cartesian.canonical_residual.max() <= 1e-14
    assert np.isfinite(cartesian.ends.action)


@pytest.mark.parametrize("scheme, ends", [("fixed", LIBRATION), ("vddvp", ROTATION)])
def test_order_two_against_the_continuous_constrained_solution(scheme, ends):
    errors = [solved(ends, nodes, scheme).verdict.error_max for nodes in (41, 81, 161)]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(orders - 2) <= 0.05), orders


@pytest.mark.parametrize("scheme, ends", [("fixed", LIBRATION), ("vddvp", ROTATION),
                                          ("lee", ROTATION)])
def test_newton_and_ipopt_solve_the_same_rows(scheme, ends):
    newton = solve(ends, 41, scheme=scheme, options=GridOptions(solver="newton"))
    ipopt = solve(ends, 41, scheme=scheme, options=GridOptions(solver="ipopt"))
    for solution, solver in ((newton, "newton"), (ipopt, "ipopt")):
        assert solution.status is Status.SUCCESS, solution.message
        assert solution.ends.stages[-1].solver == solver
        assert solution.constraints.constraint_residual.max() <= 1e-13
    assert np.max(np.abs(newton.q - ipopt.q)) <= 1e-9
    assert np.max(np.abs(newton.t - ipopt.t)) <= 1e-9


def exact_angle_motion(a0, a1, T, times):
    """theta'' = -sin theta from a0 to a1 in time T, by shooting with DOP853 (rtol 1e-13)."""
    def end(omega):
        return solve_ivp(lambda t, y: [y[1], -np.sin(y[0])], (0, T), [a0, omega],
                         method="DOP853", rtol=1e-13, atol=1e-13).y[0, -1] - a1
    omega = brentq(end, -3.0, 3.0, xtol=1e-14)
    solved = solve_ivp(lambda t, y: [y[1], -np.sin(y[0])], (0, T), [a0, omega],
                       method="DOP853", rtol=1e-13, atol=1e-13, dense_output=True)
    return solved.sol(times)


def test_the_verdict_measures_the_true_error():
    a0, a1, T = LIBRATION
    solution = solved(LIBRATION, 41, "fixed")
    theta, omega = exact_angle_motion(a0, a1, T, solution.t)
    exact = np.column_stack([np.sin(theta), -np.cos(theta), omega * np.cos(theta),
                             omega * np.sin(theta)])
    z = np.hstack([solution.q, solution.p])
    true = np.max(np.abs(z - exact) / solution.verdict.scale)
    assert solution.verdict.name == "accurate"
    assert solution.verdict.error_max == pytest.approx(true, rel=0.01)


def test_a_coarse_grid_is_not_called_accurate():
    solution = solve(LIBRATION, 5, scheme="fixed")
    assert solution.canonical_residual.max() <= 1e-14  # its equations hold ...
    assert solution.constraints.constraint_residual.max() <= 1e-14
    assert solution.status is Status.INACCURATE  # ... but it does not follow the motion
    assert solution.verdict.name == "inaccurate" and "local error" in solution.message


def test_ends_off_the_constraint_are_refused_by_name():
    with pytest.raises(InputError, match=r"q_end = .* is not on the constraints"):
        solve_bvp(CARTESIAN, point(0.3), [0.5, -0.5], (0, 2), nodes=21)
    with pytest.raises(InputError, match="q_start"):
        solve_bvp(CARTESIAN, [0.0, -1.1], point(0.3), (0, 2), nodes=21)
    with pytest.raises(InputError, match="singular Jacobian at q_start"):
        solve_bvp(CARTESIAN, [0.0, 0.0], point(0.3), (0, 2), nodes=21)


def test_an_end_off_by_rounding_is_projected_with_a_warning():
    q_end = point(-0.5) * (1 + 1e-9)
    with pytest.warns(RuntimeWarning, match=r"q_end was projected .* moved by"):
        solution = solve_bvp(CARTESIAN, point(0.3), q_end, (0, 2), nodes=21, scheme="fixed")
    assert solution.status is Status.SUCCESS
    assert 0 < solution.constraints.ends_moved["q_end"] <= 1e-8
    assert abs(np.sum(solution.q[-1] ** 2) - 1) <= 1e-15


@pytest.mark.parametrize("keywords, words", [
    ({"nodes": 2}, "nodes"),
    ({"nodes": 21, "derivatives": ("q_end",)}, "derivatives"),
    ({"nodes": 21, "guess": "march"}, "shooting"),
    ({"nodes": 21, "guess": Shooting([0.0, 0.0])}, "shooting"),
    ({"nodes": 21, "guess": "spline"}, "unknown guess 'spline'"),
    ({"nodes": 21, "options": GridOptions(linear="banded")}, "linear='banded'"),
    ({"nodes": 21, "scheme": "nonsense"}, "unknown scheme"),
])
def test_bad_input_is_refused_by_name(keywords, words):
    with pytest.raises(InputError, match=words):
        solve_bvp(CARTESIAN, point(0.3), point(-0.5), (0, 2), **keywords)


def test_a_transfer_at_an_energy_is_refused_by_name():
    with pytest.raises(InputError, match="AtEnergy"):
        solve_bvp(CARTESIAN, point(0.3), point(-0.5), AtEnergy(0.0, 0.0, 2.0), nodes=21)


@settings(max_examples=25, deadline=None)
@given(st.floats(-3.0, 3.0), st.floats(1e-5, 0.5), st.sampled_from(["q_start", "q_end"]))
def test_any_end_off_the_circle_beyond_rounding_is_refused(angle, offset, which):
    ends = {"q_start": point(0.3), "q_end": point(-0.5)}
    ends[which] = point(angle) * (1 + offset)
    with pytest.raises(InputError, match=which):
        solve_bvp(CARTESIAN, ends["q_start"], ends["q_end"], (0, 2), nodes=21)


@pytest.mark.parametrize("scheme, ends", [("fixed", LIBRATION), ("vddvp", ROTATION)])
def test_a_time_offset_moves_only_the_times(scheme, ends):
    a0, a1, T = ends
    base = solved(ends, 41, scheme)
    shifted = solve_bvp(CARTESIAN, point(a0), point(a1), (7.0, 7.0 + T), nodes=41,
                        scheme=scheme)
    assert shifted.status is Status.SUCCESS
    np.testing.assert_allclose(shifted.t - 7.0, base.t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(shifted.q, base.q, rtol=0, atol=1e-10)
    np.testing.assert_allclose(shifted.p, base.p, rtol=0, atol=1e-10)


@pytest.mark.parametrize("scheme, ends", [("fixed", LIBRATION), ("vddvp", ROTATION)])
def test_lengths_and_gravity_scaled_together_scale_the_solution(scheme, ends):
    """L -> c L and gravity -> c g keep theta(t): q and p scale by c, H by c^2."""
    a0, a1, T = ends
    c = 3.0
    base = solved(ends, 41, scheme)
    scaled = solve_bvp(CARTESIAN, point(a0, c), point(a1, c), (0.0, T), nodes=41,
                       scheme=scheme, params={"b": c, "L": c})
    assert scaled.status is Status.SUCCESS and scaled.verdict.name == base.verdict.name
    np.testing.assert_allclose(scaled.t, base.t, rtol=0, atol=1e-10)
    np.testing.assert_allclose(scaled.q / c, base.q, rtol=0, atol=1e-10)
    np.testing.assert_allclose(scaled.p / c, base.p, rtol=0, atol=1e-10)


@pytest.mark.parametrize("scheme, ends", [("fixed", LIBRATION), ("vddvp", ROTATION)])
def test_swapped_coordinates_swap_the_solution(scheme, ends):
    """Gravity along x instead of y and every point's x and y exchanged."""
    a0, a1, T = ends
    base = solved(ends, 41, scheme)
    swapped = solve_bvp(CARTESIAN, point(a0)[::-1], point(a1)[::-1], (0.0, T), nodes=41,
                        scheme=scheme, params={"a": 1.0, "b": 0.0})
    assert swapped.status is Status.SUCCESS
    np.testing.assert_allclose(swapped.t, base.t, rtol=0, atol=1e-10)
    np.testing.assert_allclose(swapped.q[:, ::-1], base.q, rtol=0, atol=1e-10)
    np.testing.assert_allclose(swapped.p[:, ::-1], base.p, rtol=0, atol=1e-10)


def test_two_constraints_double_pendulum():
    """Two rods in Cartesian coordinates (n = 4, m = 2): the constraints and the verdict."""
    def H(q, p, t):
        return (p[0] ** 2 + p[1] ** 2 + p[2] ** 2 + p[3] ** 2) / 2 + q[1] + q[3]

    def rods(q, t):
        return ca.vertcat(q[0] ** 2 + q[1] ** 2 - 1, (q[2] - q[0]) ** 2 + (q[3] - q[1]) ** 2 - 1)

    system = HamiltonianSystem(H, 4, name="double", constraints=rods)

    def position(a, b):
        first = point(a)
        return np.concatenate([first, first + point(b)])

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        solution = solve_bvp(system, position(0.3, 0.5), position(0.1, -0.2), (0.0, 1.0),
                             nodes=41, scheme="fixed")
    assert solution.status is Status.SUCCESS, solution.message
    assert solution.constraints.constraint_residual.max() <= 1e-14
    assert solution.constraints.hidden_residual.max() <= 1e-13
    assert solution.constraints.multipliers.shape == (40, 4)
    assert solution.verdict.name == "accurate"


def test_a_lagrangian_system_gives_the_hamiltonian_solution():
    from ddvp_nlp import LagrangianSystem

    def lagrangian(q, v, t, a, b, L):
        return (v[0] ** 2 + v[1] ** 2) / 2 - a * q[0] - b * q[1]

    system = LagrangianSystem(lagrangian, 2, {"a": 0.0, "b": 1.0, "L": 1.0}, name="lagrangian",
                              constraints=rod)
    a0, a1, T = LIBRATION
    solution = solve_bvp(system, point(a0), point(a1), (0.0, T), nodes=41, scheme="fixed")
    base = solved(LIBRATION, 41, "fixed")
    assert solution.status is Status.SUCCESS and solution.verdict.name == "accurate"
    np.testing.assert_allclose(solution.q, base.q, rtol=0, atol=1e-10)
    np.testing.assert_allclose(solution.p, base.p, rtol=0, atol=1e-10)
