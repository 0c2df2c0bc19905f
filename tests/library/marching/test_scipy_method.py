"""The march as a method of scipy's ``solve_ivp`` (issue 49, solvers/marching/scipy_method.py):
``solve_ivp(fun, t_span, y0, method=DDVP, hamiltonian=H, tau0=...)``. The checks of scipy's own
``scipy/integrate/_ivp/tests/test_ivp.py`` that apply (the result's fields, the dense output at
the nodes, ``t_eval``, events, a backward span, a span of length zero, the solver class driven
by hand), then what is the march's own: its nodes bit for bit, its failure as the result's
status and message, the arguments refused by name, and the same motion in other units."""

import math
import warnings

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from ddvp_nlp import DDVP, HamiltonianSystem, Output, StepControl, load_scene, march

HARMONIC = load_scene("harmonic").system  # H = (p^2 + w^2 q^2) / 2, w = 1
HENON = load_scene("henon_heiles").system


def harmonic_field(t, y):
    return [y[1], -y[0]]


def henon_field(t, y):
    q1, q2, p1, p2 = y
    return [p1, p2, -q1 - 2 * q1 * q2, -q2 - q1**2 + q2**2]


def scaled_pendulum(q, p, t, a):
    """The pendulum in a time unit ``a`` times shorter: ``H / a``."""
    return (p[0] ** 2 / 2 + 1 - ca.cos(q[0])) / a


SCALED = HamiltonianSystem(scaled_pendulum, 1, {"a": 1.0}, name="scaled_pendulum")


def harmonic_run(t_span=(0.0, 10.0), **options):
    return solve_ivp(harmonic_field, t_span, [1.0, 0.0], method=DDVP,
                     **{"hamiltonian": HARMONIC, "tau0": 0.01, **options})


def nodes(solution):
    return np.hstack([solution.q, solution.p])


def test_the_result_has_scipys_fields_and_ends_on_t_bound():
    result = harmonic_run(dense_output=True)
    assert result.success and result.status == 0
    assert result.message == "The solver successfully reached the end of the integration " \
                             "interval."
    assert result.t[0] == 0.0 and result.t[-1] == 10.0 and np.all(np.diff(result.t) > 0)
    assert result.y.shape == (2, result.t.size)
    assert result.t_events is None and result.y_events is None
    # fun is called once, to check it against H; no Jacobian, no LU
    assert (result.nfev, result.njev, result.nlu) == (1, 0, 0)
    # scipy's check: the dense output at the nodes gives the nodes
    np.testing.assert_allclose(result.sol(result.t), result.y, rtol=0, atol=1e-15)
    assert harmonic_run().sol is None


def test_nodes_are_the_marchs_bit_for_bit_across_chunks_and_the_dense_output_is_its_at():
    """Henon-Heiles over about 16 chunks of 300 steps (32 before: a chunk boundary is a
    chunk boundary, and the nodes are compared bit for bit at each): every node but the last
    (which ends on t_bound, the dense output's state there) is march's own; between the nodes
    the dense output is ``Solution.at``'s cubic."""
    y0 = [0.0, 0.1, 0.35, 0.0]
    marched = march(HENON, y0[:2], y0[2:], (0.0, 100.0), tau0=0.02)
    result = solve_ivp(henon_field, (0.0, 100.0), y0, method=DDVP, hamiltonian=HENON,
                       tau0=0.02, chunk_steps=300, dense_output=True)
    assert result.success
    assert result.t.size == marched.t.size > 10 * 300
    assert np.array_equal(result.t[:-1], marched.t[:-1])
    assert np.array_equal(result.y.T[:-1], nodes(marched)[:-1])
    q, p = marched.at(100.0)
    np.testing.assert_allclose(result.y[:, -1], np.concatenate([q, p]), rtol=0, atol=1e-15)
    between = (marched.t[:-2] + marched.t[1:-1]) / 2
    q, p = marched.at(between)
    np.testing.assert_allclose(result.sol(between).T, np.hstack([q, p]), rtol=0, atol=1e-15)


def test_t_eval_gives_the_dense_outputs_states_there():
    times = np.linspace(0.0, 10.0, 41)
    result = harmonic_run(t_eval=times)
    marched = march(HARMONIC, [1.0], [0.0], (0.0, 10.0), tau0=0.01,
                    output=Output(t_eval=times))
    assert np.array_equal(result.t, times)
    np.testing.assert_allclose(result.y.T, marched.z_eval, rtol=0, atol=1e-14)


def test_a_backward_span_runs_backwards_as_the_backward_march():
    result = harmonic_run((0.0, -10.0), dense_output=True)
    marched = march(HARMONIC, [1.0], [0.0], (0.0, -10.0), tau0=0.01)
    assert result.success and result.t[-1] == -10.0 and np.all(np.diff(result.t) < 0)
    assert np.array_equal(result.t[:-1], marched.t[:-1])
    assert np.array_equal(result.y.T[:-1], nodes(marched)[:-1])
    # q = cos t, p = -sin t, to the scheme's accuracy at tau = 0.01
    np.testing.assert_allclose(result.y[:, -1], [math.cos(10.0), math.sin(10.0)], atol=1e-3)
    assert result.sol(-5.0).shape == (2,)


def test_a_span_of_length_zero_returns_the_start():
    """scipy's test_no_integration: nothing is marched, the dense output is the start."""
    result = harmonic_run((4.0, 4.0), dense_output=True)
    assert result.success and np.array_equal(result.t, [4.0, 4.0])  # as scipy's methods
    np.testing.assert_array_equal(result.sol(4.0), [1.0, 0.0])
    np.testing.assert_array_equal(result.sol([4.0, 5.0]), [[1.0, 1.0], [0.0, 0.0]])


def test_the_zero_crossings_of_q_are_found_to_the_dense_outputs_accuracy():
    """q = cos t on the harmonic oscillator: its zeros at pi/2 + k pi, found by scipy's event
    machinery on the Hermite dense output, within twice that output's own error (|q'| = 1
    there); a terminal event going down stops at the first."""
    def crossing(t, y):
        return y[0]

    result = harmonic_run(events=crossing, dense_output=True)
    fine = np.linspace(0.0, 10.0, 4001)
    dense_error = np.max(np.abs(result.sol(fine) - [np.cos(fine), -np.sin(fine)]))
    assert 0 < dense_error < 1e-3
    exact = np.pi / 2 + np.pi * np.arange(3)
    np.testing.assert_allclose(result.t_events[0], exact, rtol=0, atol=2 * dense_error)
    assert np.max(np.abs(result.y_events[0][:, 0])) < 1e-12

    crossing.terminal, crossing.direction = True, 1  # q rises through 0 at 3 pi / 2 first
    stopped = harmonic_run(events=crossing)
    assert stopped.status == 1 and stopped.success
    assert stopped.t_events[0].size == 1 and stopped.t[-1] == stopped.t_events[0][0]
    assert abs(stopped.t[-1] - 3 * np.pi / 2) <= 2 * dense_error


def test_the_solver_class_driven_by_hand_keeps_scipys_rules():
    """scipy's test_classes: the attributes before and after a step."""
    solver = DDVP(harmonic_field, 0.0, [1.0, 0.0], 1.0, hamiltonian=HARMONIC, tau0=0.1)
    assert (solver.n, solver.status, solver.t_bound, solver.direction, solver.t) == \
        (2, "running", 1.0, 1.0, 0.0)
    assert solver.step_size is None and solver.solution is None
    assert solver.step() is None
    assert solver.status == "running" and solver.t == pytest.approx(0.1, abs=1e-15)
    assert solver.step_size == solver.t
    dense = solver.dense_output()
    np.testing.assert_array_equal(dense(solver.t), solver.y)
    np.testing.assert_array_equal(dense(0.0), [1.0, 0.0])
    while solver.status == "running":
        solver.step()
    assert solver.status == "finished" and solver.t == 1.0
    with pytest.raises(RuntimeError):
        solver.step()


def test_a_failed_march_is_a_failed_result_with_the_marchs_message():
    """max_steps reached in the third chunk: the nodes the march accepted, success False,
    the march's own sentence (its step count, not the chunk's)."""
    y0 = [0.0, 0.1, 0.35, 0.0]
    steps = StepControl(max_steps=700)
    marched = march(HENON, y0[:2], y0[2:], (0.0, 200.0), tau0=0.02, steps=steps)
    result = solve_ivp(henon_field, (0.0, 200.0), y0, method=DDVP, hamiltonian=HENON,
                       tau0=0.02, chunk_steps=300, steps=steps)
    assert not result.success and result.status == -1
    assert result.message == marched.message
    assert result.message.startswith("max_steps was reached before t_end: step 700 from")
    assert np.array_equal(result.t, marched.t)
    # a march that fails at its first step: no success with zero steps
    first = harmonic_run(steps=StepControl(max_steps=1), chunk_steps=2)
    assert not first.success and first.t.size == 2


BAD = [
    ({"hamiltonian": None}, r"method=DDVP needs hamiltonian="),
    ({"hamiltonian": 3}, r"hamiltonian must be a HamiltonianSystem or a function"),
    ({"hamiltonian": "H"}, r"hamiltonian must be a HamiltonianSystem or a function"),
    ({"n": 2}, r"n = 2 differs from the hamiltonian's n = 1"),
    ({"tau0": -1.0}, r"tau0 must be > 0, got -1\.0"),
    ({"tau0": 0}, r"tau0 must be > 0, got 0"),
    ({"tau0": math.nan}, r"tau0 must be finite"),
    ({"tau0": "0.1"}, r"tau0 must be a real number"),
    ({"scheme": "rk4"}, r"rk4"),
    ({"scheme": 3}, r"scheme must be a name or a Scheme"),
    ({"params": {"omega": 2.0}}, r"omega"),
    ({"chunk_steps": 1}, r"chunk_steps must be an integer >= 2, got 1"),
    ({"chunk_steps": 2.5}, r"chunk_steps must be"),
    ({"rtol": 1e-16, "atol": 1e-16, "tau0": None},
     r"rtol = 1e-16, atol = 1e-16 ask for a trajectory error rtol \+ atol / \|y0\| = 2e-16"),
    ({"rtol": -1.0, "tau0": None}, r"rtol must be > 0"),
]


@pytest.mark.parametrize("options, message", BAD)
def test_bad_arguments_are_refused_by_name(options, message):
    """By the solver's constructor: the march runs only at the first step."""
    with pytest.raises(ValueError, match=message):
        harmonic_run(**options)


@settings(max_examples=10, deadline=None)
@given(st.one_of(st.floats(max_value=0.0), st.sampled_from([math.inf, -math.inf, math.nan])))
def test_a_first_step_that_is_not_positive_and_finite_is_refused(tau0):
    with pytest.raises(ValueError, match=r"^tau0 must be (> 0|finite), got"):
        DDVP(harmonic_field, 0.0, [1.0, 0.0], 1.0, hamiltonian=HARMONIC, tau0=tau0)


@settings(max_examples=6, deadline=None)
@given(st.sampled_from([
    (lambda t, y: [y[1], -2 * y[0]], r"fun and hamiltonian disagree at \(t0, y0\)"),
    (lambda t, y: [y[1], -y[0] * (1 + 1e-6)], r"fun and hamiltonian disagree"),
    (lambda t, y: [y[1]], r"fun\(t0, y0\) must have the shape of y0, \(2,\), got \(1,\)"),
    (lambda t, y: [math.nan, -y[0]], r"fun and hamiltonian disagree"),
]))
def test_a_fun_that_is_not_the_hamiltonians_field_is_refused(case):
    fun, message = case
    with pytest.raises(ValueError, match=message):
        solve_ivp(fun, (0.0, 1.0), [1.0, 0.0], method=DDVP, hamiltonian=HARMONIC, tau0=0.1)
    with pytest.raises(ValueError, match=r"y0 must be \(q, p\) stacked, of length 2n = 2, "
                                         r"got length 3"):
        solve_ivp(lambda t, y: y, (0.0, 1.0), [1.0, 0.0, 0.0], method=DDVP,
                  hamiltonian=HARMONIC, tau0=0.1)


def test_a_function_h_with_its_n_and_a_fun_agreeing_to_round_off_are_taken():
    def hamiltonian(q, p, t):
        return (p[0] ** 2 + q[0] ** 2) / 2

    result = solve_ivp(lambda t, y: [y[1] * (1 + 1e-12), -y[0]], (0.0, 1.0), [1.0, 0.0],
                       method=DDVP, hamiltonian=hamiltonian, n=1, tau0=0.1)
    assert result.success and result.t[-1] == 1.0


def test_rtol_and_atol_are_a_target_error_without_tau0_and_unused_with_it():
    solver = DDVP(harmonic_field, 0.0, [1.0, 0.0], 10.0, hamiltonian=HARMONIC, rtol=1e-4)
    assert solver.target_error == pytest.approx(1e-4 + 1e-6)  # atol / |y0| with |y0| = 1
    # the derived first step: 1e-2 of the start's time scale |y0| / |f(t0, y0)| = 1
    assert solver.tau0 == pytest.approx(1e-2)
    assert DDVP(harmonic_field, 0.0, [1.0, 0.0], 10.0, hamiltonian=HARMONIC).target_error is None
    with pytest.warns(UserWarning, match=r"rtol and atol not used by DDVP: tau0 = 0\.1 sets"):
        DDVP(harmonic_field, 0.0, [1.0, 0.0], 10.0, hamiltonian=HARMONIC, tau0=0.1, rtol=1e-6,
             atol=1e-9)
    with pytest.raises(ValueError, match=r"tau0 cannot be derived from the start"):
        DDVP(harmonic_field, 0.0, [0.0, 0.0], 10.0, hamiltonian=HARMONIC)


def test_a_target_error_from_rtol_is_reached():
    result = solve_ivp(harmonic_field, (0.0, 10.0), [1.0, 0.0], method=DDVP,
                       hamiltonian=HARMONIC, rtol=1e-4, dense_output=True)
    fine = np.linspace(0.0, 10.0, 1001)
    assert result.success
    assert np.max(np.abs(result.sol(fine) - [np.cos(fine), -np.sin(fine)])) < 2e-4


def test_options_without_effect_are_warned_about_as_scipy_does():
    with pytest.warns(UserWarning, match=r"no effect for a chosen solver: `first_step`, "
                                         r"`jac`\.$"):
        harmonic_run((0.0, 0.5), first_step=0.1, jac=lambda t, y: None)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the options it knows warn about nothing
        harmonic_run((0.0, 0.5), scheme="lee", params={"w": 1.0}, chunk_steps=10)


@settings(max_examples=6, deadline=None)
@given(st.floats(min_value=1e-3, max_value=1e3))
def test_the_same_motion_in_another_time_unit_is_the_same_trajectory(a):
    """``t' = a t`` and ``H' = H / a`` (so that ``dq/dt' = H'_p``) with ``tau0' = a tau0``:
    the nodes are the first run's, times scaled by ``a``, to round-off."""
    def fun(scale):
        return lambda t, y: [y[1] / scale, -math.sin(y[0]) / scale]

    y0 = [1.0, 0.3]
    one = solve_ivp(fun(1.0), (0.0, 10.0), y0, method=DDVP, hamiltonian=SCALED, tau0=0.05)
    other = solve_ivp(fun(a), (0.0, 10.0 * a), y0, method=DDVP, hamiltonian=SCALED,
                      params={"a": a}, tau0=0.05 * a)
    assert one.success and other.success
    assert other.t.size == one.t.size
    np.testing.assert_allclose(other.t / a, one.t, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(other.y, one.y, rtol=0, atol=1e-8)


def test_a_drifted_trajectory_is_said_not_hidden_behind_success():
    """``solve_ivp(method=DDVP)`` returned plain success on a spherical pendulum whose march
    the check finds drifted at t = 11.48 (a new user's trial): the drift is a warning with its
    time."""
    system = HamiltonianSystem(lambda q, p, t: p[0] ** 2 / 2 + p[1] ** 2 / (2 * ca.sin(q[0]) ** 2)
                               - ca.cos(q[0]), 2, angles=("q2",))
    y0 = [2.0, 0.0, 0.0, 1.2]

    def field(t, y):
        theta, _, p_theta, p_phi = y
        s = math.sin(theta)
        return [p_theta, p_phi / s**2, p_phi**2 * math.cos(theta) / s**3 - s, 0.0]
    with pytest.warns(RuntimeWarning, match=r"drifted from t = 11\.48"):
        result = solve_ivp(field, (0.0, 50.0), y0, method=DDVP, hamiltonian=system, tau0=0.05)
    assert result.success
