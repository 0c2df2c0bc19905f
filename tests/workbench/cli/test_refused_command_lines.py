"""Bad inputs of issue 15, each refused with exit code 2 (or InputError) and its exact message,
before anything is built; and a seeded fuzz of the parser, march, solve_bvp and grid files."""

from __future__ import annotations

import random
import warnings
from pathlib import Path

import numpy as np
import pytest

from ddvp_nlp import Compilation, Output, StepControl, Tolerance, load_scene, march, solve_bvp
from ddvp_nlp.cli import main
from ddvp_nlp.errors import InputError

pytestmark = pytest.mark.smoke  # the quick tier: tests/README.md

CASES = [
    # kepler declares e in [0, 1): both ends of the range refused by name before any start
    (["march", "kepler", "--set", "e=1"], "parameter 'e' must lie in [0, 1), got 1.0"),
    (["march", "kepler", "--set", "e=-0.3"], "parameter 'e' must lie in [0, 1), got -0.3"),
    (["march", "./pyproject.toml"], "scene file './pyproject.toml' is not a Python file (.py)"),
    (["march", "missing/scene.py"], "scene file 'missing/scene.py' does not exist"),
    (["compare", "harmonic", "--methods", "rk4", "--halvings", "100000"],
     "--halvings must be at most 40, got 100000"),
    (["compare", "pendulum", "--workers", "0"], "--workers must be a positive integer, got 0"),
    (["sweep", "kepler", "--grid", "tau0=0,0.01"], "tau0 must be > 0, got 0.0"),
    (["sweep", "harmonic", "--grid", "tau0=-0.1", "--methods", "rk4"],
     "tau0 must be > 0, got -0.1"),
    (["march", "harmonic", "--set", "tau0=0.1", "--set", "tau0=0.2"],
     "--set tau0 is given twice ('tau0=0.1' and 'tau0=0.2'); give each setting once"),
    (["march", "harmonic", "--out", ""], "output folder must be a non-empty path, got ''"),
    (["march", "harmonic", "--checkpoint-every", "0"], "--checkpoint-every must be > 0, got 0.0"),
    # one rule for every bad --nodes, the command's own least (a user met "a positive integer"
    # for -5 and "an integer >= 3" for 1)
    (["bvp", "pendulum", "--nodes", "-5"], "--nodes must be an integer >= 3, got -5"),
    (["bvp", "pendulum", "--nodes", "1"], "--nodes must be an integer >= 3, got 1"),
    (["periodic", "pendulum", "--nodes", "3"], "--nodes must be an integer >= 4, got 3"),
    # the option objects check, the command line names the flags (cli/flags.py)
    (["march", "harmonic", "--tau-min", "0.1", "--tau-max", "0.01"],
     "--tau-min must be < --tau-max = 0.01, got 0.1"),
    (["march", "harmonic", "--checkpoint-every", "0.001"],
     "--checkpoint-every must be at least 0.01 s (a checkpoint writes every node so far), got "
     "0.001"),
    # issue 45: taken unchecked unless --stability or --follow was given
    (["periodic", "harmonic", "--stability-tol", "nan"], "--stability-tol must be finite, got nan"),
    (["periodic", "harmonic", "--stability-tol", "inf"], "--stability-tol must be finite, got inf"),
    (["periodic", "harmonic", "--stability-tol", "0"], "--stability-tol must be > 0, got 0.0"),
    (["periodic", "harmonic", "--stability", "--stability-tol=-inf"],
     "--stability-tol must be finite, got -inf"),
    (["periodic", "harmonic", "--step", "nan"], "--step must be finite, got nan"),
    (["periodic", "harmonic", "--max-orbits", "1"], "--max-orbits must be an integer >= 2, got 1"),
    # issue 45: a 6000-character path was answered as an output error (exit 1)
    (["march", "a/" * 3000 + "scene.py"],
     "scene file " + repr(("a/" * 3000)[:120]) + "..." + repr(("a/" * 3000 + "scene.py")[-60:])
     + " (6008 characters) cannot be looked up: File name too long"),
    # issue 45: the checkpoints asked for were left out without a word
    (["march", "harmonic", "--keep-every", "10", "--checkpoint-every", "1"],
     "--checkpoint-every 1 does not apply to a thinned march (--keep-every or --keep t_eval): "
     "a checkpoint is for --resume, which needs every node; give one or the other"),
]


@pytest.mark.parametrize("argv, text", CASES, ids=[" ".join(c[0][:3]) for c in CASES])
def test_bad_command_lines_are_refused(argv, text, capsys, tmp_path, monkeypatch):
    if "pyproject" in argv[1]:
        monkeypatch.chdir(Path(__file__).resolve().parents[3])
    else:
        monkeypatch.chdir(tmp_path)  # a command that wrongly ran writes nothing in the repo
    assert main([*argv, "--no-progress"] if argv[0] != "sweep" else argv) == 2
    assert capsys.readouterr().err == f"ddvp {argv[0]}: error: {text}\n"


@pytest.mark.parametrize("body, text", [
    ("import sys\nsys.exit(0)\n",
     "line 2: loading the file called sys.exit(0); a scene may not end the command"),
    ("from ddvp_nlp import Scene\nscene = Scene(hamiltonian=lambda q, p, t: p[0]**2/2, n=1, "
     "q0=lambda: ['a'], p0=[0.0], tau0=0.1, t_end=1.0)\n",
     "scene 'bad': q0 must be an array of 1 real numbers, got ['a']"),
    ("from ddvp_nlp import Scene\ndef q0():\n    raise RuntimeError('no start')\n"
     "scene = Scene(hamiltonian=lambda q, p, t: p[0]**2/2, n=1, q0=q0, p0=[0.0], tau0=0.1, "
     "t_end=1.0)\n",
     "scene 'bad': q0 cannot be computed for the defaults: RuntimeError: no start"),
])
def test_bad_scene_files_are_refused(tmp_path, capsys, body, text):
    path = tmp_path / "bad.py"
    path.write_text(body)
    assert main(["march", str(path), "--no-progress", "--out", str(tmp_path / "o")]) == 2
    assert text in capsys.readouterr().err


@pytest.mark.parametrize("kwargs, text", [
    (lambda: {"params": [0.5]},
     "params of system 'pendulum' must be a mapping of names to numbers, got [0.5]"),
    (lambda: {"compilation": Compilation(chunk=10**9)},
     "chunk must be at most 65536, got 1000000000"),
    (lambda: {"compilation": Compilation(cache_dir=__file__)},
     f"cache_dir must be a folder, got the file {__file__!r}"),
    (lambda: {"steps": {"tol": 1e-8}},
     "steps must be a StepControl(...), got {'tol': 1e-08}"),
    (lambda: {"accuracy": 1e-3}, "accuracy must be a Tolerance(...), got 0.001"),
])
def test_bad_march_arguments_are_refused(kwargs, text):
    """Bad values are refused by name, when an option object is made or, for a value where an
    option object belongs, by the march."""
    scene = load_scene("pendulum")
    config = scene.resolve({})
    with pytest.raises(InputError) as info:
        march(scene.system, config.q0, config.p0, (0.0, 1.0), tau0=config.tau0, **kwargs())
    assert str(info.value) == text


@pytest.mark.slow(why="processes")
def test_a_damaged_cached_library_is_rebuilt(tmp_path):
    import json
    import os
    import subprocess
    import sys

    from ddvp_nlp.solvers.compiler import find_compiler

    if find_compiler() is None:
        pytest.skip("no C compiler on this machine")
    command = [sys.executable, "-m", "ddvp_nlp.cli", "march", "harmonic", "--no-progress",
               "--no-plot", "--out", str(tmp_path / "run")]
    env = {**os.environ, "DDVP_NLP_CACHE": str(tmp_path / "cache")}
    assert subprocess.run(command, env=env, capture_output=True).returncode == 0
    for library in (tmp_path / "cache").glob("chunk_*.so"):
        library.write_bytes(library.read_bytes()[:100])  # truncated: was a bus error on load
    done = subprocess.run(command, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "run" / "meta.json").read_text())["path"] == "compiled"


@pytest.mark.parametrize("setting", ["cache", "compiler"])
def test_an_unusable_cache_or_compiler_falls_back_with_one_warning(tmp_path, monkeypatch,
                                                                   setting):
    from ddvp_nlp.solvers import compiler

    compiler.forget_warnings()
    cache = tmp_path / "a-file"
    cache.write_text("")
    options = ({"cache_dir": cache / "sub"} if setting == "cache"
               else {"cache_dir": tmp_path / "c", "compiler": "false"})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        solution = march(load_scene("harmonic").system, [1.0], [0.0], (0.0, 2.0), tau0=0.1,
                         compilation=Compilation(**options))
    assert solution.success and solution.stats["path"] == "vm"
    fallbacks = [w for w in caught if "virtual machine instead" in str(w.message)]
    assert len(fallbacks) == 1


# --- fuzz: random bad values, seeded; every one must end in exit 2 / InputError -------------

BAD_VALUES = ["", "nan", "inf", "-inf", "-1", "0", "1e309", "abc", "1,2", "0x10", "--",
              "1e-320", "-0", "=", "a=b", "tau0", "\x00", "é", "9" * 400]
NUMERIC_OPTIONS = ["--tol", "--alpha", "--max-steps", "--tau-min", "--tau-max",
                   "--max-step-ratio", "--time-limit", "--energy-guard", "--checkpoint-every"]
SETTINGS = ["t0", "tau0", "t_end", "q0", "p0", "g", "nope"]
FUZZ_COUNT = 60


def fuzz_argv(rng: random.Random) -> list[str]:
    argv = ["march", rng.choice(["pendulum", "harmonic", "kepler"]), "--no-progress",
            "--no-plot"]
    if rng.random() < 0.5:
        argv += [rng.choice(NUMERIC_OPTIONS), rng.choice(BAD_VALUES)]
    else:
        argv += ["--set", f"{rng.choice(SETTINGS)}={rng.choice(BAD_VALUES)}"]
    return argv


# drawn starts may sit at rest, where the solvability monitor warns
@pytest.mark.filterwarnings("ignore:solvability monitor:RuntimeWarning")
def test_fuzz_command_line(tmp_path, capsys):
    rng = random.Random(15)
    clean = 0
    for _ in range(FUZZ_COUNT):
        argv = [*fuzz_argv(rng), "--out", str(tmp_path / "o"), "--max-steps", "200"]
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse's own refusals: exit 2, a usage message
            code = exc.code
        err = capsys.readouterr().err
        assert "Traceback" not in err
        if code == 2:
            clean += 1
        else:  # a value that happens to be valid runs (a short march): never another failure
            assert code in (0, 1), (argv, code, err)
    assert clean >= FUZZ_COUNT // 2


# where each fuzzed name of the march goes: the call itself, or an option object
MARCH_PLACES = {"q0": None, "p0": None, "tau0": None, "t_end": None, "t0": None,
                "params": None, "scheme": None, "tol": StepControl, "max_steps": StepControl,
                "tau_min": StepControl, "max_step_ratio": StepControl,
                "time_limit": StepControl, "energy_guard": StepControl,
                "breakdown": StepControl, "chunk": Compilation, "rtol": Tolerance,
                "energy_tol": Tolerance, "checkpoint_interval": Output}


def _fuzzed_march(system, name, value):
    """A march of ``harmonic`` with ``name`` set to ``value`` where it belongs."""
    values = {"q0": [1.0], "p0": [0.0], "tau0": 0.1, "t0": 0.0, "t_end": 1.0}
    groups = {StepControl: {"max_steps": 50}, Compilation: {}, Tolerance: {}, Output: {}}
    place = MARCH_PLACES[name]
    (values if place is None else groups[place])[name] = value
    keyword = {StepControl: "steps", Compilation: "compilation", Tolerance: "accuracy",
               Output: "output"}
    options = {keyword[kind]: kind(**fields) for kind, fields in groups.items()}
    extra = {key: values[key] for key in ("params", "scheme") if key in values}
    return march(system, values["q0"], values["p0"], (values["t0"], values["t_end"]),
                 tau0=values["tau0"], **extra, **options)


# drawn starts may sit at rest, where the solvability monitor warns
@pytest.mark.filterwarnings("ignore:solvability monitor:RuntimeWarning")
def test_fuzz_library_calls():
    """Random bad values for every argument and option field: each is refused with an
    InputError (never a traceback from inside), or, where it is harmless, solved."""
    rng = random.Random(16)
    scene = load_scene("harmonic")
    bad = [None, "x", [], [np.nan], [1.0, 2.0], -1.0, 0.0, np.inf, True, {"w": "a"}, 10**30,
           object(), -5, 1e-300]
    refused = 0
    for _ in range(FUZZ_COUNT):
        try:
            _fuzzed_march(scene.system, rng.choice(list(MARCH_PLACES)), rng.choice(bad))
        except InputError:
            refused += 1
    for _ in range(FUZZ_COUNT // 3):
        span, nodes = [0.0, 1.0], 11
        args = [[1.0], [0.5]]
        slot = rng.randrange(5)
        if slot < 2:
            args[slot] = rng.choice(bad)
        elif slot < 4:
            span[slot - 2] = rng.choice(bad)
        else:
            nodes = rng.choice(bad)
        try:
            solve_bvp(scene.system, *args, tuple(span), nodes=nodes)
        except InputError:
            refused += 1
    assert refused >= FUZZ_COUNT


def test_fuzz_grid_files(tmp_path):
    from ddvp_nlp.studies.sweep_file import load_grid_file

    rng = random.Random(17)
    pieces = ['scene = "harmonic"', 'scene = 3', '[axes]', 'w = [1, 2]', 'w = "1,2"',
              'tau0 = [-0.1]', 'q0 = "1,2"', 'count = 100000000', 'w = {from = 1, to = 2, '
              'count = 100000000}', '[settings]', 't_end = "x"', 'methods = ["nope"]', '\xff',
              'max_steps = -1', '[[', 'time_limit = 0']
    for i in range(FUZZ_COUNT):
        path = tmp_path / f"g{i}.toml"
        text = "\n".join(rng.choice(pieces) for _ in range(rng.randint(1, 6)))
        path.write_bytes(text.encode("utf-8", "surrogateescape") if "\xff" not in text
                         else text.encode("latin-1", "replace"))
        try:
            spec = load_grid_file(path)
            from ddvp_nlp.studies.sweep import sweep_cases
            sweep_cases(spec)
        except InputError:
            pass


@pytest.mark.slow_when(lambda expression, **_: expression == "0 * p[0]", why="repetition")
@pytest.mark.parametrize("expression", ["p[0]", "0 * p[0]"])
def test_a_hamiltonian_with_no_well_posed_energy_step_is_refused_by_name(tmp_path, capsys,
                                                                         expression):
    scene = tmp_path / "flat.py"
    scene.write_text("from ddvp_nlp import Scene\n\n\ndef hamiltonian(q, p, t):\n"
                     f"    return {expression}\n\n\n"
                     "scene = Scene(hamiltonian, n=1, q0=[0.0], p0=[1.0], tau0=0.1, t_end=1.0)\n")
    assert main(["march", str(scene), "--no-plot", "--no-progress",
                 "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert ("H of 'flat' has no well-posed vddvp step: the step equations do not determine "
            "(z_next, tau) (their Jacobian is structurally singular: rank 2 of 3)") in err
    assert "Traceback" not in err
    assert main(["march", str(scene), "--scheme", "fixed", "--no-plot", "--no-progress",
                 "--out", str(tmp_path / "fixed")]) in (0, 1)


def test_a_fixed_endpoint_grid_too_large_for_the_machine_is_refused(capsys):
    assert main(["bvp", "pendulum", "--nodes", "1000000000", "--no-plot"]) == 2
    err = capsys.readouterr().err
    assert "nodes = 1000000000 needs about 800 GB with solver 'auto'" in err
    assert "this machine has available" in err and "Traceback" not in err


def fuzz_other_argv(rng: random.Random, out) -> list[str]:
    """One bad value in one option of bvp, compare or sweep; the rest keeps a valid run short."""
    command = rng.choice(["bvp", "compare", "sweep"])
    bad = rng.choice(BAD_VALUES)
    if command == "bvp":
        option = rng.choice([["--nodes", bad], ["--tol", bad], ["--time-limit", bad],
                             ["--set", f"q_end={bad}"], ["--set", f"t_end={bad}"],
                             ["--solver", bad], ["--guess", bad]])
        return ["bvp", "pendulum", "--no-plot", "--nodes", "21", *option, "--out", str(out)]
    if command == "compare":
        option = rng.choice([["--halvings", bad], ["--repeats", bad], ["--workers", bad],
                             ["--methods", bad], ["--set", f"tau0={bad}"]])
        return ["compare", "harmonic", "--methods", "rk4", "--halvings", "0", "--repeats", "1",
                "--set", "t_end=1", "--no-progress", *option, "--out", str(out)]
    option = rng.choice([["--grid", f"w={bad}"], ["--grid", f"{bad}=1,2"],
                         ["--grid", f"tau0={bad}"], ["--methods", bad], ["--workers", bad]])
    return ["sweep", "harmonic", "--methods", "rk4", "--set", "t_end=1", "--grid", "w=1",
            *option, "--workers", "1", "--no-progress", "--out", str(out)]


def test_fuzz_other_commands(tmp_path, capsys):
    """bvp, compare and sweep over random bad values: exit 2 with a message, or (a value that
    happens to be valid) a short run; never a traceback or another exit code."""
    rng = random.Random(18)
    clean = 0
    for i in range(FUZZ_COUNT // 2):
        argv = fuzz_other_argv(rng, tmp_path / f"o{i}")
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
        err = capsys.readouterr().err
        assert "Traceback" not in err, argv
        if code == 2:
            clean += 1
        else:
            assert code in (0, 1), (argv, code, err)
    assert clean >= FUZZ_COUNT // 4
