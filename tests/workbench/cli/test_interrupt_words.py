"""What an interrupted command says about going on (found by a user): the resume hint named no
scene file, so the command it printed was refused; an interrupt that came after the run had
reached its end offered to resume a finished run; a march whose energy step failed gave no
hint of the fixed steps that march it."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from types import SimpleNamespace

import pytest

from ddvp_nlp.cli.one_run import interrupted_words

META = {"nodes": 12, "t_reached": 3.5, "resume": True, "scene": "pendulum"}


@pytest.mark.parametrize("scene, shown", [
    ("pendulum", "`ddvp march --resume out`"),
    ("my scene.py", "`ddvp march 'my scene.py' --resume out`"),
    (None, "`ddvp march --resume out`")])
def test_the_resume_hint_names_the_scene_file_it_needs(scene, shown):
    words = interrupted_words(SimpleNamespace(command="march", scene=scene), META,
                              SimpleNamespace(success=False), "out")
    assert shown in words and "12 nodes, up to t = 3.5" in words


def test_a_run_that_reached_its_end_is_not_offered_a_resume():
    words = interrupted_words(SimpleNamespace(command="march", scene="pendulum"), META,
                              SimpleNamespace(success=True), "out")
    assert "--resume" not in words and "nothing to resume" in words


def test_no_resume_hint_where_there_is_no_resume():
    for args, meta in ((SimpleNamespace(command="bvp", scene="pendulum"), META),
                       (SimpleNamespace(command="march", scene="pendulum"),
                        {**META, "resume": None})):
        assert "--resume" not in interrupted_words(args, meta, SimpleNamespace(success=False),
                                                   "out")


@pytest.mark.slow(why="processes")
def test_the_printed_command_resumes_a_scene_file_run(tmp_path):
    """The hint, run as printed, goes on (it had exited 2: 'name it on the command line')."""
    (tmp_path / "osc.py").write_text(
        "from ddvp_nlp import Scene\n"
        "def hamiltonian(q, p, t):\n    return p[0]**2 / 2 + q[0]**2 / 2\n"
        "scene = Scene(hamiltonian, n=1, q0=[1.0], p0=[0.0], tau0=0.01, t_end=2e4)\n")
    process = subprocess.Popen([sys.executable, "-m", "ddvp_nlp.cli", "march", "osc.py",
                                "--no-plot", "--no-progress", "--max-steps", "3000000",
                                "--checkpoint-every", "0.05", "--out", "run"], cwd=tmp_path,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    meta = tmp_path / "run" / "meta.json"
    for _ in range(100_000):  # polls for the first checkpoint, not a time bound
        if meta.exists() or process.poll() is not None:
            break
        time.sleep(0.01)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate()
    assert process.returncode == 1, err
    hint = err.split("`")[1]
    assert hint == "ddvp march osc.py --resume run", err
    again = subprocess.run([sys.executable, "-m", "ddvp_nlp.cli", *hint.split()[1:],
                            "--no-plot", "--no-progress"],
                           cwd=tmp_path, capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    assert json.loads(meta.read_text())["status"] == "success"


@pytest.mark.parametrize("scheme, status, advised", [
    ("vddvp", "newton_failed", True), ("lee", "no_admissible_step", True),
    ("vddvp", "step_ratio", True), ("fixed", "newton_failed", False),
    ("vddvp", "success", False), ("vddvp", "interrupted", False), ("vddvp", "max_steps", False)])
def test_an_energy_step_that_ends_a_march_points_to_fixed_steps(scheme, status, advised):
    """A user's double-well Duffing ended newton_failed with no hint that --scheme fixed
    marches it (where c(z) changes sign the energy rules have no positive root)."""
    from ddvp_nlp.cli.summary import _energy_step_advice

    lines = _energy_step_advice({"command": "march", "scheme": scheme, "status": status})
    assert bool(lines) == advised
    assert not lines or "--scheme fixed" in lines[0]


def test_a_march_interrupted_before_its_first_step_writes_no_run(tmp_path, monkeypatch, capsys):
    """Found by the faults page: SIGTERM 0.74 s into a march said "the run was written whole
    (1 nodes, up to t = 0) ... --resume goes on from there" beside a result.npz no reader
    takes (a run needs two times). Its start alone is not a run: nothing is written."""
    from ddvp_nlp.cli import march_command
    from ddvp_nlp.cli.interrupts import INTERRUPTS
    from ddvp_nlp.cli.main import main

    real = march_command._march

    def stopped_at_once(*args, **kwargs):  # the signal arrives before the first step
        INTERRUPTS.requested, INTERRUPTS.name = True, "SIGTERM"
        return real(*args, **kwargs)

    monkeypatch.setattr(march_command, "_march", stopped_at_once)
    try:
        code = main(["march", "pendulum", "--no-plot", "--no-progress", "--out",
                     str(tmp_path / "out")])
    finally:
        INTERRUPTS.requested, INTERRUPTS.name = False, ""
    assert code == 1
    assert "before the run's first step; nothing new was written" in capsys.readouterr().err
    assert not (tmp_path / "out" / "result.npz").exists()
