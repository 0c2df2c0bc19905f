"""The command line's seams (issue 31): one progress option on every command, plain lines (no
carriage return) when stderr is not a terminal, a guess for a mistyped scene or option, a
scene setting given as an option of its own answered with the --set line, whole descriptions
in `ddvp scenes`."""

import io
import subprocess
import sys

import numpy as np
import pytest

from ddvp_nlp import Output, load_scene, march
from ddvp_nlp.cli import main
from ddvp_nlp.cli.parser import build_parser, parse_arguments
from ddvp_nlp.cli.scenes_command import SCENES_WIDTH
from ddvp_nlp.progress import PlainLines, Silent, progress
from ddvp_nlp.runner.tasks import Task, run_tasks

# The smallest arguments each command parses with.
MINIMAL = {"march": ["harmonic"], "bvp": ["pendulum"], "compare": ["harmonic"], "stress": [],
           "sweep": ["harmonic"], "reproduce": [], "periodic": ["henon_heiles"],
           "poincare": ["henon_heiles", "--energy", "0.1"],
           "chaos": ["henon_heiles", "--energy", "0.1", "--grid", "q2=-0.3:0.3:3,p2=-0.3:0.3:3"]}


def test_every_command_but_scenes_is_covered():
    assert set(build_parser().commands) - {"scenes"} == set(MINIMAL)


@pytest.mark.parametrize("command", sorted(MINIMAL))
def test_every_command_takes_progress_and_no_progress(command):
    parser = build_parser()
    argv = [command, *MINIMAL[command]]
    assert parse_arguments(parser, argv).progress is None  # the command's own default
    assert parse_arguments(parser, [*argv, "--progress"]).progress is True
    assert parse_arguments(parser, [*argv, "--no-progress"]).progress is False


def test_bvp_no_progress_runs(tmp_path, capsys):
    assert main(["bvp", "pendulum", "--no-progress", "--no-plot", "--out",
                 str(tmp_path / "b")]) == 0
    assert "success" in capsys.readouterr().out


def test_plain_lines_off_a_terminal():
    stream = io.StringIO()  # not a terminal
    report = progress(10, unit="task", label="runs", stream=stream, every=0.0)
    assert isinstance(report, PlainLines)
    for _ in range(10):
        report.update()
    report.close()
    lines = stream.getvalue().splitlines()
    assert "\r" not in stream.getvalue()
    assert lines[0].startswith("runs: 1/10 task (10%)") and lines[-1].startswith(
        "runs: 10/10 task (100%)")
    assert isinstance(progress(10, unit="task", enabled=False, stream=stream), Silent)


def test_a_march_and_a_grid_write_no_carriage_return_into_a_redirected_stderr(capsys):
    system = load_scene("harmonic").system
    solution = march(system, [1.0], [0.0], (0.0, 20.0), tau0=0.01,
                     output=Output(progress=True))
    assert solution.success
    tasks = [Task(f"t{i}", "math:sqrt", (float(i),), {}) for i in range(4)]
    # one worker: the grid's bar is the same (ddvp_nlp/progress.py, updated as each task ends)
    # wherever its tasks run; a local Dask cluster for them cost 2.5 s of CPU
    results = sorted(r for _, r, _ in run_tasks(tasks, workers=1, progress=True))
    assert np.allclose(results, np.sqrt(np.arange(4)))
    assert "\r" not in capsys.readouterr().err


@pytest.mark.slow(why="processes")
def test_a_redirected_stderr_of_the_command_has_no_carriage_return(tmp_path):
    done = subprocess.run([sys.executable, "-m", "ddvp_nlp.cli", "compare", "harmonic",
                           "--methods", "vddvp,rk4", "--halvings", "1", "--repeats", "1",
                           "--no-compile", "--out", str(tmp_path / "c")],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert "\r" not in done.stderr and "Traceback" not in done.stderr


def test_an_unknown_scene_gets_a_guess(tmp_path, capsys):
    assert main(["march", "pendulm", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "unknown scene 'pendulm'; did you mean 'pendulum'" in err
    assert main(["march", "henon-heiles", "--out", str(tmp_path)]) == 2
    assert "did you mean 'henon_heiles'?" in capsys.readouterr().err


@pytest.mark.parametrize("argv, line", [
    (["march", "pendulum", "--tau0", "0.01"], "--set tau0=0.01"),
    (["march", "pendulum", "--tau0=0.01"], "--set tau0=0.01"),
    (["march", "kepler", "--q0", "1,0"], "--set q0=1,0"),
    (["bvp", "pendulum", "--q-end", "1"], "--set q_end=1"),
    (["compare", "kepler", "--e", "0.3"], "--set e=0.3"),       # a parameter of the scene
    (["poincare", "henon_heiles", "--energy", "0.1", "--t0", "1"], "--set t0=1"),
    (["sweep", "kepler", "--grid", "e=0.1,0.2", "--tau0", "0.1"], "--set tau0=0.1"),
])
def test_a_scene_setting_as_an_option_says_to_use_set(argv, line, capsys):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert line in err and "usage:" not in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err


def test_a_mistyped_option_gets_the_closest_ones(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["march", "pendulum", "--tau-mn", "0.1"])
    assert stop.value.code == 2
    assert "did you mean --tau-min or --tau-max?" in capsys.readouterr().err


def test_t_end_of_a_fresh_march_is_the_end_time(tmp_path, capsys):
    assert main(["march", "harmonic", "--t-end", "2", "--no-progress", "--no-plot", "--out",
                 str(tmp_path / "m")]) == 0
    assert "reached t_end = 2 " in capsys.readouterr().out
    assert main(["march", "harmonic", "--t-end", "2", "--set", "t_end=3", "--out",
                 str(tmp_path / "n")]) == 2
    assert "t_end is given twice" in capsys.readouterr().err


def test_scenes_shows_whole_descriptions_wrapped(capsys):
    from ddvp_nlp.scenes import list_scenes

    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    joined = " ".join(out.split())
    for name in list_scenes():
        assert " ".join(load_scene(name).description.split()) in joined, name
    assert "its exact solution by Kepler's equation." in joined  # cut at "over ten" before
    entries = out.split("\n\n")
    for entry in entries:
        for text in entry.splitlines()[1:]:
            if not text.lstrip().startswith(("start:", "fixed ends:", "scheme:")):
                assert len(text) <= SCENES_WIDTH, text
