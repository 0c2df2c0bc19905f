"""Everyday use of the ddvp command: help for every option, each command's own usage on its
errors, default output folders that follow the settings, whole-run replacement, scenes' default
schemes and what `ddvp scenes` shows."""

import argparse
import json
import textwrap

import pytest

from ddvp_nlp.cli import main
from ddvp_nlp.cli.parser import build_parser

pytestmark = pytest.mark.smoke  # the quick tier: tests/README.md


def options_without_help(parser: argparse.ArgumentParser, name: str = "ddvp"):
    """``(command, option)`` of every argument, at every level, that has no help text."""
    missing = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            if not action.help:
                missing.append((name, "COMMAND"))
            for command, sub in action.choices.items():
                missing += options_without_help(sub, f"{name} {command}")
        elif not action.help or action.help == argparse.SUPPRESS:
            missing.append((name, "/".join(action.option_strings) or action.dest))
    return missing


def test_the_walk_finds_an_option_without_help():
    parser = argparse.ArgumentParser(prog="x")
    commands = parser.add_subparsers(dest="command", help="commands")
    commands.add_parser("run").add_argument("--bare")
    assert options_without_help(parser) == [("ddvp run", "--bare")]


def test_every_option_of_every_command_has_help():
    assert options_without_help(build_parser()) == []


def test_set_help_names_the_state_settings():
    for command in ("march", "bvp"):
        parser = build_parser().commands[command]
        text = next(a.help for a in parser._actions if "--set" in a.option_strings)
        for name in ("q0", "p0", "v0", "tau0", "t_end", "q_start", "q_end"):
            assert name in text, (command, name)


@pytest.mark.parametrize("argv, usage", [
    (["march", "harmonic", "--bogus"], "usage: ddvp march"),
    (["bvp", "pendulum", "--nodes", "11", "--bogus", "3"], "usage: ddvp bvp"),
    (["sweep", "kepler", "--grid", "e=0.5,0.6", "--bogus"], "usage: ddvp sweep"),
    (["march", "harmonic", "--tol", "abc"], "usage: ddvp march"),
    (["compare", "harmonic", "--halvings", "x"], "usage: ddvp compare"),
])
def test_a_commands_errors_print_its_own_usage(argv, usage, capsys):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith(usage), err
    assert f"ddvp {argv[0]}: error:" in err and "Traceback" not in err


def test_default_folder_follows_the_settings(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    short = ["--no-progress", "--no-plot"]
    assert main(["march", "harmonic", *short]) == 0
    assert (tmp_path / "runs" / "harmonic-vddvp" / "meta.json").is_file()
    for e in ("0.6", "0.7"):
        assert main(["march", "kepler", "--set", f"e={e}", "--set", "t_end=1", *short]) == 0
    folders = sorted(p.name for p in (tmp_path / "runs").iterdir())
    kepler = [name for name in folders if name.startswith("kepler-vddvp-")]
    assert len(kepler) == 2 and all(len(name) == len("kepler-vddvp-") + 8 for name in kepler)
    overrides = [json.loads((tmp_path / "runs" / name / "meta.json").read_text())["overrides"]
                 for name in kepler]
    assert sorted(o["e"] for o in overrides) == [0.6, 0.7]
    assert all(o["t_end"] == 1.0 for o in overrides)
    # the same settings find the same folder again
    assert main(["march", "kepler", "--set", "t_end=1", "--set", "e=0.6", *short]) == 0
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == folders
    assert json.loads((tmp_path / "runs" / "harmonic-vddvp" / "meta.json").read_text())[
        "overrides"] == {}
    capsys.readouterr()


def test_bvp_default_folder_follows_the_settings(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["bvp", "pendulum", "--nodes", "61", "--no-plot"]) == 0
    assert main(["bvp", "pendulum", "--nodes", "61", "--set", "q_end=0", "--no-plot"]) == 0
    folders = sorted(p.name for p in (tmp_path / "runs").iterdir())
    assert len(folders) == 2 and all(f.startswith("pendulum-bvp-vddvp-") for f in folders)
    metas = [json.loads((tmp_path / "runs" / f / "meta.json").read_text()) for f in folders]
    assert sorted(json.dumps(m["overrides"], sort_keys=True) for m in metas) == [
        '{"nodes": 61, "q_end": [0.0]}', '{"nodes": 61}']
    capsys.readouterr()


# bvp is the march's repetition: both write through cli/one_run.write_run and
# io/run_folder.save_run, which removes a figure not drawn; the march case keeps it by default.
@pytest.mark.slow_when(lambda command, **_: command[0] == "bvp", why="repetition")
@pytest.mark.parametrize("command", [
    ["march", "harmonic", "--no-progress"],
    ["bvp", "pendulum", "--nodes", "41"],
])
def test_a_run_without_its_figure_removes_the_old_figure(tmp_path, command, capsys):
    out = tmp_path / "run"
    assert main([*command, "--out", str(out), "--set", "t_end=2"]) == 0
    assert (out / "trajectory.png").is_file()
    first = json.loads((out / "meta.json").read_text())
    assert main([*command, "--out", str(out), "--set", "t_end=3", "--no-plot"]) == 0
    assert not (out / "trajectory.png").exists()
    second = json.loads((out / "meta.json").read_text())
    assert second["t_reached"] != first["t_reached"]
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == [
        "meta.json", "result.npz"]
    capsys.readouterr()


def test_higher_order_scenes_run_at_their_default_scheme(tmp_path, capsys):
    assert main(["march", "pais_uhlenbeck", "--set", "t_end=1", "--no-plot",
                 "--out", str(tmp_path / "pu")]) == 0
    assert json.loads((tmp_path / "pu" / "meta.json").read_text())["scheme"] == "fixed"
    assert main(["bvp", "spline", "--no-plot", "--out", str(tmp_path / "spline")]) == 0
    meta = json.loads((tmp_path / "spline" / "meta.json").read_text())
    assert meta["scheme"] == "fixed" and meta["success"]
    assert "[fixed]: success" in capsys.readouterr().out


def test_a_scene_declaring_an_unknown_scheme_is_refused(tmp_path, capsys):
    path = tmp_path / "odd.py"
    path.write_text(textwrap.dedent('''
        from ddvp_nlp import Scene

        def hamiltonian(q, p, t):
            return p[0]**2 / 2 + q[0]**2 / 2

        scene = Scene(hamiltonian, n=1, q0=[1.0], p0=[0.0], tau0=0.1, t_end=1.0,
                      scheme="verlet")
    '''))
    assert main(["march", str(path), "--out", str(tmp_path / "o"), "--no-plot"]) == 2
    err = capsys.readouterr().err
    assert "scene 'odd' declares scheme 'verlet'" in err and "Traceback" not in err


def test_scenes_shows_start_boundary_data_and_scheme(capsys):
    assert main(["scenes"]) == 0
    entries = {block.split()[0]: block for block in capsys.readouterr().out.split("\n\n")}
    assert "start: q0=[0.5] p0=[0.5]" in entries["pendulum"]
    assert "fixed ends: q_start=[0.5] q_end=[-0.036], t in [0, 9], 181 nodes" \
        in entries["pendulum"]
    assert "scheme: vddvp (default)" in entries["pendulum"]
    assert "fixed ends: none" in entries["kepler"]
    for name in ("pais_uhlenbeck", "spline"):
        assert "scheme: fixed (the scene's)" in entries[name]


def test_a_closed_stdout_ends_quietly():
    """``ddvp scenes | head -1``: the reader goes away; no traceback, the shell's SIGPIPE
    code. A real pipe whose reader is closed before the command writes (the child waits
    until its stdout is broken, so the write always meets the closed pipe)."""
    import subprocess
    import sys

    child = ("import sys\n"
             "from ddvp_nlp.cli import main\n"
             "sys.stdin.read()  # the parent closes stdin once it has closed our stdout\n"
             "sys.exit(main(['scenes']))\n")
    process = subprocess.Popen([sys.executable, "-c", child], stdin=subprocess.PIPE,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    process.stdout.close()
    process.stdin.close()
    err = process.stderr.read()
    process.wait(timeout=120)
    assert process.returncode == 141, err  # 128 + SIGPIPE
    assert b"Traceback" not in err


def test_a_motion_at_rest_says_why_the_step_is_free_and_prints_no_nan(tmp_path, capsys):
    """harmonic with w = 0 from rest: f = 0, so w = f' H_zz f = 0 at every node."""
    with pytest.warns(RuntimeWarning, match="site-density weight w = -8 c\\(z\\) is zero"):
        assert main(["march", "harmonic", "--set", "w=0", "--out", str(tmp_path / "a"),
                     "--no-progress", "--no-plot"]) == 0
    captured = capsys.readouterr()
    assert "nan" not in captured.out and "invalid value" not in captured.err
    assert "error against the exact solution 0.000e+00" in captured.out


# Options whose default is the command line's own (not a field of an option object or an
# argument of the API): where to write, what to run, how to show it.
CLI_ONLY = {"out", "figure_format", "settings", "events", "scene", "methods", "grid", "guess",
            "direction"}


def _defaults(parser: argparse.ArgumentParser) -> dict:
    return {action.dest: action.default for action in parser._actions
            if not isinstance(action, (argparse._HelpAction, argparse._VersionAction))}


def test_every_command_line_default_is_the_apis():
    """A default exists once, in the API: every option whose default is a value (not ``None``,
    ``False`` or an empty list) reads it from ``cli/arguments.API_DEFAULTS``, and that table
    gives the option objects' own defaults."""
    from ddvp_nlp.cli.arguments import API_DEFAULTS, api_default

    own = []
    for command, parser in build_parser().commands.items():
        tables = [table for table in (command, "accuracy", "stress") if table in API_DEFAULTS]
        for dest, value in _defaults(parser).items():
            known = [table for table in tables if dest in API_DEFAULTS[table]]
            if known and value is not None:  # None: taken later (a sweep's grid file's bound)
                assert value == api_default(known[0], dest), (command, dest)
            elif value not in (None, False, []) and dest not in CLI_ONLY:
                own.append(f"ddvp {command} --{dest.replace('_', '-')} = {value!r}")
    assert own == []


def test_the_options_a_command_builds_by_default_are_the_apis():
    from ddvp_nlp import Compilation, GridOptions, Output, StepControl, Tolerance
    from ddvp_nlp.cli import arguments
    from ddvp_nlp.cli.request import Request

    def request(*words):
        parser = build_parser(words[0])
        return Request.read(parser.parse_args(list(words)), parser.commands[words[0]])

    march = request("march", "pendulum")
    assert arguments.step_control(march) == StepControl()
    assert arguments.tolerance(march) == Tolerance()
    assert arguments.compilation(march) == Compilation()
    assert arguments.march_output(march).checkpoint_interval == Output().checkpoint_interval
    bvp = request("bvp", "pendulum")
    assert arguments.grid_options(bvp) == GridOptions()
    periodic = request("periodic", "pendulum")
    assert arguments.grid_options(periodic) == GridOptions()


def test_the_default_check_finds_a_default_of_the_command_lines_own():
    parser = argparse.ArgumentParser(prog="x")
    parser.add_argument("--tol", type=float, default=1e-9)
    assert _defaults(parser)["tol"] == 1e-9  # what the walk above would flag for `x`


def test_the_guides_synopsis_is_the_parsers():
    """Section 11 of the guide (the synopsis the README points to) names every command and
    every option of each command's parser, and no option the parser does not know."""
    import re
    from pathlib import Path

    from ddvp_nlp.cli.parser import build_parser

    text = (Path(__file__).resolve().parents[3] / "docs" / "guide.md").read_text()
    synopsis = text[text.index("## 11. The command line in full"):]
    synopsis = synopsis[synopsis.index("```text"):]
    synopsis = synopsis[:synopsis.index("```\n", 7)]
    known = {"--version"}
    for name, sub in build_parser().commands.items():
        options = {o for action in sub._actions for o in action.option_strings
                   if o.startswith("--")} - {"--help"}
        known |= options
        assert f"ddvp {name}" in synopsis, f"command {name} missing from the guide's synopsis"
        missing = sorted(o for o in options if not re.search(re.escape(o) + r"(?![\w-])",
                                                             synopsis))
        assert not missing, f"ddvp {name}: {missing} missing from the guide's synopsis"
    unknown = set(re.findall(r"--[a-z][a-z0-9-]*", synopsis)) - known
    assert not unknown, f"the guide's synopsis names options the parser lacks: {unknown}"


def test_a_command_started_with_stdout_closed_shows_no_traceback():
    """``ddvp scenes >&-`` (descriptor 1 closed before the command starts): the supervised
    command flushed a missing stdout and showed a traceback (issue 45)."""
    import os
    import shutil
    import subprocess
    import sys

    ddvp = shutil.which("ddvp", path=os.path.dirname(sys.executable))
    assert ddvp is not None
    done = subprocess.run(f"'{ddvp}' scenes >&-", shell=True, capture_output=True,
                          text=True, timeout=120)
    assert "Traceback" not in done.stderr
    assert done.returncode == 0, done.stderr


# the breakdown (and the monitor's warning before it) is the point
@pytest.mark.filterwarnings("ignore:solvability monitor:RuntimeWarning")
def test_a_failed_runs_verdict_says_what_it_covers(tmp_path, capsys):
    """A failed run was printed ``accurate`` beside its failed status (the verdict of the part
    kept, not said so): it says where the run ended and that the verdict covers up to there
    (issue 45)."""
    import re

    from ddvp_nlp.cli import main

    code = main(["march", "pendulum", "--set", "p0=2.2", "--max-steps", "500", "--no-plot",
                 "--no-progress", "--out", str(tmp_path / "run")])
    out = capsys.readouterr().out
    assert code == 1
    verdict = next(line for line in out.splitlines() if "verdict:" in line)
    assert re.search(r"no verdict on the whole run \(it ended \w+ at t = [-\d.e+]+\); the \d+ "
                     r"steps kept up to there are (accurate|drifted from t = )", verdict), verdict
    assert not verdict.strip().endswith("verdict: accurate")
