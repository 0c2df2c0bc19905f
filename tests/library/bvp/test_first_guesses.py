"""Starts of the fixed-endpoint solve (issue 16, item 5): the predicted times, a node guess of
another rule or size, shooting from a given momentum, and the diagnosis of a branch on which the
energy rules have no solution. Kepler e = 0.5 over three periods from the pericentre: the
straight line leads to the radial branch, the orbit's momentum to the three revolutions."""

import functools
import json

import numpy as np
import pytest

from ddvp_nlp import GridOptions, InputError, Shooting, StepControl, load_scene, march, solve_bvp
from ddvp_nlp.cli import main

E = 0.5
PERIODS = 3.0
Q0 = [1 - E, 0.0]
P0 = [0.0, np.sqrt((1 + E) / (1 - E))]


@functools.cache
def kepler(nodes):
    """The system, its fixed-step march over three periods on ``nodes`` nodes, and the march's
    end (the fixed-endpoint data); marched once for every test of that size (read only)."""
    system = load_scene("kepler").system
    T = 2 * np.pi * PERIODS
    marched = march(system, Q0, P0, (0.0, T), tau0=T / (nodes - 1), scheme="fixed",
                    params={"e": E}, steps=StepControl(max_steps=nodes))
    assert marched.success and marched.t.size == nodes
    return system, marched


def revolutions(solution) -> float:
    angle = np.unwrap(np.arctan2(solution.q[:, 1], solution.q[:, 0]))
    return float((angle[-1] - angle[0]) / (2 * np.pi))


def test_a_fixed_step_march_as_guess_is_moved_to_the_predicted_times_first():
    """Released directly from the fixed-step march, Newton needed 56 damped iterations; the
    old prediction (tau_k ~ w_k^(-1/3) of the old grid's interval k) 44; the predicted times by
    the integral of w^(1/3) leave a handful."""
    system, marched = kepler(1000)
    solution = solve_bvp(system, Q0, marched.q[-1], (0.0, marched.t[-1]), nodes=1000,
                         params={"e": E}, guess=marched, options=GridOptions(solver="newton"))
    assert solution.success, solution.message
    names = [ph.name for ph in solution.ends.stages]
    assert names == ["fixed steps, predicted times (from the guess)", "vddvp equations"]
    assert solution.ends.stages[-1].iterations <= 8
    assert revolutions(solution) == pytest.approx(3.0, abs=0.05)


def test_a_guess_that_already_solves_the_equations_is_taken_as_it_is():
    system = load_scene("kepler").system
    marched = march(system, Q0, P0, (0.0, 2.0), tau0=0.02, params={"e": E})
    assert marched.success
    solution = solve_bvp(
        system,
        Q0,
        marched.q[-1],
        (0.0, marched.t[-1]),
        nodes=marched.t.size,
        params={"e": E},
        guess=marched,
        options=GridOptions(solver="newton"),
    )
    assert solution.success, solution.message
    assert [ph.name for ph in solution.ends.stages] == ["vddvp equations"]
    assert np.max(np.abs(solution.t - marched.t)) < 1e-10


def test_a_guess_with_another_number_of_nodes_is_resampled():
    system, marched = kepler(600)
    solution = solve_bvp(
        system,
        Q0,
        marched.q[-1],
        (0.0, marched.t[-1]),
        nodes=1000,
        params={"e": E},
        guess={"t": marched.t, "q": marched.q, "p": marched.p},
        options=GridOptions(solver="newton"),
    )
    assert solution.success, solution.message
    assert solution.t.size == 1000
    # the coarse march's end lies past the pericentre: the solution follows it there
    assert revolutions(solution) == pytest.approx(revolutions(marched), abs=0.01)


def test_the_straight_start_reaches_a_branch_without_solution_and_says_so():
    """The straight line between two points near the pericentre ends, with fixed steps, on the
    radial orbit (out to r = 4.2 and back), where w = f' H_zz f < 0 for r < 2: the released
    solve fails, the message says why, and no IPOPT is run from the same start."""
    system, marched = kepler(1000)
    solution = solve_bvp(system, Q0, marched.q[-1], (0.0, marched.t[-1]), nodes=1000,
                         params={"e": E})
    assert not solution.success
    assert "w = f' H_zz f <= 0 on" in solution.message
    assert "IPOPT not tried from this start" in solution.message
    assert all(ph.solver == "newton" for ph in solution.ends.stages)
    assert abs(revolutions(solution)) < 0.05  # out and back, not round
    assert np.isfinite(solution.canonical_residual).all()


def test_shooting_from_the_orbits_momentum_finds_the_three_revolutions():
    """Over whole periods the problem is degenerate (every direction of p_0 with |p_0| = sqrt 3
    returns to the start): shooting stops short of q_end, and its closest march starts the
    fixed-step solve on the branch it chose."""
    system, marched = kepler(1000)
    solution = solve_bvp(system, Q0, marched.q[-1], (0.0, marched.t[-1]), nodes=1000,
                         params={"e": E}, guess=Shooting([0.0, 1.7320508]))
    assert solution.success, solution.message
    assert solution.ends.stages[0].name == "shooting (march)"
    assert revolutions(solution) == pytest.approx(3.0, abs=0.05)
    assert solution.ends.p_sign_changes == (6, 6)
    assert sum(ph.iterations for ph in solution.ends.stages[1:]) <= 25


def test_p_start_is_checked():
    system = load_scene("kepler").system
    with pytest.raises(InputError, match=r"^p_start must have shape \(2,\), got shape \(1,\)"):
        solve_bvp(system, Q0, Q0, (0.0, 1.0), nodes=10, guess=Shooting([1.0]))
    with pytest.raises(InputError, match=r"^p_start must be finite"):
        solve_bvp(system, Q0, Q0, (0.0, 1.0), nodes=10, guess=Shooting([np.nan, 1.0]))


def test_cli_p_start(tmp_path, capsys):
    # no figure: the option's reading and the solve are the claim (test_fixed_ends's
    # test_cli_bvp_writes_the_same_outputs draws the bvp figure)
    args = ["bvp", "kepler", "--set", "q_start=0.5,0", "--set", "q_end=-0.5,0.5", "--set",
            "t_end=2", "--nodes", "201", "--no-plot"]
    assert main([*args, "--guess", "march", "--p-start", "0,1.7", "--out",
                 str(tmp_path / "a")]) == 0
    assert "kepler bvp [vddvp]: success" in capsys.readouterr().out
    assert main([*args, "--p-start", "0,x", "--out", str(tmp_path / "b")]) == 2
    assert "--p-start must be comma-separated numbers, got '0,x'" in capsys.readouterr().err


def test_a_failure_from_the_straight_start_suggests_the_other_starts():
    """M midpoint steps of h = 2 tan(pi/2M) turn the harmonic oscillator by exactly pi: q_end =
    0.5 from q_0 = 1 has no solution, and every start fails."""
    M = 20
    system = load_scene("harmonic").system
    solution = solve_bvp(
        system,
        [1.0],
        [0.5],
        (0.0, M * 2 * np.tan(np.pi / (2 * M))),
        nodes=M + 1,
        options=GridOptions(solver="newton"),
    )
    assert not solution.success
    assert solution.message.endswith("give guess=Shooting(p_start) (shooting, p_start near the "
                                      "motion's momentum) or a march's nodes as the guess")


def test_auto_retries_a_fixed_phase_with_ipopt_where_newton_stalls():
    """Henon-Heiles over 50 time units from the straight line: Newton stalls on the first
    fixed-step phase; auto retries that phase with IPOPT, and the rest follows by Newton."""
    system = load_scene("henon_heiles").system
    T = 50.0
    marched = march(system, [0.0, 0.1], [0.35, 0.0], (0.0, T), tau0=T / 999)
    assert marched.success
    auto = solve_bvp(system, [0.0, 0.1], marched.q[-1], (0.0, marched.t[-1]), nodes=marched.t.size)
    assert auto.success, auto.message
    phases = [(ph.name, ph.solver, ph.converged) for ph in auto.ends.stages]
    assert phases[:2] == [("fixed steps, uniform times", "newton", False),
                          ("fixed steps, uniform times", "ipopt", True)]
    assert phases[-1] == ("vddvp equations", "newton", True)


@pytest.mark.slow(why="study")
@pytest.mark.parametrize("T", [10.0, 20.0])
def test_the_continuation_solves_what_newton_and_ipopt_miss_from_the_straight_line(T):
    """Henon-Heiles over 10 and 20 time units: from the straight line both Newton and IPOPT
    fail on the fixed-step phase (IPOPT: Infeasible_Problem_Detected); the pseudo-arclength
    continuation in the end position, from the march of the straight line's momentum, passes
    the folds and reaches a verified solution."""
    system = load_scene("henon_heiles").system
    marched = march(system, [0.0, 0.1], [0.35, 0.0], (0.0, T), tau0=T / 999)
    solution = solve_bvp(
        system, [0.0, 0.1], marched.q[-1], (0.0, marched.t[-1]), nodes=marched.t.size
    )
    assert solution.success, solution.message
    phases = solution.ends.stages
    assert [(ph.solver, ph.converged) for ph in phases[:2]] == [("newton", False),
                                                                ("ipopt", False)]
    continued = phases[2]
    assert continued.name.startswith("continuation in q_end") and continued.converged
    assert continued.steps <= 300
    assert solution.verdict.first_failure is None


def test_newton_and_ipopt_return_the_same_kepler_nodes_from_the_same_start():
    system, marched = kepler(1000)
    solved = [solve_bvp(system, Q0, marched.q[-1], (0.0, marched.t[-1]), nodes=1000,
                        params={"e": E}, guess=marched, options=GridOptions(solver=solver))
              for solver in ("newton", "ipopt")]
    assert all(s.success for s in solved), [s.message for s in solved]
    for key in ("t", "q", "p"):
        assert np.max(np.abs(getattr(solved[0], key) - getattr(solved[1], key))) < 1e-10, key


def test_cli_refusals_name_the_options_and_leave_no_empty_folder(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = ["bvp", "kepler", "--set", "q_start=0.5,0", "--set", "q_end=-0.5,0.5", "--set",
            "t_end=2", "--nodes", "201"]
    assert main([*args, "--p-start", "0,1"]) == 2
    assert "--p-start 0,1 is the momentum shooting starts from: give it with --guess " \
        "march (got --guess straight)" in capsys.readouterr().err
    (tmp_path / "notes.txt").write_text("not an npz")
    assert main([*args, "--guess", "notes.txt"]) == 2
    assert "--guess 'notes.txt': notes.txt is not a result.npz with t, q and p arrays" \
        in capsys.readouterr().err
    np.savez(tmp_path / "one.npz", t=np.linspace(0, 2, 201), q=np.zeros((201, 1)),
             p=np.zeros((201, 1)))
    assert main([*args, "--guess", "one.npz"]) == 2
    assert "its q has shape (201, 1), this scene has n = 2 coordinates" \
        in capsys.readouterr().err
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())


def test_cli_runs_with_other_starts_get_folders_of_their_own(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = ["bvp", "pendulum", "--set", "q_start=0.5", "--set", "q_end=-0.3", "--set",
            "t_end=10", "--nodes", "201", "--no-plot"]
    assert main(args) == 0
    assert main([*args, "--guess", "march"]) == 0
    folders = sorted(path.name for path in (tmp_path / "runs").iterdir())
    assert len(folders) == 2, folders
    metas = [json.loads((tmp_path / "runs" / name / "meta.json").read_text())
             for name in folders]
    assert sorted(m["overrides"].get("guess", "straight") for m in metas) == ["march",
                                                                             "straight"]


def _end_map(end, fails=lambda p, k: False, differences_fail=lambda k: False):
    """A march stand-in whose last position is ``end(p_0)``: a march ``k`` (counted from 0)
    fails to reach the end when ``fails(p_0, k)``, or fails outright (a march of the finite
    differences) when ``differences_fail(k)``."""
    from types import SimpleNamespace
    marches = []

    def fake(request, fixed, p0, theta=None):
        k = len(marches)
        marches.append(np.array(p0, float))
        p = np.asarray(p0, float)
        whole = not fails(p, k)
        q = np.zeros((5, p.size))
        q[-1] = end(p)
        return SimpleNamespace(success=whole and not differences_fail(k),
                               t=np.zeros(5 if whole else 3), q=q, p=q,
                               message=f"march {k} failed")
    return fake, marches


SHOT = {
    # a fold (q = p^2 never reaches -1e-4): the closest miss stops halving
    "fold": ((lambda p: p ** 2), [-1e-4], [1.0], {}, False, 10, 34,
             "the miss has not halved in 3 iterations; the closest march (miss 1.001e-04) "
             "starts the fixed-step solve"),
    "differences": ((lambda p: np.array([p[0] + 0.1 * p[1] ** 3, p[1] - 0.2 * p[0] ** 2])),
                    [1.0, 2.0], [0.0, 0.0], {"differences_fail": lambda k: k == 5}, False, 2,
                    6, "a march of the finite differences failed; the closest march (miss "
                       "1.124e+00) starts the fixed-step solve"),
    "every trial": ((lambda p: p), [1.0], [0.0], {"fails": lambda p, k: p[0] > 1e-6}, False,
                    1, 11, "every march along the step from p_0 = [0.0] fails (miss 1.000e+00); "
                           "the closest march (miss 1.000e+00) starts the fixed-step solve"),
    "start": ((lambda p: p), [1.0], [0.0], {"fails": lambda p, k: True}, None, 0, 1,
              "the march from p_0 = [0.0] failed: march 0 failed"),
    "no root": ((lambda p: np.abs(p) + 1.0), [0.5], [2.0], {}, False, 30, 187,
                "q_end not reached in 30 iterations; the closest march (miss 5.000e-01) starts "
                "the fixed-step solve"),
    "longest": ((lambda p: np.sin(7 * p) + 0.3 * p), [0.9], [0.1],
                {"fails": lambda p, k: abs(p[0]) > 3}, True, 5, 9,
                "q_end reached, p_0 = [0.1467742371083065]"),
}


@pytest.mark.parametrize("case", sorted(SHOT))
def test_shooting_says_why_it_stops_and_starts_from_its_closest_march(case, monkeypatch):
    """Shooting (the grid's Newton on its end map) on end maps of known shape: its words, its
    iterations and the marches it asked for (pinned from before it ran on the grid's Newton)."""
    from ddvp_nlp.discrete.scheme import Scheme
    from ddvp_nlp.solvers.bvp import first_guess
    from ddvp_nlp.solvers.bvp.phases import Boundary
    from ddvp_nlp.solvers.grid.problem import GridRequest
    end, q_end, p_start, failing, reached, iterations, marches, said = SHOT[case]
    fake, asked = _end_map(end, **failing)
    monkeypatch.setattr(first_guess, "_march", fake)
    n = len(q_end)
    request = GridRequest(
        type("System", (), {"n": n, "params": ()})(), Scheme("fixed"), 5, np.zeros(0),
        Boundary(np.zeros(n), np.array(q_end), 0.0, 1.0, np.linspace(0, 1, 5),
                 np.array(p_start)), GridOptions(tol=1e-10))
    start, got = first_guess.shooting(request, Scheme("fixed"), np.linspace(0, 1, 5))
    stage = request.phases[0]
    assert (stage.said, stage.iterations, len(asked)) == (said, iterations, marches)
    if reached is None:
        assert start is None and not got
        return
    assert got is reached and stage.converged is reached
    miss = np.linalg.norm(start["q"][-1] - q_end)
    assert miss <= request.tol if reached else f"closest march (miss {miss:.3e})" in said


def test_shootings_least_squares_solve_leaves_the_directions_the_end_ignores_alone():
    from ddvp_nlp.solvers.bvp.first_guess import SHOOTING_RCOND, LeastSquares
    J = np.array([[2.0, 0.0], [0.0, 0.1 * SHOOTING_RCOND]])
    solve = LeastSquares(J)
    assert np.array_equal(solve.solve(np.array([1.0, 1.0])), [0.5, 0.0])
    A = np.array([[2.0, 1.0], [0.5, 3.0]])
    b = np.array([1.0, -2.0])
    assert np.allclose(A.T @ LeastSquares(A).solve_transposed(b), b, rtol=0, atol=1e-15)
    assert np.all(np.isnan(LeastSquares(None).solve(b)))


@pytest.mark.parametrize("seed", range(3))
def test_the_continuations_bordered_solve_and_its_transpose_solve_the_bordered_jacobian(seed):
    """``Bordered``: the corrector's solve by the LU of ``F_x`` alone, against the whole
    bordered matrix (``_Path.sparse``), to the backward error of LU."""
    from ddvp_nlp import Compilation
    from ddvp_nlp.discrete.scheme import Scheme
    from ddvp_nlp.solvers.bvp.end_continuation import Hyperplane, _Path
    from ddvp_nlp.solvers.bvp.interleaved import GridAssembly
    from ddvp_nlp.solvers.bvp.phases import Boundary
    from ddvp_nlp.solvers.grid.problem import GridRequest
    rng = np.random.default_rng(seed)
    system = load_scene("pendulum").system
    nodes = int(rng.integers(5, 30))
    times = np.linspace(0.0, 3.0, nodes)
    request = GridRequest(system, Scheme("fixed"), nodes, np.zeros(0),
                          Boundary(np.array([0.5]), np.array([-0.2]), 0.0, 3.0, times),
                          GridOptions())
    grid = GridAssembly(system, Scheme("fixed"), nodes, Compilation(compiler=None))
    path = _Path(request, grid, times, np.array([0.1]))
    y = np.r_[grid.layout.pack(times, rng.normal(size=(nodes, 1)),
                               rng.normal(size=(nodes, 1))), rng.random()]
    plane = Hyperplane(y + rng.normal(size=y.size), rng.normal(size=y.size))
    b = rng.normal(size=y.size)
    for transposed in (False, True):
        _, jacobian = path.evaluate(y, plane)
        matrix = path.sparse(jacobian).toarray()
        solver = path.bordered(jacobian)
        x = solver.solve_transposed(b.copy()) if transposed else solver.solve(b.copy())
        operator = matrix.T if transposed else matrix
        eps = np.finfo(float).eps
        bound = 100 * y.size ** 2 * eps * np.max(np.abs(matrix)) * np.max(np.abs(x))
        assert np.max(np.abs(operator @ x - b)) <= bound
        assert np.max(np.abs((matrix if transposed else matrix.T) @ x - b)) > bound
