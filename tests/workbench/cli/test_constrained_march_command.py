"""``ddvp march`` of a constrained scene backwards in time and continued with ``--resume``
(issue 48): the command's runs equal the library's, a damaged carried state is refused by name
with exit 2. The fault cases of the same surface: scripts/pages/faults.py --only
constrained_march."""

import json

import numpy as np
import pytest

from ddvp_nlp import load_scene, march
from ddvp_nlp.cli import main

FLAGS = ["--no-plot", "--no-progress"]


def arrays(folder):
    with np.load(folder / "result.npz") as data:
        return {key: data[key] for key in ("t", "q", "p")}


@pytest.mark.slow(why="repetition")
def test_a_backward_march_of_the_cartesian_pendulum(tmp_path, capsys):
    assert main(["march", "cartesian_pendulum", "--t-end", "-5", *FLAGS, "--out",
                 str(tmp_path / "bw")]) == 0
    meta = json.loads((tmp_path / "bw" / "meta.json").read_text())
    assert meta["status"] == "success"
    run = arrays(tmp_path / "bw")
    scene = load_scene("cartesian_pendulum")
    alone = march(scene.system, scene.q0, scene.p0, (0, -5), tau0=scene.tau0)
    assert run["t"].size == alone.t.size and np.all(np.diff(run["t"]) < 0)
    assert np.abs(run["q"] - alone.q).max() <= 1e-12
    assert "verdict: accurate" in capsys.readouterr().out


@pytest.mark.slow(why="repetition")
def test_a_resumed_march_is_the_whole_march_and_a_damaged_state_is_refused(tmp_path, capsys):
    run, whole = tmp_path / "run", tmp_path / "whole"
    assert main(["march", "cartesian_pendulum", "--t-end", "2", *FLAGS, "--out", str(run)]) == 0
    meta = json.loads((run / "meta.json").read_text())
    assert len(meta["carried"]["multipliers"]) == 2
    assert main(["march", "cartesian_pendulum", "--t-end", "5", *FLAGS, "--out",
                 str(whole)]) == 0
    assert main(["march", "--resume", str(run), "--t-end", "5", *FLAGS]) == 0
    resumed, once = arrays(run), arrays(whole)
    assert resumed["t"].size == once["t"].size
    # the Newton's tolerance (StepControl.tol / UPDATE_SHARE of the unknowns) per step
    assert np.abs(resumed["q"] - once["q"]).max() <= once["t"].size * 1e-12 * 6
    meta = json.loads((run / "meta.json").read_text())
    meta["carried"]["multipliers"] = [1.0]
    (run / "meta.json").write_text(json.dumps(meta))
    capsys.readouterr()
    assert main(["march", "--resume", str(run), "--t-end", "6", *FLAGS]) == 2
    err = capsys.readouterr().err
    assert "multipliers" in err and "Traceback" not in err
