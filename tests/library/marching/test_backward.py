"""Backward integration (issue 40): ``march`` with ``t_end < t0`` runs backwards in time, as
scipy's ``solve_ivp`` does, by the time reversal ``H(q, -p, -t)`` (solvers/marching/backward.py).
Judged against scipy's DOP853 run backwards on the original vector field (independent of the
reversal) and against the forward march it undoes."""

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from ddvp_nlp import HamiltonianSystem, InputError, Output, load_scene, march

HARMONIC = load_scene("harmonic")


def driven_pendulum(q, p, t, eps):
    return p[0] ** 2 / 2 + (1 - ca.cos(q[0])) * (1 - eps * ca.sin(2 * t))


DRIVEN = HamiltonianSystem(driven_pendulum, 1, {"eps": 0.3}, name="driven")
PAPER = load_scene("paper_pendulum").system


def truth(system, z0, t_span, times, theta):
    """scipy's DOP853 on ``(H_p, -H_q)`` of ``system`` itself, from ``t_span[0]``."""
    z, t = ca.SX.sym("z", 2), ca.SX.sym("t")
    H = system.H_function(z[0], z[1], t, theta)
    f = ca.Function("f", [t, z], [ca.vertcat(ca.gradient(H, z[1]), -ca.gradient(H, z[0]))])
    run = solve_ivp(lambda s, y: np.asarray(f(s, y)).ravel(), t_span, z0, method="DOP853",
                    rtol=1e-12, atol=1e-12, dense_output=True)
    return run.sol(times).T


def relative_error(solution, exact):
    scale = np.asarray(solution.verdict.scale)
    return np.max(np.abs(np.hstack([solution.q, solution.p]) - exact) / scale)


@pytest.mark.slow_when(lambda scheme, **_: scheme != "fixed", why="repetition")
@pytest.mark.parametrize("system, scheme", [(DRIVEN, "lee"), (DRIVEN, "fixed"),
                                            (PAPER, "vddvp")], ids=["lee", "fixed", "vddvp"])
def test_a_time_dependent_march_backwards_follows_the_exact_flow(system, scheme):
    """The nodes against scipy's backward run within the verdict's own error; times decrease
    from t0 to t_end, steps are negative, the verdict's times are in t. (vddvp on the paper's
    slowly driven pendulum: on DRIVEN its steps run away forwards too, theory section 8.)"""
    theta = system.parameter_vector()
    solution = march(system, [0.4], [0.2], (6.0, 1.0), tau0=0.01, scheme=scheme)
    assert solution.success, solution.message
    assert solution.t[0] == 6.0 and solution.t[-1] <= 1.0 and np.all(solution.tau < 0)
    report = solution.verdict.as_dict()
    assert report["verdict"] == "accurate"
    exact = truth(system, [0.4, 0.2], (6.0, 0.5), solution.t, theta)
    assert relative_error(solution, exact) <= 1.5 * report["error_max"] + 1e-9
    assert "t_end = 1 " in solution.message + " "
    # H at the nodes is H(q, p, t) of the system asked for, in its own signs
    assert np.allclose(solution.energy(), [float(system.H_function(q, p, t, theta))
                                           for q, p, t in zip(solution.q[:, 0],
                                                              solution.p[:, 0], solution.t,
                                                              strict=True)])


def test_forward_then_backward_returns_to_the_start():
    forward = march(DRIVEN, [0.4], [0.2], (0.0, 5.0), tau0=0.01, scheme="lee")
    q1, p1 = forward.at_end()
    back = march(DRIVEN, q1, p1, (5.0, 0.0), tau0=0.01, scheme="lee")
    assert back.success and forward.success
    scale = np.asarray(forward.verdict.scale)
    q0, p0 = back.at_end()
    error = np.max(np.abs(np.concatenate([q0 - 0.4, p0 - 0.2])) / scale)
    bound = forward.verdict.error_max + back.verdict.error_max
    assert error <= 1.5 * bound + 1e-9, (error, bound)


def test_output_times_and_events_backwards():
    """t_eval sorted in decreasing order (scipy's rule for a backward run) and events in the
    original time and signs; increasing t_eval is refused by name."""
    def q_zero(t, q, p):
        return q[0]
    q_zero.terminal = False
    times = np.linspace(10.0, 2.0, 5)
    solution = march(HARMONIC.system, [1.0], [0.0], (10.0, 2.0), tau0=0.005,
                     output=Output(t_eval=times, events=q_zero))
    assert np.array_equal(solution.t_eval, times)
    exact_q = np.cos(times - 10.0)
    assert np.max(np.abs(solution.z_eval[:, 0] - exact_q)) < 1e-3
    assert np.max(np.abs(solution.z_eval[:, 1] + np.sin(times - 10.0))) < 1e-3
    # q = cos(t - 10) crosses zero at t = 10 - pi/2 - k pi inside [2, 10]
    expected = 10 - np.pi / 2 - np.pi * np.arange(3)
    assert np.allclose(solution.t_events[0], expected, atol=1e-4)
    assert np.allclose(np.abs(solution.z_events[0][:, 1]), 1.0, atol=1e-3)
    with pytest.raises(InputError, match="sorted in decreasing order for a backward"):
        march(HARMONIC.system, [1.0], [0.0], (10.0, 2.0), tau0=0.005,
              output=Output(t_eval=[2.0, 3.0]))
    with pytest.raises(InputError, match="t_eval must lie in t_span"):
        march(HARMONIC.system, [1.0], [0.0], (10.0, 2.0), tau0=0.005,
              output=Output(t_eval=[11.0, 3.0]))


@settings(max_examples=12, deadline=None, derandomize=True)
@given(t0=st.floats(-20, 20), length=st.floats(0.2, 4.0), tau0=st.sampled_from([0.01, 0.02]))
def test_random_backward_spans_on_the_exact_solution(t0, length, tau0):
    """The harmonic oscillator from (1, 0) at t0 backwards to t0 - length: q = cos(t - t0),
    p = -sin(t - t0); at_end lands on t_end; the verdict's error bounds the true one."""
    t_end = t0 - length
    solution = march(HARMONIC.system, [1.0], [0.0], (t0, t_end), tau0=tau0)
    assert solution.success, solution.message
    assert solution.t[0] == t0 and solution.t[-1] <= t_end + 1e-12
    exact = np.column_stack([np.cos(solution.t - t0), -np.sin(solution.t - t0)])
    report = solution.verdict.as_dict()
    assert relative_error(solution, exact) <= 1.5 * report["error_max"] + 1e-9
    q, p = solution.at_end()
    assert abs(q[0] - np.cos(length)) < 1e-3 and abs(p[0] - np.sin(length)) < 1e-3


def test_the_command_line_marches_backwards(tmp_path, capsys):
    """`ddvp march SCENE --set t0=20 --set t_end=0`: a backward run folder, its verdict against
    the scene's exact solution read in t (accurate: before the reversal of the exact solution
    it had read 'drifted'), its figure drawn; --resume refuses it by name."""
    from ddvp_nlp.cli import main

    out = tmp_path / "back"
    code = main(["march", "pendulum", "--set", "t0=20", "--set", "t_end=0", "--out", str(out),
                 "--t-eval", "20:0:5", "--no-progress"])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    assert "success - reached t_end = 0 in" in printed.out and "verdict: accurate" in printed.out
    data = np.load(out / "result.npz")
    assert data["t"][0] == 20.0 and np.all(np.diff(data["t"]) < 0)
    assert np.array_equal(data["t_eval"], np.linspace(20, 0, 5))
    assert (out / "trajectory.png").stat().st_size > 0
    assert main(["march", "--resume", str(out), "--t-end", "-5", "--no-plot"]) == 2
    assert "marched backwards" in capsys.readouterr().err


# -- the compared methods (issue 45): backwards too, never "success" with no step -----------------

COMPARED = [m for m in __import__("ddvp_nlp.solvers", fromlist=["INTEGRATORS"]).INTEGRATORS
            if not m.reverses_itself and m.name != "lee_left"  # lee_left: stops on any swing
            and m.name not in ("rattle", "shake")]  # constrained systems only: test_rattle.py


def _driven_config(t0, t_end):
    from types import SimpleNamespace
    return SimpleNamespace(q0=np.array([0.8]), p0=np.array([0.3]), v0=None, t0=t0,
                           t_end=t_end, params={"eps": 0.3}, tau0=None)


@pytest.mark.parametrize("method", COMPARED, ids=lambda m: m.name)
def test_every_compared_method_marches_backwards_at_its_order(method):
    """A time-dependent system marched from t0 = 1.5 back to -1.5 (never a grid point of the
    forward run): the nodes go down in time to t_end, the end state converges to scipy's
    DOP853 run backwards on the original field at the method's own order (or, for DOP853,
    within a hundred times its tolerance). Before, every compared method returned success
    with zero steps and t left at t0."""
    config = _driven_config(1.5, -1.5)
    theta = DRIVEN.parameter_vector(config.params)
    exact = truth(DRIVEN, [0.8, 0.3], (1.5, -1.5), [-1.5], theta)[0]
    values = [1e-6, 1e-8] if method.knob == "rtol" else [0.02, 0.01]
    errors = []
    for value in values:
        solution = method.run(DRIVEN, config, value, compiler=None, cache_dir=None,
                              max_steps=10**6)
        assert solution.success, solution.message
        assert solution.t.size > 2 and solution.t[-1] == -1.5 and np.all(np.diff(solution.t) < 0)
        errors.append(np.max(np.abs(np.r_[solution.q[-1], solution.p[-1]] - exact)))
    if method.knob == "rtol":
        assert errors[-1] < 100 * values[-1], errors
    else:
        order = np.log2(errors[0] / errors[1])
        assert abs(order - method.order) < 0.3, (errors, order)
