"""The march of a constrained system (solvers/marching/constrained_march.py): the Cartesian
pendulum and the spherical pendulum keep g = 0 and the hidden constraint at round-off, the
energy rule's row at round-off, the angular momentum about the vertical; the trajectory
converges at order 2 to the exact pendulum; the start is made consistent; the verdict holds
against the exact pendulum; metamorphic relations (rotated frame, time offset, length units)."""

import functools
import warnings

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ddvp_nlp import HamiltonianSystem, LagrangianSystem, Output, load_scene, march
from ddvp_nlp.discrete.constrained import solvability_function
from ddvp_nlp.solution import Status


def pendulum_h(q, p, t, a, b):
    """Unit mass under the force -(a, b): gravity along any direction (a parameter, so that
    every test shares one compiled chunk)."""
    return (p[0] ** 2 + p[1] ** 2) / 2 + a * q[0] + b * q[1]


def rod(q, t, a, b, L):
    return q[0] ** 2 + q[1] ** 2 - L ** 2


def pendulum(**params):
    values = {"a": 0.0, "b": 1.0, "L": 1.0}
    values.update(params)
    return HamiltonianSystem(pendulum_h_L, 2, values, name="cartesian",
                             constraints=rod)


def pendulum_h_L(q, p, t, a, b, L):
    return pendulum_h(q, p, t, a, b)


# One system for the module: a march's functions are built once per system (ddvp_nlp/cache.py),
# so every test of the Cartesian pendulum reuses them; other gravities and lengths are params.
PENDULUM = pendulum()
Q0, P0 = np.array([0.0, -1.0]), np.array([3.0, 0.0])  # a rotation


@functools.cache
def rotation(scheme, t_end):
    """The rotation from (Q0, P0) on (0, t_end) at tau0 = 0.01, marched once for the tests
    that compare another march with it (a Solution; they only read it)."""
    return march(PENDULUM, Q0, P0, (0, t_end), tau0=0.01, scheme=scheme)


def exact_angle(theta0, omega0, times):
    """theta'' = -sin theta (g = L = 1) by DOP853 at tight tolerance."""
    solved = solve_ivp(lambda t, y: [y[1], -np.sin(y[0])], (0, times[-1]), [theta0, omega0],
                       method="DOP853", rtol=1e-13, atol=1e-13, dense_output=True)
    return solved.sol(times)[0]


def test_fixed_steps_keep_the_constraints_at_round_off_with_no_trend():
    solution = march(PENDULUM, [np.sin(1.0), -np.cos(1.0)], [0.0, 0.0], (0, 100), tau0=0.01,
                     scheme="fixed")
    record = solution.constraints
    assert solution.success and solution.t.size == 10001
    assert record.constraint_residual.max() <= 1e-12
    assert record.hidden_residual.max() <= 1e-12
    quarter = solution.t.size // 4
    for residual in (record.constraint_residual, record.hidden_residual):
        assert residual[-quarter:].max() <= 4 * residual[:quarter].max() + 1e-15
    assert record.newton_updates.max() <= 5
    assert solution.canonical_residual.max() <= 1e-12


def test_energy_steps_conserve_the_interval_energy_in_a_rotation():
    solution = march(PENDULUM, [0.0, -1.0], [3.0, 0.0], (0, 50), tau0=0.01)
    record = solution.constraints
    assert solution.success
    assert np.abs(solution.energy_residual).max() <= 1e-12
    assert record.constraint_residual.max() <= 1e-12
    assert record.hidden_residual.max() <= 1e-12
    assert record.newton_updates.max() <= 5
    tau = np.diff(solution.t)
    assert tau.max() / tau.min() > 1.5  # the steps follow the motion


@pytest.mark.parametrize("tau0", [0.1, 0.002])
def test_the_verdict_holds_against_the_exact_pendulum(tau0):
    """A constrained march is judged against the constrained exact flow like any march; the
    verdict is tested here against an independent reference, the pendulum's angle equation
    by DOP853: a run called accurate is within the tolerance of it (relative to the motion's
    size, which the verdict states), a run whose error passes the tolerance is not called
    accurate, and the time the verdict says it drifted is when the error passes."""
    theta0 = 1.0
    solution = march(PENDULUM, [np.sin(theta0), -np.cos(theta0)], [0.0, 0.0], (0, 30),
                     tau0=tau0, scheme="fixed")
    verdict = solution.verdict
    assert verdict is not None and verdict.steps == solution.t.size - 1
    angle = exact_angle(theta0, 0.0, solution.t)
    error = np.abs(np.column_stack([np.sin(angle), -np.cos(angle)]) - solution.q)
    relative = (error / np.asarray(verdict.scale)[:2]).max(axis=1)
    tolerance = 0.01  # the default Tolerance's global_tol
    if verdict.accurate:
        assert relative.max() <= tolerance
    else:
        assert relative.max() > 0.5 * tolerance
    if verdict.drifted:
        passes = solution.t[np.argmax(relative > tolerance)]
        assert abs(passes - verdict.t_drift) <= 0.1 * verdict.t_drift + 2 * tau0
    assert (tau0 == 0.002) == verdict.accurate


def test_a_libration_has_no_positive_energy_step_where_c_changes_sign():
    """docs/theory.md: c = (nu' G H_pp G' nu - f' H_zz f)/8 changes sign on every libration
    of the Cartesian pendulum; the march stops there, saying so, and never accepts tau <= 0."""
    system = PENDULUM
    solution = march(system, [np.sin(0.5), -np.cos(0.5)], [0.5 * np.cos(0.5),
                     0.5 * np.sin(0.5)], (0, 20), tau0=0.05)
    assert not solution.success
    assert solution.status in (Status.NO_ADMISSIBLE_STEP, Status.RESIDUAL_TOO_LARGE,
                               Status.STEP_RATIO, Status.NEWTON_FAILED)
    assert np.all(np.diff(solution.t) > 0)
    c = solvability_function(system)
    theta = system.parameter_vector()
    values = [float(c(np.r_[np.sin(a), -np.cos(a), w * np.cos(a), w * np.sin(a)], 0, theta))
              for a, w in ((0.0, 1.0), (0.5, 0.0))]
    assert values[0] > 0 > values[1]


@pytest.mark.parametrize("scheme, start, span", [
    ("fixed", ([np.sin(1.0), -np.cos(1.0)], [0.0, 0.0]), 6.0),
    ("vddvp", ([0.0, -1.0], [3.0, 0.0]), 3.0)])
def test_the_trajectory_converges_at_order_two(scheme, start, span):
    errors, steps = [], []
    q0, p0 = start
    theta0 = np.arctan2(q0[0], -q0[1])
    omega0 = (q0[0] * p0[1] * 0 + np.hypot(*p0)) * (1 if p0[0] >= 0 else -1)
    for tau in (0.02, 0.01, 0.005):
        solution = march(PENDULUM, q0, p0, (0, span), tau0=tau, scheme=scheme)
        assert solution.success
        angle = exact_angle(theta0, omega0, solution.t)
        exact = np.column_stack([np.sin(angle), -np.cos(angle)])
        errors.append(np.abs(solution.q - exact).max())
        steps.append(np.diff(solution.t).mean())
    order = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert 1.85 <= order <= 2.15, (order, errors)


def spherical_h(q, p, t):
    return ca.dot(p, p) / 2 + q[2]


def sphere(q, t):
    return ca.dot(q, q) - 1


def test_spherical_pendulum_keeps_the_angular_momentum_about_the_vertical():
    system = HamiltonianSystem(spherical_h, 3, name="spherical", constraints=sphere)
    q0 = [0.0, np.sin(0.1), -np.cos(0.1)]
    solution = march(system, q0, [0.06, 0.0, 0.0], (0, 200), tau0=0.05, scheme="fixed")
    assert solution.success
    L = solution.q[:, 0] * solution.p[:, 1] - solution.q[:, 1] * solution.p[:, 0]
    assert np.abs(L - L[0]).max() <= 1e-12 * abs(L[0])
    assert solution.constraints.constraint_residual.max() <= 1e-12
    assert solution.constraints.hidden_residual.max() <= 1e-12


def test_an_inconsistent_start_is_projected_and_said():
    system = PENDULUM
    with pytest.warns(RuntimeWarning, match="projected onto the constraints"):
        moved = march(system, [0.1, -1.05], [1.0, 0.3], (0, 2), tau0=0.01)
    start = moved.constraints.start
    assert start.moved_q > 0 and start.moved_p > 0
    assert abs(start.q0 @ start.q0 - 1) <= 1e-15 and abs(start.q0 @ start.p0) <= 1e-15
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        again = march(system, start.q0, start.p0, (0, 2), tau0=0.01)
    assert not again.constraints.start.moved
    assert np.array_equal(again.q, moved.q)


@pytest.mark.parametrize("scheme", ["fixed", "vddvp"])
def test_a_rotated_frame_gives_the_same_motion_rotated(scheme):
    angle = 0.7
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    plain = rotation(scheme, 5)
    a, b = R @ np.array([0.0, 1.0])
    turned = march(PENDULUM, R @ Q0, R @ P0, (0, 5), tau0=0.01, scheme=scheme,
                   params={"a": a, "b": b})
    assert turned.t.size == plain.t.size
    assert np.abs(turned.t - plain.t).max() <= 1e-9
    assert np.abs(turned.q - plain.q @ R.T).max() <= 1e-9


@pytest.mark.parametrize("scheme", ["fixed", "vddvp"])
def test_a_time_offset_shifts_the_nodes(scheme):
    plain = rotation(scheme, 5)
    later = march(PENDULUM, Q0, P0, (7, 12), tau0=0.01, scheme=scheme)
    assert later.t.size == plain.t.size
    assert np.abs(later.t - 7 - plain.t).max() <= 1e-10
    assert np.abs(later.q - plain.q).max() <= 1e-9


@pytest.mark.parametrize("scheme", ["fixed", "vddvp"])
def test_length_units_scale_the_motion(scheme):
    """A rod of length L under gravity L (the same angular motion): q and p scale by L, H and
    g by L^2, the steps stay."""
    L = 3.0
    plain = rotation(scheme, 5)
    scaled = march(PENDULUM, L * Q0, L * P0, (0, 5), tau0=0.01, scheme=scheme,
                   params={"b": L, "L": L})
    assert scaled.t.size == plain.t.size
    assert np.abs(scaled.t - plain.t).max() <= 1e-10
    assert np.abs(scaled.q / L - plain.q).max() <= 1e-9


@pytest.mark.parametrize("scheme, bound", [("fixed", 1e-11), ("vddvp", 1e-8)])
def test_lagrangian_and_hamiltonian_forms_give_the_same_motion(scheme, bound):
    """The same equations written two ways: equal up to round-off (an energy step's
    round-off is divided by the energy row's O(tau) derivative in tau, hence vddvp's bound)."""
    def lagrangian(q, v, t):
        return (v[0] ** 2 + v[1] ** 2) / 2 - q[1]

    def circle(q, t):
        return q[0] ** 2 + q[1] ** 2 - 1

    system = LagrangianSystem(lagrangian, 2, name="cartesian_l", constraints=circle)
    assert system.n_constraints == 1
    from_l = march(system, Q0, P0, (0, 3), tau0=0.01, scheme=scheme)
    from_h = rotation(scheme, 3)
    assert from_l.success and from_l.t.size == from_h.t.size
    assert np.abs(from_l.q - from_h.q).max() <= bound


def test_t_eval_and_events_on_the_constrained_interpolant():
    def crossing(t, q, p):
        return q[0]
    crossing.direction = 1
    solution = march(PENDULUM, [0.0, -1.0], [3.0, 0.0], (0, 5), tau0=0.01,
                     output=Output(t_eval=np.linspace(0, 5, 11), events=(crossing,)))
    g = (solution.z_eval[:, :2] ** 2).sum(axis=1) - 1
    assert np.abs(g).max() <= 1e-7  # the Hermite interpolant between two nodes on the circle
    assert solution.t_events[0].size >= 2
    assert np.abs(solution.z_events[0][:, 0]).max() <= 1e-7


def test_a_time_dependent_constraint_is_kept():
    def breathing(q, t):
        return q[0] ** 2 + q[1] ** 2 - (1 + 0.1 * ca.sin(t)) ** 2

    system = HamiltonianSystem(lambda q, p, t: (p[0] ** 2 + p[1] ** 2) / 2 + q[1], 2,
                               name="breathing", constraints=breathing)
    solution = march(system, [0.0, -1.0], [1.0, -0.1], (0, 10), tau0=0.01, scheme="fixed")
    assert solution.success
    assert solution.constraints.constraint_residual.max() <= 1e-12
    assert solution.constraints.hidden_residual.max() <= 1e-12


def test_the_built_in_scene_has_its_constraint():
    scene = load_scene("cartesian_pendulum")
    assert scene.system.n_constraints == 1 and scene.constraints is not None


def test_lee_is_vddvp_for_an_autonomous_system():
    """For autonomous H and g the lee balance dS/dt_k = 0 is the change of the interval energy
    (theory section 12): the same steps up to round-off."""
    vddvp = rotation("vddvp", 3)
    lee = march(PENDULUM, Q0, P0, (0, 3), tau0=0.01, scheme="lee")
    assert lee.success and lee.t.size == vddvp.t.size
    assert np.abs(lee.t - vddvp.t).max() <= 1e-9


def chain(links):
    def hamiltonian(q, p, t):
        return ca.dot(p, p) / 2 + ca.sum1(q[1::2])

    def rods(q, t):
        rows = [q[0] ** 2 + q[1] ** 2 - 1]
        rows += [(q[2 * i] - q[2 * i - 2]) ** 2 + (q[2 * i + 1] - q[2 * i - 1]) ** 2 - 1
                 for i in range(1, links)]
        return ca.vertcat(*rows)
    q0 = np.ravel([[(i + 1) * np.sin(0.3), -(i + 1) * np.cos(0.3)] for i in range(links)])
    return HamiltonianSystem(hamiltonian, 2 * links, name=f"chain{links}", constraints=rods), q0


def test_a_chain_of_links_takes_few_newton_updates_per_step():
    """bench_constraints.py measures 10, 50 and 128 links (2 updates per step each)."""
    system, q0 = chain(10)
    with pytest.warns(RuntimeWarning, match="projected"):
        solution = march(system, q0, np.tile([0.2, 0.0], 10), (0, 1), tau0=0.01,
                         scheme="fixed")
    assert solution.success
    assert solution.constraints.newton_updates.max() <= 5
    assert solution.constraints.constraint_residual.max() <= 1e-12
    assert solution.constraints.hidden_residual.max() <= 1e-12
