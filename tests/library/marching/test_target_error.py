"""Asking for an error instead of a step (solvers/marching/target.py): the march chooses its
tau0 so that the run is accurate at the error asked for, judged by the accuracy check and by an
independent reference; the choice does not depend on units; bad requests are refused."""

from __future__ import annotations

import json

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import InputError, Scene, march
from ddvp_nlp.cli import main
from ddvp_nlp.solvers import exact_reference


def _true_error(scene, config, solution) -> float:
    """The largest error over the nodes against the exact flow at rtol 1e-12, relative to each
    component's range over the run (the accuracy check's scales, without their floors)."""
    z = np.column_stack([solution.q, solution.p])
    theta = scene.system.parameter_vector(config.params)
    states = exact_reference(scene.system, z[0], solution.t[0], solution.t[-1], theta,
                             rtol=1e-12).states(solution.t)
    both = np.vstack([z, states])
    scale = both.max(axis=0) - both.min(axis=0)
    return float(np.max(np.abs(z - states) / scale))


@pytest.mark.parametrize("name, overrides, target", [("kepler", {"e": 0.6, "t_end": 20.0}, 1e-3),
                                                     ("henon_heiles", {"t_end": 100.0}, 1e-3),
                                                     ("pendulum", {"t_end": 50.0}, 1e-4)])
def test_the_run_is_accurate_at_the_error_asked_for(name, overrides, target, scene_of):
    scene = scene_of(name)
    config = scene.resolve(overrides)
    solution = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                     tau0=config.tau0, params=config.params, target_error=target)
    record = solution.march.target_error
    assert solution.success and solution.verdict.name == "accurate"
    assert solution.verdict.global_tol == target
    assert record["tau0"] == record["runs"][-1]["tau0"] and 1 <= len(record["runs"]) <= 2
    # an independent measure: within twice the target (the verdict study's margin)
    assert _true_error(scene, config, solution) <= 2 * target
    # not wasteful beyond reason: the chosen step at least a tenth of the pilot's prediction
    assert record["pilot"]["steps"] >= 2 and record["cpu_s"] > 0


def _oscillator(amplitude: float) -> Scene:
    def hamiltonian(q, p, t):
        return (ca.sumsqr(p) + 4 * ca.sumsqr(q)) / 2 + 0.1 * q[0] ** 4 / amplitude ** 2
    return Scene(hamiltonian, n=1, q0=[amplitude], p0=[0.0], tau0=0.05, t_end=30.0,
                 name="oscillator")


@pytest.mark.slow(why="repetition")
def test_the_choice_does_not_depend_on_units():
    """q and p a thousand times larger (the quartic term scaled with them): the same motion in
    other units, the same tau0 chosen (everything the choice measures is relative)."""
    chosen = []
    for amplitude in (1.0, 1000.0):
        scene = _oscillator(amplitude)
        config = scene.resolve({})
        solution = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                         tau0=config.tau0, target_error=1e-3)
        chosen.append(solution.march.target_error["tau0"])
    assert chosen[1] == pytest.approx(chosen[0], rel=1e-3)


@pytest.mark.parametrize("value", [0.0, -1e-3, 1.0, 5.0, float("nan"), "x", 1e-300, 1e-13])
def test_a_bad_target_is_refused_by_name(value, scene_of):
    """Below the exact-flow reference's floor no run can be judged to reach the target: it
    is refused up front (``1e-300`` ran 250 s before failing, issue 45)."""
    scene = scene_of("harmonic")
    with pytest.raises(InputError, match="target_error"):
        march(scene.system, [1.0], [0.0], (0.0, 1.0), tau0=0.1, target_error=value)


def test_a_target_needs_the_check_and_p0(scene_of):
    scene = scene_of("harmonic")
    with pytest.raises(InputError, match="accuracy check"):
        march(scene.system, [1.0], [0.0], (0.0, 1.0), tau0=0.1, target_error=1e-3,
              accuracy=None)
    lagrangian = scene_of("pendulum_lagrangian")
    with pytest.raises(InputError, match="p0"):
        march(lagrangian.system, [0.5], None, (0.0, 1.0), tau0=0.05, v0=[0.1],
              target_error=1e-3)


def test_the_command_line_says_what_it_chose(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["march", "pendulum", "--set", "t_end=20", "--target-error", "1e-3",
                 "--no-plot", "--no-progress", "--out", str(out)]) == 0
    meta = json.loads((out / "meta.json").read_text())
    assert meta["target_error"]["target"] == 1e-3 and meta["target_error"]["tau0"] > 0
    assert "target error 0.001: tau0" in capsys.readouterr().out
    assert main(["march", "pendulum", "--method", "rk4", "--target-error", "1e-3",
                 "--no-plot", "--out", str(tmp_path / "m")]) == 2
    assert "compared method" in capsys.readouterr().err


def test_a_pilot_that_breaks_down_is_a_status_with_its_nodes_not_an_input_error(scene_of):
    """The pilot's breakdown is a failed solve (issue 45: it raised `InputError`, and the
    command line exited 2, the bad-input code)."""
    scene = scene_of("kepler")
    config = scene.resolve({"e": 0.9})
    solution = march(scene.system, config.q0, config.p0, (0.0, 50.0), tau0=0.5,
                     target_error=1e-3)
    assert not solution.success and solution.steps >= 1
    assert solution.verdict is None  # no run was chosen: nothing claimed for the span
    assert "pilot march" in solution.message and "no run was made" in solution.message
    assert solution.march.target_error["tau0"] is None


def test_a_run_stopped_before_its_first_step_carries_no_verdict_and_is_not_retried(scene_of):
    """Ctrl-C during the tries wrote status interrupted, 0 steps and verdict accurate."""
    from ddvp_nlp import Output

    scene = scene_of("pendulum")
    config = scene.resolve({})
    polls = []

    def stop():  # the pilot runs unwatched; the chosen run is stopped at its first poll
        polls.append(1)
        return True
    solution = march(scene.system, config.q0, config.p0, (0.0, 200.0), tau0=0.05,
                     target_error=1e-3, output=Output(stop=stop))
    assert solution.status.code == "interrupted"
    if solution.steps == 0:
        assert solution.verdict is None and solution.accuracy_skipped
    assert len(solution.march.target_error["runs"]) == 1


def test_a_target_error_run_resumes_at_the_step_it_chose(tmp_path, capsys):
    """``--resume`` of a ``--target-error`` run was refused ("tau0 did not make the run's
    first step"): it goes on at the chosen step, judged at the target, and its nodes are those
    of an uninterrupted march at that step, bit for bit (issue 45)."""
    import numpy as np

    out = tmp_path / "run"
    assert main(["march", "pendulum", "--set", "t_end=20", "--target-error", "1e-3",
                 "--no-plot", "--no-progress", "--out", str(out)]) == 0
    chosen = json.loads((out / "meta.json").read_text())["target_error"]["tau0"]
    assert main(["march", "--resume", str(out), "--t-end", "30", "--no-plot",
                 "--no-progress"]) == 0
    meta = json.loads((out / "meta.json").read_text())
    assert meta["accuracy"]["global_tol"] == 1e-3
    whole = tmp_path / "whole"
    assert main(["march", "pendulum", "--set", "t_end=30", "--set", f"tau0={chosen!r}",
                 "--no-plot", "--no-progress", "--out", str(whole)]) == 0
    resumed, direct = (np.load(folder / "result.npz") for folder in (out, whole))
    assert np.array_equal(resumed["t"], direct["t"])
    assert np.array_equal(resumed["q"], direct["q"])
    capsys.readouterr()


def test_the_command_line_says_a_pilot_failed_instead_of_crashing(tmp_path, capsys):
    """Found by a user: the summary formatted the chosen tau0 (None after a failed pilot) and the
    command ended in 'internal error: TypeError'; it prints the pilot's failure and exits 1."""
    code = main(["march", "kepler", "--set", "e=0.9", "--set", "t_end=50", "--set", "tau0=0.5",
                 "--target-error", "1e-3", "--no-plot", "--out", str(tmp_path / "run")])
    out = capsys.readouterr()
    assert code == 1
    assert "no step chosen" in out.out and "no run was made" in out.out
    assert "internal error" not in out.err + out.out
