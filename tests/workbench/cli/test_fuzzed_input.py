"""Fuzzing the command line and the files it reads back, with a fixed seed and a fixed number of
cases (no clock): every command line and every damaged file must end in exit 0, 1 or 2 with a
one-line message, never an exception out of ``main``, an "internal error" or a traceback.

The command lines are cheap valid commands with one option replaced by a value drawn from a
pool of hostile ones (non-numbers, NaN, infinities, zero, negatives, subnormals, huge counts,
empty strings, long strings); the files are valid ones (a grid's CSV, a TOML grid file, a guess,
a run folder's manifest) with bytes flipped, cut or replaced at random.
"""

from __future__ import annotations

import random
import shutil

import numpy as np
import pytest

from ddvp_nlp.cli import main

SEED = 28
COMMAND_CASES = 90
FILE_CASES = 40
# The default run draws the first cases of each (every base command and every kind of file is
# among them); the rest, the same property on more draws, are the slow tier's.
DEFAULT_COMMAND_CASES = 30
DEFAULT_FILE_CASES = 15

HOSTILE = ["", " ", "nan", "inf", "-inf", "-1", "0", "-0", "1e308", "1e400", "5e-324",
           "4000000000", "100000000000", "abc", "1,2", "1:2", "0x10", "é", "x" * 300, "1e-320",
           "3.5", "-7", "None", "[1]", "=", "q1=", "=0", "q9=0", "p1=nan", "1:1:1", "0:1:0",
           "1:2:1000000000"]

# Cheap commands (seconds at most), each with the options that may be replaced.
BASES = [
    (["march", "harmonic", "--set", "t_end=0.5", "--no-progress", "--no-plot"],
     ["--tol", "--alpha", "--tau-min", "--tau-max", "--max-step-ratio", "--time-limit",
      "--energy-guard", "--rtol", "--atol", "--energy-tol", "--global-tol", "--max-steps",
      "--checkpoint-every", "--set", "--clock", "--scheme"]),
    (["bvp", "pendulum", "--nodes", "61", "--no-plot"],
     ["--nodes", "--tol", "--alpha", "--time-limit", "--p-start", "--guess", "--set",
      "--solver"]),
    (["periodic", "harmonic", "--nodes", "21", "--no-plot"],
     ["--energy", "--nodes", "--section", "--family", "--set", "--guess"]),
    (["poincare", "henon_heiles", "--energy", "0.1", "--orbits", "2", "--t-end", "5",
      "--no-plot", "--workers", "1"],
     ["--energy", "--orbits", "--section", "--t-end", "--tau0", "--seed", "--workers",
      "--set"]),
    (["compare", "harmonic", "--set", "t_end=0.5", "--methods", "rk4", "--halvings", "0",
      "--repeats", "1", "--no-progress"],
     ["--methods", "--halvings", "--repeats", "--workers", "--set", "--horizons",
      "--time-unit", "--run-budget", "--reference-span"]),
    (["sweep", "harmonic", "--grid", "tau0=0.1", "--set", "t_end=0.5", "--methods", "rk4",
      "--no-progress", "--workers", "1"],
     ["--grid", "--methods", "--set", "--max-steps", "--time-limit", "--workers"]),
]


def _replaced(argv: list[str], option: str, value: str) -> list[str]:
    """``argv`` with ``option``'s value replaced (or the option added)."""
    argv = list(argv)
    if option in argv and option != "--set":
        argv[argv.index(option) + 1] = value
    else:
        argv += [option, value]
    return argv


def _check(code, err: str, argv) -> None:
    assert code in (0, 1, 2), (argv, code, err)
    assert "Traceback" not in err and "internal error" not in err, (argv, err)
    if code == 2:
        assert "error" in err, (argv, err)


@pytest.mark.slow_when(lambda index, **_: index >= DEFAULT_COMMAND_CASES,
                       why="repetition")  # cases 0-29 of this test check it by default
@pytest.mark.parametrize("index", range(COMMAND_CASES))
def test_fuzzed_command_lines_end_cleanly(index, tmp_path, monkeypatch, capsys):
    rng = random.Random(SEED * 1000 + index)
    base, options = rng.choice(BASES)
    option = rng.choice(options)
    value = rng.choice(HOSTILE)
    if option in ("--set", "--grid") and rng.random() < 0.7:
        name = rng.choice(["t_end", "tau0", "t0", "w", "q0", "p0", "e", "nodes"])
        value = f"{name}={value}"
    argv = _replaced(base, option, value)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("DDVP_SCENE_TIME_LIMIT", "5")
    try:
        code = main([*argv, "--out", str(tmp_path / "out")])
    except SystemExit as stop:  # argparse's own refusal (an option of the wrong type), as is
        code = stop.code
    _check(code, capsys.readouterr().err, argv)


def _mutated(data: bytes, rng: random.Random) -> bytes:
    """``data`` with a few bytes flipped, a piece cut, or a random piece put in."""
    data = bytearray(data)
    kind = rng.choice(["flip", "cut", "insert", "truncate", "garbage"])
    if kind == "flip" and data:
        for _ in range(rng.randint(1, 8)):
            data[rng.randrange(len(data))] = rng.randrange(256)
    elif kind == "cut" and len(data) > 2:
        start = rng.randrange(len(data) - 1)
        del data[start:start + rng.randint(1, 40)]
    elif kind == "insert":
        at = rng.randrange(len(data) + 1)
        data[at:at] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 40)))
    elif kind == "truncate":
        data = data[:rng.randrange(len(data) + 1)]
    else:
        data = bytearray(rng.randbytes(rng.randint(0, 400)))
    return bytes(data)


@pytest.fixture(scope="module")
def valid_files(tmp_path_factory):
    """A finished sweep folder, a finished bvp run folder, and a TOML grid file."""
    root = tmp_path_factory.mktemp("valid")
    sweep = ["sweep", "harmonic", "--grid", "tau0=0.1,0.05", "--set", "t_end=0.5",
             "--methods", "rk4", "--no-progress", "--workers", "1", "--out", str(root / "sweep")]
    assert main(sweep) == 0
    assert main(["bvp", "pendulum", "--nodes", "61", "--no-plot", "--out",
                 str(root / "run")]) == 0
    (root / "grid.toml").write_text('scene = "harmonic"\nmethods = ["rk4"]\n[settings]\n'
                                    't_end = 0.5\n[grid]\ntau0 = [0.1, 0.05]\n')
    return root, sweep


@pytest.mark.slow_when(lambda index, **_: index >= DEFAULT_FILE_CASES,
                       why="repetition")  # cases 0-14 of this test check it by default
@pytest.mark.parametrize("index", range(FILE_CASES))
def test_fuzzed_input_files_are_refused_or_rebuilt(index, valid_files, tmp_path, capsys,
                                                   monkeypatch):
    root, sweep = valid_files
    rng = random.Random(SEED * 7919 + index)
    target = rng.choice(["sweep.csv", "toml", "guess", "manifest"])
    monkeypatch.chdir(tmp_path)
    if target == "sweep.csv":  # a resumed grid reads its rows back
        shutil.copytree(root / "sweep", tmp_path / "sweep")
        path = tmp_path / "sweep" / "sweep.csv"
        path.write_bytes(_mutated(path.read_bytes(), rng))
        argv = [*sweep[:-1], str(tmp_path / "sweep")]
    elif target == "toml":
        path = tmp_path / "grid.toml"
        path.write_bytes(_mutated((root / "grid.toml").read_bytes(), rng))
        argv = ["sweep", "--file", str(path), "--no-progress", "--workers", "1", "--out",
                str(tmp_path / "out")]
    else:
        shutil.copytree(root / "run", tmp_path / "run")
        name = "result.npz" if target == "guess" else "meta.json"
        path = tmp_path / "run" / name
        path.write_bytes(_mutated(path.read_bytes(), rng))
        argv = ["bvp", "pendulum", "--nodes", "61", "--no-plot", "--guess",
                str(tmp_path / "run"), "--out", str(tmp_path / "out")]
    try:
        code = main(argv)
    except SystemExit as stop:
        code = stop.code
    err = capsys.readouterr().err
    _check(code, err, (target, argv))
    if target in ("guess", "manifest") and code != 2:
        # a damaged run folder used as a guess: only if it still reads back whole
        from ddvp_nlp.io.run_folder import read_run

        arrays, _ = read_run(tmp_path / "run")
        assert np.all(np.isfinite(arrays["t"]))
