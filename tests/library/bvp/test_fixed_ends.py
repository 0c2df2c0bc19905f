"""Fixed-endpoint problems: one NLP over the whole grid, verified by its own residuals."""

import functools
import json
import re

import numpy as np
import pytest
from helpers.common import fitted_order
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from ddvp_nlp import (
    GridOptions,
    InputError,
    Scheme,
    Status,
    Tolerance,
    load_scene,
    march,
    solve_bvp,
)
from ddvp_nlp.cli import main


@functools.cache
def _marched(name, tau0, t_end, rule):
    """The march whose ends and nodes both solvers are given: marched once for the two (read
    only)."""
    return march(load_scene(name).system, [0.5], [0.5], (0.0, t_end), tau0=tau0, scheme=rule)


@pytest.mark.slow_when(
    lambda solver, name, tau0, **_: solver == "ipopt" and name == "paper_pendulum" and tau0 == 0.5,
    why="repetition")
# IPOPT on the pendulum repeats IPOPT on paper_pendulum at tau0 = 0.1 (both rules) and Newton on
# the pendulum (both rules), all in the default run; IPOPT's and Newton's nodes on the pendulum
# are compared by test_ipopt_assembly.py's test_ipopt_and_newton_return_the_same_nodes (vddvp)
# and test_interleaved_system.py's test_newton_and_ipopt_return_the_same_nodes (fixed)
@pytest.mark.slow_when(lambda solver, name, **_: solver == "ipopt" and name == "pendulum",
                       why="repetition")
@pytest.mark.parametrize("name, tau0, t_end", [("paper_pendulum", 0.5, 9.0),
                                                ("paper_pendulum", 0.1, 9.0),
                                                ("pendulum", 0.05, 9.0)])
@pytest.mark.parametrize("rule", ["vddvp", "lee"])
@pytest.mark.parametrize("solver", ["ipopt", "newton"])
def test_endpoints_of_a_march_give_back_its_nodes(name, tau0, t_end, rule, solver):
    """From the default start (no guess), with the march's endpoints and node count. The
    coarse grid (paper_pendulum, tau0 = 0.5: 19 nodes over 9 time units) is some 8% off the
    continuous solution through the same ends: with both ends fixed that is ``inaccurate``
    (the march from the same start is ``drifted``: it loses phase), so its verdict is recorded
    and the status kept (``stop=False``) to compare the nodes."""
    system = load_scene(name).system
    marched = _marched(name, tau0, t_end, rule)
    assert marched.success and 20 <= marched.t.size <= 300
    solved = solve_bvp(
        system,
        marched.q[0],
        marched.q[-1],
        (marched.t[0], marched.t[-1]),
        nodes=marched.t.size,
        scheme=rule,
        options=GridOptions(solver=solver, accuracy=Tolerance(stop=False)),
    )
    assert solved.success, solved.message
    coarse = tau0 == 0.5
    assert solved.verdict.name == ("inaccurate" if coarse else "accurate")
    assert marched.verdict.name == ("drifted" if coarse else "accurate")
    assert np.max(np.abs(solved.t - marched.t)) < 1e-8
    assert np.max(np.abs(solved.q - marched.q)) < 1e-8
    assert np.max(np.abs(solved.p - marched.p)) < 1e-8
    assert np.all(solved.tau > 0)


def shooting_reference(q_start, q_end, T):
    """The continuous pendulum's fixed-endpoint solution by shooting with DOP853 at rtol 1e-13."""
    def flow(p0):
        return solve_ivp(lambda t, y: [y[1], -np.sin(y[0])], (0.0, T), [q_start, p0],
                         method="DOP853", rtol=1e-13, atol=1e-13, dense_output=True)
    p0 = brentq(lambda p0: flow(p0).y[0, -1] - q_end, 0.3, 0.7, xtol=1e-15)
    return flow(p0).sol


def test_fixed_steps_converge_with_order_two_to_the_continuous_solution():
    q_start, q_end, T = 0.5, -0.036, 9.0
    reference = shooting_reference(q_start, q_end, T)
    system = load_scene("pendulum").system
    sizes, errors = [], []
    for nodes in (51, 101, 201, 401):
        solution = solve_bvp(system, [q_start], [q_end], (0.0, T), nodes=nodes,
                             scheme="fixed")
        assert solution.success, solution.message
        exact = reference(solution.t)
        errors.append(max(np.max(np.abs(solution.q[:, 0] - exact[0])),
                          np.max(np.abs(solution.p[:, 0] - exact[1]))))
        sizes.append(T / (nodes - 1))
    assert 1.9 < fitted_order(sizes, errors) < 2.1, errors


def test_lee_and_vddvp_agree_on_an_autonomous_scene():
    scene = load_scene("pendulum")
    data = scene.resolve_boundary()
    solutions = [
        solve_bvp(
            scene.system,
            data.q_start,
            data.q_end,
            (data.t_span[0], data.t_span[1]),
            nodes=data.nodes,
            scheme=rule,
        )
        for rule in ("vddvp", "lee")
    ]
    assert all(s.success for s in solutions)
    assert np.max(np.abs(solutions[0].t - solutions[1].t)) < 1e-10
    assert np.max(np.abs(solutions[0].q - solutions[1].q)) < 1e-10


# IPOPT on the fixed rule runs to its iteration limit as on vddvp (the default run's ipopt
# case), and the fixed rule is refused as well by Newton (the default run's newton-fixed case)
@pytest.mark.slow_when(lambda rule, solver, **_: rule == "fixed" and solver == "ipopt",
                       why="repetition")
@pytest.mark.parametrize("rule", ["fixed", "vddvp"])
@pytest.mark.parametrize("solver", ["ipopt", "newton"])
def test_unreachable_endpoints_end_with_a_status_and_residuals(rule, solver):
    """M midpoint steps of h = 2 tan(pi/2M) turn the harmonic oscillator by exactly pi, so
    q_M = -q_0 whatever the momentum: q_end = 0.5 from q_0 = 1 cannot be reached."""
    M = 20
    h = 2 * np.tan(np.pi / (2 * M))
    system = load_scene("harmonic").system
    solution = solve_bvp(system, [1.0], [0.5], (0.0, M * h), nodes=M + 1, scheme=rule,
                         options=GridOptions(solver=solver))
    assert not solution.success
    # INACCURATE: Newton on the fixed rule runs off to |p| ~ 1e15, where the rows are at their
    # round-off (relative to the point, as every row's limit is); the accuracy check refuses it
    assert solution.status in (Status.SOLVER_FAILED, Status.NOT_VERIFIED,
                               Status.NO_ADMISSIBLE_STEP, Status.INACCURATE)
    assert solution.t.size == M + 1 and solution.q.shape == (M + 1, 1)
    # no point holds every row: the canonical or, with released times, the energy rows stay
    # off (IPOPT on the scaled rows ends "Infeasible_Problem_Detected" with the energy rows off)
    assert max(solution.ends.canonical_residual_max,
               solution.ends.energy_residual_max or 0.0) > 1e-3
    assert solution.canonical_residual.shape == (M,)


@pytest.mark.parametrize("solver, said", [("ipopt", r"ipopt: Maximum_Iterations_Exceeded"),
                                         ("newton", r"newton: max_iter = 1 reached, residual "
                                                    r"norm \S+")])
def test_solver_failure_keeps_the_last_iterate_and_says_why(solver, said):
    scene = load_scene("pendulum")
    data = scene.resolve_boundary()
    solution = solve_bvp(
        scene.system,
        data.q_start,
        data.q_end,
        (data.t_span[0], data.t_span[1]),
        nodes=data.nodes,
        options=GridOptions(solver=solver, max_iter=1),
    )
    assert solution.status is Status.SOLVER_FAILED
    assert re.match(r"the NLP solver did not converge \(" + said + r"\); "
                    r"canonical residual \S+ on interval \d+", solution.message)
    assert solution.t.size == data.nodes and np.all(np.isfinite(solution.q))


def test_verification_rejects_a_converged_point_above_the_tolerance():
    """The solver's convergence flag is not enough: one residual of 2e-9 against tol = 1e-9 on
    an otherwise solved grid gives NOT_VERIFIED, naming the interval."""
    scene = load_scene("pendulum")
    data = scene.resolve_boundary()
    solution = solve_bvp(
        scene.system,
        data.q_start,
        data.q_end,
        (data.t_span[0], data.t_span[1]),
        nodes=data.nodes,
        options=GridOptions(tol=1e-9),
    )
    assert solution.success
    from ddvp_nlp.solvers.bvp.fixed_ends import _verify
    from ddvp_nlp.solvers.grid.policy import Stage

    phase = Stage("vddvp equations", "ipopt", True, "Solve_Succeeded", 3)
    canonical = np.zeros((data.nodes - 1, 2))
    canonical[17, 1] = 2e-9
    status, message = _verify(phase, solution.t, canonical, solution.energy_residual,
                              Scheme("vddvp"), (np.full(2, 1e-9), 0.05e-9), {})
    assert status is Status.NOT_VERIFIED
    assert message.startswith("the solver's point does not satisfy the equations to the "
                              "tolerance: canonical residual 2.000e-09 on interval 17")
    assert message.endswith("(ipopt: Solve_Succeeded)")


def test_bad_input_is_refused_before_building():
    system = load_scene("pendulum").system
    with pytest.raises(InputError, match=r"^nodes must be an integer >= 3, got 2$"):
        solve_bvp(system, [0.5], [0.1], (0.0, 1.0), nodes=2)
    with pytest.raises(InputError, match=r"^t_end must be > t0 = 1\.0, got 0\.0$"):
        solve_bvp(system, [0.5], [0.1], (1.0, 0.0), nodes=10)
    with pytest.raises(InputError, match=r"^q_end must be finite, got \[nan\]$"):
        solve_bvp(system, [0.5], [np.nan], (0.0, 1.0), nodes=10)
    with pytest.raises(InputError,
                       match=r"^unknown solver 'snopt' \(choose from auto, newton, ipopt\)$"):
        solve_bvp(system, [0.5], [0.1], (0.0, 1.0), nodes=10, options=GridOptions(solver="snopt"))
    with pytest.raises(InputError, match=r"^guess\['q'\] must have shape \(10, 1\), got \(9, 1\)$"):
        solve_bvp(system, [0.5], [0.1], (0.0, 1.0), nodes=10,
                  guess={"t": np.linspace(0, 1, 10), "q": np.zeros((9, 1)),
                         "p": np.zeros((10, 1))})


def test_cli_bvp_writes_the_same_outputs(tmp_path, capsys):
    out = tmp_path / "bvp"
    assert main(["bvp", "paper_pendulum", "--nodes", "61", "--out", str(out)]) == 0
    meta = json.loads((out / "meta.json").read_text())
    assert meta["command"] == "bvp" and meta["success"] and meta["steps"] == 60
    assert meta["params"]["nodes"] == 61 and meta["solver"]["solver"] == "newton"
    assert np.load(out / "result.npz")["t"].shape == (61,)
    assert (out / "trajectory.png").exists()
    assert "paper_pendulum bvp [vddvp]: success" in capsys.readouterr().out


def test_cli_bvp_without_endpoint_data_says_what_to_give(tmp_path, capsys):
    assert main(["bvp", "kepler", "--out", str(tmp_path)]) == 2
    assert ("scene 'kepler' declares no fixed-endpoint data: give q_start, q_end, t0 and t_end "
            "(--set NAME=VALUE) and --nodes") in capsys.readouterr().err
    assert main(["bvp", "kepler", "--set", "q_start=0.5,0", "--set", "q_end=-0.5,0.5",
                 "--set", "t_end=2", "--nodes", "201", "--out", str(tmp_path), "--no-plot"]) == 0
