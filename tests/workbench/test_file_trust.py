"""What a file says is checked like the command line (issue 39): a run folder is data, never
code or authority (``--resume`` rebuilds the system from the scene the user names, checked
against the fingerprint the run kept); a folder being written is busy for readers too; default
folder names carry every input that changes the result; grid rows are reused only when the
manifest vouches for their file; ``--cluster FILE`` is read like any file the user names."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from ddvp_nlp import InputError
from ddvp_nlp.cli import main

HARMONIC = """from ddvp_nlp import Scene
def H(q, p, t):
    return p[0]**2/2 + {k}*q[0]**2/2
scene = Scene(H, n=1, q0=[1.0], p0=[0.0], tau0=0.1, t_end=2)
"""


def test_periodic_of_a_scene_whose_energy_is_nowhere_finite_on_the_ray_says_so(tmp_path,
                                                                                capsys):
    """H = p^2/2 - 1/q^2 on the section q1 = 0 is infinite along the whole start ray: the
    message had been numpy's 'zero-size array to reduction operation minimum'."""
    scene = tmp_path / "singular.py"
    scene.write_text("from ddvp_nlp import Scene\ndef H(q, p, t):\n    return p[0]**2/2 - "
                     "1/q[0]**2\nscene = Scene(H, n=1, q0=[1.0], p0=[0.5], tau0=0.01, "
                     "t_end=1)\n")
    code = main(["periodic", str(scene), "--energy", "0.5", "--nodes", "20", "--section",
                 "q1=0", "--no-plot", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "H is not finite anywhere on the start's ray of the section q1=0" in err
    assert "zero-size" not in err and "Traceback" not in err


def _run(tmp_path, scene="h.py", k="1", out="run", *extra):
    (tmp_path / "h.py").write_text(HARMONIC.format(k=k))
    return main(["march", str(tmp_path / scene) if scene.endswith(".py") else scene,
                 "--no-plot", "--no-progress", "--out", str(tmp_path / out), *extra])


def _edit_meta(folder, change):
    meta = json.loads((folder / "meta.json").read_text())
    change(meta)
    (folder / "meta.json").write_text(json.dumps(meta))


def test_resume_runs_no_scene_file_the_run_folder_names(tmp_path, capsys):
    """``--resume F`` had imported whatever .py file F/meta.json named: a planted file ran."""
    assert _run(tmp_path) == 0
    evil = tmp_path / "evil.py"
    evil.write_text(f"open({str(tmp_path / 'pwned')!r}, 'w').write('x')\n")
    _edit_meta(tmp_path / "run", lambda m: m["resume"].update(scene=str(evil)))
    capsys.readouterr()
    assert main(["march", "--resume", str(tmp_path / "run"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "name it on the command line" in err and str(evil) in err
    assert not (tmp_path / "pwned").exists()
    # named on the command line, it is the user's own file: run, and refused by its content
    assert main(["march", str(evil), "--resume", str(tmp_path / "run"), "--no-progress"]) == 2
    assert "is not the file the run was computed from" in capsys.readouterr().err
    assert not (tmp_path / "pwned").exists()  # refused by its SHA-256 before it ran


def test_resume_refuses_an_edited_scene_naming_both(tmp_path, capsys):
    assert _run(tmp_path) == 0
    assert main(["march", str(tmp_path / "h.py"), "--resume", str(tmp_path / "run"),
                 "--t-end", "3", "--no-plot", "--no-progress"]) == 0
    (tmp_path / "h.py").write_text(HARMONIC.format(k="2"))  # another H
    capsys.readouterr()
    assert main(["march", str(tmp_path / "h.py"), "--resume", str(tmp_path / "run"),
                 "--t-end", "4", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "is not the file the run was computed from" in err
    assert err.count("SHA-256") == 2 and "Traceback" not in err
    # a built-in scene the run never used is refused the same way
    assert main(["march", "harmonic", "--resume", str(tmp_path / "run"), "--no-progress"]) == 2
    assert "'harmonic'" in capsys.readouterr().err


def test_resume_refuses_settings_changed_in_the_record(tmp_path, capsys):
    """The fingerprint covers the settings too: a record whose overrides were edited does not
    continue another run into this folder."""
    assert main(["march", "harmonic", "--set", "w=2", "--set", "t_end=2", "--no-plot",
                 "--no-progress", "--out", str(tmp_path / "run")]) == 0
    _edit_meta(tmp_path / "run", lambda m: m["resume"]["overrides"].update(w=3.0))
    capsys.readouterr()
    assert main(["march", "--resume", str(tmp_path / "run"), "--no-progress"]) == 2
    assert "is not what the run was computed from" in capsys.readouterr().err


@pytest.mark.parametrize("change, message", [
    (lambda m: m["resume"]["options"].update(out="/tmp/elsewhere"), "names the option 'out'"),
    (lambda m: m["resume"]["options"].update(tol="1e-3"), "gives tol = '1e-3'"),
    (lambda m: m["resume"]["options"].update(alpha=7.0),
     "--alpha must be a number in [0, 1], got 7.0"),
    # the folder's value, not a flag the user gave: said so (issue 45)
    (lambda m: m["resume"]["options"].update(tau_min=float("nan")),
     "the run's recorded options are refused (meta.json resume.options; not a value given on "
     "this command line): --tau-min must be finite, got nan"),
    (lambda m: m["resume"]["options"].update(scheme="rk4"), "gives the scheme 'rk4'"),
    (lambda m: m["resume"]["overrides"].update(w="__import__('os')"), "not a number"),
    (lambda m: m["resume"].pop("fingerprint"), "records no fingerprint"),
    (lambda m: m.update(carried={"drift": "nan", "careful_left": 0, "phase": 0}),
     "is not one ddvp wrote"),
    (lambda m: m.update(carried={"drift": 0.0, "careful_left": -1, "phase": 0}),
     "is not one ddvp wrote"),
])
def test_a_resume_record_is_data_checked_like_the_command_line(tmp_path, capsys, change,
                                                               message):
    assert main(["march", "harmonic", "--set", "t_end=2", "--no-plot", "--no-progress",
                 "--out", str(tmp_path / "run")]) == 0
    _edit_meta(tmp_path / "run", change)
    capsys.readouterr()
    assert main(["march", "--resume", str(tmp_path / "run"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and "internal error" not in err


def _hold_lock(folder):
    """Another process holding the folder's lock as a writer does, until its stdin closes."""
    script = ("import fcntl, os, sys; fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT); "
              "fcntl.flock(fd, fcntl.LOCK_EX); os.write(fd, b'4242'); print('held', "
              "flush=True); sys.stdin.read()")
    holder = subprocess.Popen([sys.executable, "-c", script, str(folder / ".ddvp.lock")],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline() == "held\n"  # a line read, not a time waited
    return holder


@pytest.mark.slow(why="processes")
def test_a_folder_being_written_is_busy_for_resume_and_for_readers(tmp_path, capsys):
    """A second --resume of a folder being written had failed with a node-count mismatch
    (it read a set half-swapped); the folder's lock is taken before anything is read."""
    from ddvp_nlp.io.atomic import FolderBusy
    from ddvp_nlp.io.run_folder import read_run

    assert main(["march", "harmonic", "--set", "t_end=2", "--no-plot", "--no-progress",
                 "--out", str(tmp_path / "run")]) == 0
    holder = _hold_lock(tmp_path / "run")
    try:
        capsys.readouterr()
        assert main(["march", "--resume", str(tmp_path / "run"), "--t-end", "3",
                     "--no-progress"]) == 2
        err = capsys.readouterr().err
        assert "is busy" in err and "pid 4242" in err and "Traceback" not in err
        with pytest.raises(FolderBusy, match="is busy: another ddvp process \\(pid 4242\\)"):
            read_run(tmp_path / "run")
        assert main(["periodic", "harmonic", "--guess", str(tmp_path / "run"), "--energy",
                     "0.5", "--nodes", "20", "--no-plot", "--out", str(tmp_path / "orbit")]) == 2
        assert "is busy" in capsys.readouterr().err
    finally:
        holder.stdin.close()
        holder.wait()
    arrays, meta = read_run(tmp_path / "run")  # free again; the reader leaves no lock file
    assert meta["status"] == "success" and not (tmp_path / "run" / ".ddvp.lock").exists()


@pytest.mark.slow(why="processes")
def test_default_folders_differ_by_every_input_that_changes_the_result(tmp_path, capsys,
                                                                       monkeypatch):
    """--event, --t-eval and the scene file's content had been left out of the default
    folder's name: such runs overwrote each other."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "h.py").write_text(HARMONIC.format(k="1"))

    def folder(*argv):
        capsys.readouterr()
        assert main(["march", *argv, "--no-plot", "--no-progress"]) == 0
        return capsys.readouterr().out.split("written to ")[1].split("/")[1]

    plain = folder("harmonic")
    event = folder("harmonic", "--event", "q1")
    other_event = folder("harmonic", "--event", "q1;up")
    times = folder("harmonic", "--t-eval", "0:1:3")
    scene = folder("h.py")
    (tmp_path / "h.py").write_text(HARMONIC.format(k="2"))
    edited = folder("h.py")
    assert len({plain, event, other_event, times, scene, edited}) == 6
    assert plain == "harmonic-vddvp" and folder("harmonic", "--event", "q1") == event
    (tmp_path / "h.py").write_text(HARMONIC.format(k="1"))
    assert folder("h.py") == scene  # the same content finds its folder again


# -- files the user names, drawn at random: a checked object or an InputError, nothing else --

def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return {"nan": "nan", "inf": "inf", "-inf": "-inf"}.get(repr(value), repr(value))
    if isinstance(value, (int, str)):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(v)}" for k, v in value.items()) + "}"


def _toml(tables: dict) -> str:
    lines = []
    for key, value in tables.items():
        if isinstance(value, dict):
            lines.append(f"[{json.dumps(key)}]")
            lines += [f"{json.dumps(k)} = {_toml_value(v)}" for k, v in value.items()]
        else:
            lines.insert(0, f"{json.dumps(key)} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"


_SCALARS = st.one_of(st.integers(-10, 10**6), st.integers(), st.floats(), st.booleans(),
                     st.sampled_from(["local", "slurm", "16GB", "01:00:00", "a b", "x\ny",
                                      "harmonic", "kepler", "rk4", "vddvp", "evil.py",
                                      "--exclusive;--x=1", "$(reboot)", "2.9", "1e400"]),
                     st.text(max_size=8))
_VALUES = st.recursive(_SCALARS, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.sampled_from(
        ["from", "to", "count", "x", "w", "e"]), inner, max_size=3)), max_leaves=8)


@pytest.mark.slow(why="processes")
@given(table=st.dictionaries(st.sampled_from(
    ["kind", "workers", "threads", "cores", "memory", "processes", "queue", "account",
     "walltime", "job_extra", "jobs", "other"]), _VALUES, max_size=5),
    kind=st.sampled_from(["local", "slurm", "pbs", 3, None]))
@settings(max_examples=150, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_any_cluster_file_is_a_checked_description_or_refused(tmp_path, table, kind):
    from ddvp_nlp.runner.cluster import MAXIMA, ClusterSpec, parse_cluster

    if kind is not None:
        table = {**table, "kind": kind}
    path = tmp_path / "cluster.toml"
    path.write_text(_toml({"cluster": table}))
    try:
        spec = parse_cluster(str(path))
    except InputError as exc:
        assert str(exc).startswith("--cluster")
        return
    assert isinstance(spec, ClusterSpec) and spec.kind in ("local", "slurm")
    for name, value in spec.settings.items():
        if isinstance(value, int):
            assert not isinstance(value, bool) and 1 <= value <= MAXIMA.get(name, 10**6)
        else:
            assert "\n" not in value and "$" not in value


@given(doc=st.dictionaries(st.sampled_from(["scene", "methods", "settings", "grid", "bounds",
                                            "other"]), _VALUES, max_size=5))
@settings(max_examples=50, deadline=None, derandomize=True,  # 150 before the CPU budget
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_any_grid_file_is_a_checked_sweep_or_refused_and_runs_no_code(tmp_path, doc):
    from ddvp_nlp.studies.sweep_file import load_grid_file

    (tmp_path / "evil.py").write_text(f"open({str(tmp_path / 'pwned')!r}, 'w')\n")
    path = tmp_path / "grid.toml"
    path.write_text(_toml(doc))
    try:
        spec = load_grid_file(path)
    except InputError:
        pass
    else:
        assert spec.axes and all(np.all(np.isfinite(v)) for v in spec.axes.values())
    assert not (tmp_path / "pwned").exists()


@pytest.mark.parametrize("make, message", [
    (lambda p: p.symlink_to("/dev/zero"), "it is a symbolic link, which ddvp does not follow"),
    (lambda p: os.mkfifo(p), "is not a regular file"),
    (lambda p: p.write_bytes(b"#" * (1 << 17)), "bytes, more than the"),
    (lambda p: p.write_text('[cluster]\nkind = "local"\nworkers = 100000\n'),
     "workers = 100000 is more than this machine can hold"),
    (lambda p: p.write_text('[cluster]\nkind = "local"\nworkers = 2.9\n'),
     "workers must be int (a whole number), got 2.9"),
    (lambda p: p.write_text('[cluster]\nkind = "slurm"\nqueue = "x\\n#!/bin/sh"\n'),
     "queue must be a partition name"),
])
def test_a_cluster_file_is_checked_like_the_command_line(tmp_path, capsys, make, message):
    path = tmp_path / "cluster.toml"
    make(path)
    assert main(["stress", "--quick", "--cluster", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and not (tmp_path / "o").exists()


def test_a_device_named_as_a_cluster_file_is_not_read(capsys):
    assert main(["stress", "--quick", "--cluster", "/dev/zero"]) == 2
    assert "--cluster /dev/zero: the file '/dev/zero' is not a regular file" in \
        capsys.readouterr().err


def test_workers_on_the_command_line_and_in_a_description_are_checked_alike(capsys):
    assert main(["stress", "--quick", "--workers", "100000"]) == 2
    flag = capsys.readouterr().err
    assert main(["stress", "--quick", "--cluster", "local:workers=100000"]) == 2
    described = capsys.readouterr().err
    assert "workers = 100000 is more than this machine can hold" in flag
    assert "workers = 100000 is more than this machine can hold" in described


def test_a_slurm_cluster_without_sbatch_is_a_quick_exit_2(tmp_path, capsys, monkeypatch):
    pytest.importorskip("dask_jobqueue")
    monkeypatch.setenv("PATH", str(tmp_path))  # no sbatch
    assert main(["stress", "--quick", "--cluster", "slurm:cores=2", "--out",
                 str(tmp_path / "o")]) == 2
    assert "sbatch was not found on the PATH" in capsys.readouterr().err


_JSON = st.recursive(st.one_of(st.none(), st.booleans(), st.integers(), st.floats(),
                               st.sampled_from(["evil.py", "harmonic", "pendulum", "vddvp",
                                                "running", "march", "../x", "a" * 64]),
                               st.text(max_size=6)),
                     lambda inner: st.one_of(st.lists(inner, max_size=3),
                                             st.dictionaries(st.text(max_size=5), inner,
                                                             max_size=3)), max_leaves=6)
_META_PATHS = [("resume", "scene"), ("resume", "options", "tol"), ("resume", "options", "scheme"),
               ("resume", "options", "alpha"), ("resume", "options", "out"),
               ("resume", "overrides", "w"), ("resume", "overrides", "q0"),
               ("resume", "fingerprint"), ("resume", "scene_sha256"), ("resume",),
               ("carried",), ("carried", "drift"), ("carried", "phase"), ("status",),
               ("command",), ("nodes",), ("files",), ("files", "result.npz", "sha256"),
               ("files", "result.npz")]
_FILE_DAMAGE = ["none", "no result", "garbage result", "result a folder", "meta a link",
                "lock a folder", "lock a link", "meta truncated", "previous twin only"]


@given(changes=st.lists(st.tuples(st.sampled_from(_META_PATHS), st.one_of(st.just("delete"),
                                                                            _JSON)),
                        max_size=3),
       damage=st.sampled_from(_FILE_DAMAGE), named=st.sampled_from([None, "harmonic", "h.py",
                                                                    "evil.py"]))
@example(changes=[], damage="none", named="h.py")  # the run continued
@example(changes=[], damage="previous twin only", named="h.py")  # cut between two renames
@example(changes=[(("resume", "scene"), "evil.py")], damage="none", named=None)
@settings(max_examples=25, deadline=None, derandomize=True,  # 60 before the CPU budget
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_any_state_of_a_run_folder_is_resumed_checked_or_refused(tmp_path_factory, capsys,
                                                                 changes, damage, named):
    """Random edits of meta.json and damage to the files: --resume continues the run, or
    refuses it with a message (exit 2), or says it failed (exit 1); never a traceback, never
    code the command line did not name, never a run it did not check."""
    import shutil

    root = tmp_path_factory.mktemp("resume")
    base = _base_run(tmp_path_factory)
    shutil.copytree(base, root, dirs_exist_ok=True, symlinks=True)
    (root / "evil.py").write_text(f"open({str(root / 'pwned')!r}, 'w')\n")
    folder = root / "run"
    meta = json.loads((folder / "meta.json").read_text())
    for path, value in changes:
        _set(meta, path, value)
    (folder / "meta.json").write_text(json.dumps(meta))
    _damage(folder, damage)
    argv = ["march", *([str(root / named)] if named and named.endswith(".py") else
                       [named] if named else []), "--resume", str(folder), "--no-progress",
            "--no-plot", "--t-end", "3"]
    capsys.readouterr()
    code = main(argv)
    err = capsys.readouterr().err
    assert code in (0, 1, 2), err
    assert "Traceback" not in err and "internal error" not in err, err
    assert not (root / "pwned").exists()
    if code == 0:  # only a run the checks passed: this scene, its settings, its options
        from ddvp_nlp.io.run_folder import read_run

        arrays, written = read_run(folder)
        assert named in (None, "h.py") and written["status"] == "success"
        assert arrays["t"][-1] >= 3.0 and written["resume"]["scene"].endswith("h.py")


def _base_run(factory):
    base = factory.getbasetemp() / "resume-base"
    if not (base / "run" / "meta.json").exists():
        base.mkdir(exist_ok=True)
        (base / "h.py").write_text(HARMONIC.format(k="1"))
        assert main(["march", str(base / "h.py"), "--no-plot", "--no-progress", "--out",
                     str(base / "run")]) == 0
    return base


def _set(meta, path, value):
    node = meta
    for key in path[:-1]:
        if not isinstance(node.get(key), dict):
            node[key] = {}
        node = node[key]
    if value == "delete":
        node.pop(path[-1], None)
    else:
        node[path[-1]] = value


def _damage(folder, damage):
    result = folder / "result.npz"
    if damage == "no result":
        result.unlink()
    elif damage == "garbage result":
        result.write_bytes(b"PK\x03\x04" + b"\0" * 100)
    elif damage == "result a folder":
        result.unlink()
        result.mkdir()
    elif damage == "meta a link":
        (folder / "elsewhere.json").write_text((folder / "meta.json").read_text())
        (folder / "meta.json").unlink()
        (folder / "meta.json").symlink_to(folder / "elsewhere.json")
    elif damage == "lock a folder":
        (folder / ".ddvp.lock").mkdir()
    elif damage == "lock a link":
        (folder / ".ddvp.lock").symlink_to(folder / "nowhere")
    elif damage == "meta truncated":
        (folder / "meta.json").write_text((folder / "meta.json").read_text()[:50])
    elif damage == "previous twin only":
        result.rename(folder / ".result.npz.previous")


# march options that change only how a run is shown or saved, and those named in the folder
# otherwise (the label holds the scene and the scheme; --set goes through the resolved
# settings; --t-eval and --event through requested_options; --t-end only with --resume)
SHOWN_ONLY = {"help", "out", "progress", "no_plot", "figure_format", "checkpoint_every"}
NAMED_OTHERWISE = {"scene", "scheme", "method", "settings", "resume", "t_end", "t_eval",
                   "events"}


def test_every_march_option_is_in_the_default_folders_name_or_said_not_to_change_the_result():
    """A new option of ddvp march that changes the result must name the default folder
    (--target-error had been left out: its run overwrote the main job's folder)."""
    from ddvp_nlp.cli.one_run import RESULT_OPTIONS, result_options
    from ddvp_nlp.cli.parser import build_parser, parse_arguments
    from ddvp_nlp.cli.request import Request

    parser = build_parser("march")
    march = parser.commands["march"]
    dests = {action.dest for action in march._actions}
    assert dests - set(RESULT_OPTIONS) - SHOWN_ONLY - NAMED_OTHERWISE == set()
    args = Request.read(parse_arguments(parser, ["march", "x", "--target-error", "1e-3"]), march)
    assert result_options(args) == {"target_error": 1e-3}
