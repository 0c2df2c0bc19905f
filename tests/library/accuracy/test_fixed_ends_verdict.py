"""Two verdict figures from the fresh-eyes trial 56 (findings 3 and 5).

A fixed-end solution (both ends given) whose trajectory error passes the tolerance is
``inaccurate`` (the grid is off the continuous solution through its ends; nothing drifts
between two fixed ends), never ``drifted`` with exit 0; judged against an independent scipy
shooting reference. A drifted run's ``error_max`` is what it says: the largest error over the
whole run where the reference covers it (an exact solution known at every node), else the error
where the scan stopped, at ``t_drift``, and the words say so ("not measured past it"), never
"largest"."""

import json

import numpy as np
import pytest

from ddvp_nlp import Status, Tolerance, load_scene, march, solve_bvp
from ddvp_nlp.cli import main
from ddvp_nlp.solvers import describe


def pendulum_reference(q_start, q_end, T):
    from library.bvp.test_fixed_ends import shooting_reference

    return shooting_reference(q_start, q_end, T)


def test_a_fixed_end_grid_off_the_continuous_solution_is_inaccurate():
    """The pendulum from q = 0.5 to -0.036 over 9: 31 nodes are 2.5% of the
    motion's size off the continuous solution (scipy DOP853 shooting at rtol 1e-13): refused
    as ``inaccurate`` with the advice to add nodes; 61 nodes are within 1% (0.6%):
    ``accurate``. The check's figure agrees with the independent one."""
    reference = pendulum_reference(0.5, -0.036, 9.0)
    system = load_scene("pendulum").system
    for nodes in (31, 61):
        solution = solve_bvp(system, [0.5], [-0.036], (0.0, 9.0), nodes=nodes)
        exact = reference(solution.t)
        scale = np.asarray(solution.verdict.scale)
        true = max(np.max(np.abs(solution.q[:, 0] - exact[0])) / scale[0],
                   np.max(np.abs(solution.p[:, 0] - exact[1])) / scale[1])
        assert solution.verdict.error_max == pytest.approx(true, rel=0.1), nodes
        if true > 1.5e-2:
            assert solution.status is Status.INACCURATE, nodes
            assert solution.verdict.name == "inaccurate"
            failure = solution.verdict.first_failure
            assert failure.test == "trajectory error" and failure.limit == 1e-2
            assert failure.value == pytest.approx(solution.verdict.error_max)
            assert "try more nodes" in solution.message
            assert "drift" not in solution.verdict.name
        else:
            assert true < 7e-3 and solution.success and solution.verdict.name == "accurate"


def test_ddvp_bvp_on_too_few_nodes_exits_1(tmp_path):
    """The CLI: ``ddvp bvp`` on 21 nodes is ``inaccurate``, exit 1 (before: ``drifted from
    step 1``, exit 0)."""
    out = tmp_path / "coarse"
    assert main(["bvp", "paper_pendulum", "--nodes", "21", "--out", str(out), "--no-plot"]) == 1
    meta = json.loads((out / "meta.json").read_text())
    assert meta["status"] == "inaccurate"
    assert meta["accuracy"]["verdict"] == "inaccurate"
    assert meta["accuracy"]["first_failure"]["test"] == "trajectory error"


def test_a_drifted_march_says_its_figure_is_at_the_drift():
    """Against the reference flow the scan stops at ``t_drift``: ``error_max`` is the error
    there, measured up to there (``reference_until``), and the words do not call it the
    largest."""
    scene = load_scene("kepler")
    config = scene.resolve({"e": 0.6, "tau0": 0.01, "t_end": 12.0})
    run = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                tau0=config.tau0, params=config.params)
    verdict = run.verdict
    assert verdict.name == "drifted" and verdict.reference_until == verdict.t_drift
    words = describe(verdict)
    assert "not measured past it" in words and "largest" not in words
    assert f"{verdict.error_max:.3e} there" in words


def test_a_drifted_march_against_an_exact_solution_gives_its_largest_error():
    """Against the scene's exact solution (known at every node) the largest error over the
    whole run costs one pass: ``error_max`` is that, at its time, equal to the error computed
    here from ``cos`` and ``sin`` in the verdict's scales."""
    scene = load_scene("harmonic")
    config = scene.resolve({"tau0": 0.2, "t_end": 150.0})
    run = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                tau0=config.tau0, params=config.params, scheme="fixed",
                accuracy=Tolerance(exact=scene.exact_states(config)))
    verdict = run.verdict
    assert verdict.name == "drifted" and verdict.reference_until == run.t[-1]
    w = config.params["w"]
    q0, p0 = float(config.q0[0]), float(config.p0[0])
    exact_q = q0 * np.cos(w * run.t) + p0 / w * np.sin(w * run.t)
    exact_p = -q0 * w * np.sin(w * run.t) + p0 * np.cos(w * run.t)
    scale = np.asarray(verdict.scale)
    error = np.maximum(np.abs(run.q[:, 0] - exact_q) / scale[0],
                       np.abs(run.p[:, 0] - exact_p) / scale[1])
    assert verdict.error_max == pytest.approx(np.max(error), rel=1e-6)
    assert verdict.error_max_t == run.t[int(np.argmax(error))]
    assert verdict.error_max > 3 * verdict.global_tol  # well past the drift's own error
    assert f"largest {verdict.error_max:.3e}" in describe(verdict)
