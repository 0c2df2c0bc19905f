"""The ddvp command: outputs, exit codes and messages."""

import json
import textwrap

import numpy as np

from ddvp_nlp.cli import main

USER_SCENE = textwrap.dedent('''
    """A quartic oscillator written by a user."""
    from ddvp_nlp import Scene

    def hamiltonian(q, p, t, k):
        return p[0]**2 / 2 + k * q[0]**4 / 4

    scene = Scene(hamiltonian, n=1, params={"k": 1.0}, q0=[1.0], p0=[0.0], tau0=0.05,
                  t_end=5.0)
''')


def test_march_writes_result_meta_and_plot(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["march", "harmonic", "--set", "t_end=5", "--set", "w=2", "--out", str(out),
                 "--no-progress"])
    assert code == 0
    meta = json.loads((out / "meta.json").read_text())
    for key in ("scene", "scheme", "params", "status", "success", "message", "steps",
                "timing", "energy_error"):
        assert key in meta
    assert meta["scene"] == "harmonic" and meta["scheme"] == "vddvp" and meta["success"]
    assert meta["params"]["w"] == 2.0 and meta["params"]["t_end"] == 5.0
    assert set(meta["timing"]) >= {"build_s", "solve_s"}
    assert meta["energy_error"] < 1e-13
    result = np.load(out / "result.npz")
    n_nodes = meta["steps"] + 1
    assert result["t"].shape == (n_nodes,) and result["q"].shape == (n_nodes, 1)
    assert result["p"].shape == (n_nodes, 1)
    assert (out / "trajectory.png").stat().st_size > 10_000
    assert "harmonic march [vddvp]: success" in capsys.readouterr().out


def test_failed_march_exits_1_and_keeps_partial_results(tmp_path):
    out = tmp_path / "rotation"
    # --accept-inaccurate: the breakdown of the energy step is what this test is about
    code = main(["march", "pendulum", "--set", "q0=0", "--set", "p0=2.2360679775",
                 "--out", str(out), "--no-progress", "--no-plot", "--accept-inaccurate"])
    assert code == 1
    meta = json.loads((out / "meta.json").read_text())
    assert not meta["success"] and meta["status"] in ("newton_failed", "no_admissible_step")
    result = np.load(out / "result.npz")
    assert result["t"].size == meta["steps"] + 1 > 5 and np.all(np.diff(result["t"]) > 0)


def test_user_scene_file(tmp_path):
    path = tmp_path / "quartic.py"
    path.write_text(USER_SCENE)
    code = main(["march", str(path), "--scheme", "lee", "--out", str(tmp_path / "q"),
                 "--no-progress", "--no-plot"])
    assert code == 0
    assert json.loads((tmp_path / "q" / "meta.json").read_text())["scene"] == "quartic"


def test_bad_usage_exits_2_with_the_message(tmp_path, capsys):
    assert main(["march", "nowhere", "--out", str(tmp_path)]) == 2
    assert "ddvp march: error: unknown scene 'nowhere'" in capsys.readouterr().err
    assert main(["march", "harmonic", "--set", "w=fast", "--out", str(tmp_path)]) == 2
    assert "--set w: value 'fast' is not a number" in capsys.readouterr().err
    assert main(["march", "harmonic", "--set", "g=1", "--out", str(tmp_path)]) == 2
    assert "scene 'harmonic' has no parameter 'g'" in capsys.readouterr().err
    assert main(["march", "harmonic", "--set", "tau0=-1", "--out", str(tmp_path)]) == 2
    assert "tau0 must be > 0, got -1.0" in capsys.readouterr().err


def test_unwritable_output_folder_is_refused_before_solving(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    # an output problem, not bad usage: exit 1, naming the path that is not a folder
    assert main(["march", "harmonic", "--out", str(blocker / "sub")]) == 1
    assert f"cannot write {blocker}: it is not a folder" in capsys.readouterr().err


def test_scenes_lists_every_scene_with_parameters(capsys):
    assert main(["scenes"]) == 0
    text = capsys.readouterr().out
    for name in ("paper_pendulum", "pendulum", "harmonic", "kepler", "fpu", "henon_heiles"):
        assert name in text
    assert "eps=0.1, omega=0.02" in text and "e=0.5" in text
