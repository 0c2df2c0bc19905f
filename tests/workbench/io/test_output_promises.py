"""The promises of issue 28, each tested on the real code: the output layer (links, the lock,
every write point failing, a kill between two renames), grid files read back, scene code
bounded, sizes and options checked by name, default folders by setting, checkpoints on time,
workers that end with their parent. No wall-clock bound: waits are bounded counts of polls.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ddvp_nlp.cli import main
from ddvp_nlp.errors import InputError, OutputError
from ddvp_nlp.io import atomic
from ddvp_nlp.io.run_folder import read_run, save_run

VICTIM = "must not change\n"


def _set(folder, generation: int):
    return save_run(folder, {"t": np.arange(generation + 2.0), "q": np.zeros((generation + 2, 1)),
                             "p": np.zeros((generation + 2, 1))}, {"status": f"g{generation}"})


# -- the output layer ------------------------------------------------------------------------

def test_planted_links_are_replaced_never_followed(tmp_path):
    victim = tmp_path / "victim"
    victim.write_text(VICTIM)
    out = tmp_path / "run"
    out.mkdir()
    for name in ("result.npz", "meta.json", "trajectory.png"):
        (out / name).symlink_to(victim)
    (out / "missing.npz").symlink_to(tmp_path / "absent")
    _set(out, 1)
    assert victim.read_text() == VICTIM and not (tmp_path / "absent").exists()
    assert not (out / "result.npz").is_symlink() and read_run(out)[1]["status"] == "g1"


def test_a_link_at_the_lock_or_the_folder_is_refused(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / ".ddvp.lock").symlink_to(tmp_path / "target")
    with pytest.raises(OutputError, match="symbolic link"):
        _set(out, 1)
    assert not (tmp_path / "target").exists()
    (tmp_path / "real").mkdir()
    (tmp_path / "linked").symlink_to(tmp_path / "real")
    with pytest.raises(OutputError, match="linked: it is a symbolic link"):
        _set(tmp_path / "linked", 1)
    assert list((tmp_path / "real").iterdir()) == []


def test_a_second_writer_is_refused_while_the_first_holds_the_folder(tmp_path):
    out = tmp_path / "run"
    with atomic.output_folder(out):
        other = subprocess.run([sys.executable, "-c", "from ddvp_nlp.io import atomic; "
                                f"atomic.open_folder({str(out)!r})"], capture_output=True,
                               text=True)
        assert other.returncode != 0 and "is writing this folder" in other.stderr
    assert not (out / ".ddvp.lock").exists()  # released and removed


def test_a_kill_between_two_renames_leaves_the_previous_set_readable(tmp_path, monkeypatch):
    """Every moment of a swap: the renames stop after the k-th (as a SIGKILL would), and the
    reader still finds a complete set, the old or the new one."""
    out = tmp_path / "run"
    _set(out, 1)
    real_rename = os.rename
    for stop_after in range(3):  # before, between and after the renames of a set
        calls = []

        def rename(src, dst, *args, stop_after=stop_after, calls=calls, **kwargs):
            if len(calls) == stop_after:
                raise KeyboardInterrupt  # the process dies here
            calls.append(dst)
            return real_rename(src, dst, *args, **kwargs)

        monkeypatch.setattr(os, "rename", rename)
        with pytest.raises(KeyboardInterrupt):
            _set(out, 2 + stop_after)
        monkeypatch.setattr(os, "rename", real_rename)
        arrays, meta = read_run(out)
        assert meta["status"] in {"g1", f"g{2 + stop_after}"}
        assert arrays["t"].size == meta["nodes"]
        _set(out, 1)  # a later writer completes over the leftovers
        assert read_run(out)[1]["status"] == "g1"


@pytest.mark.parametrize("call", ["open", "rename", "fsync", "mkdir"])
@pytest.mark.parametrize("error", [errno.ENOSPC, errno.EROFS, errno.ENAMETOOLONG])
def test_every_write_point_failing_is_an_output_error_naming_the_path(tmp_path, monkeypatch,
                                                                      call, error):
    """Each call of the layer failing in turn (as a full, read-only or too-long path does):
    an OutputError that names a path of the folder, no scratch file left, the earlier set
    readable."""
    out = tmp_path / "run"
    _set(out, 1)
    real = getattr(os, call)
    for failing in range(12):
        count = [0]

        def failing_call(*args, failing=failing, count=count, **kwargs):
            count[0] += 1
            if count[0] == failing + 1:
                raise OSError(error, os.strerror(error))
            return real(*args, **kwargs)

        monkeypatch.setattr(os, call, failing_call)
        try:
            _set(out / "sub" if call == "mkdir" else out, 2)
        except OutputError as exc:
            assert str(tmp_path) in str(exc) and os.strerror(error) in str(exc)
        finally:
            monkeypatch.setattr(os, call, real)
        assert read_run(out)[1]["status"] in ("g1", "g2")
        assert not [p for p in out.rglob(".*.tmp")]
        _set(out, 1)


def _small_tmpfs(tmp_path):
    mount = tmp_path / "fs"
    mount.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mount)],
                          capture_output=True)
    if done.returncode != 0:
        pytest.skip("no tmpfs can be mounted here (the fault script says what stands in)")
    return mount


@pytest.mark.slow_when(lambda state, **_: state == "read-only", why="processes")
@pytest.mark.parametrize("state", ["full", "read-only"])
def test_a_real_full_or_read_only_file_system(tmp_path, state):
    mount = _small_tmpfs(tmp_path)
    try:
        run = [sys.executable, "-m", "ddvp_nlp.cli", "march", "harmonic", "--no-progress",
               "--out", str(mount / "run")]
        assert main(run[3:]) == 0  # the earlier run, written in this process (one start less)
        before = read_run(mount / "run")[1]
        if state == "full":
            free = os.statvfs(mount).f_bavail * os.statvfs(mount).f_frsize
            (mount / "filler").write_bytes(b"\0" * max(0, free - 4096))
        else:
            subprocess.run(["mount", "-o", "remount,ro", str(mount)], check=True)
        done = subprocess.run([*run[:-1], str(mount / "run"), "--set", "t_end=30"],
                              capture_output=True, text=True)
        assert done.returncode == 1 and "Traceback" not in done.stderr
        assert f"cannot write {mount / 'run'}" in done.stderr
        assert read_run(mount / "run")[1] == before  # the earlier run, whole
        assert not [p.name for p in (mount / "run").iterdir() if p.name.startswith(".")]
    finally:
        subprocess.run(["umount", "-l", str(mount)], capture_output=True)


# -- grid files read back --------------------------------------------------------------------

# One cheap run (a third of the CPU of two methods at two steps): what is read back here is the
# table's file, whatever rows it holds.
SWEEP = ["sweep", "harmonic", "--grid", "tau0=0.1", "--set", "t_end=1", "--methods", "rk4",
         "--no-progress", "--workers", "1"]


def test_a_forged_success_row_is_run_again(tmp_path, capsys):
    out = tmp_path / "out"
    assert main([*SWEEP, "--out", str(out)]) == 0
    lines = (out / "sweep.csv").read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[1].split(",")
    cells[header.index("energy_error")] = "1e-30"  # a better number than was measured
    lines[1] = ",".join(cells)
    (out / "sweep.csv").write_text("\n".join(lines) + "\n")
    from ddvp_nlp.runner.journal import JournalWarning

    with pytest.warns(JournalWarning,
                      match="is not the file its manifest describes .*its checksum differs"):
        assert main([*SWEEP, "--out", str(out)]) == 0
    assert "1e-30" not in (out / "sweep.csv").read_text()


@pytest.mark.slow_when(lambda content, **_: content.startswith(b"cl"), why="repetition")
@pytest.mark.parametrize("content, reason", [
    (b"\xff\xfe" + bytes(range(256)) * 8, "not UTF-8 text"),
    ("clé,été\n".encode("latin-1"), "not UTF-8 text"),
    (b"key,x\n" + b"a" * 300_000 + b",1\n", "start the table afresh"),
    (b"other,columns\n1,2\n", "other columns"),
])
def test_a_damaged_grid_file_is_refused_by_name(tmp_path, capsys, content, reason):
    out = tmp_path / "out"
    out.mkdir()
    (out / "sweep.csv").write_bytes(content)
    assert main([*SWEEP, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(out / "sweep.csv") in err and reason in err
    assert (out / "sweep.csv").read_bytes() == content  # refused, not overwritten
    assert main([*SWEEP, "--out", str(out), "--fresh"]) == 0  # afresh: replaced


@pytest.mark.slow(why="processes")
def test_a_second_grid_never_wipes_another_grids_rows(tmp_path, capsys):
    out = tmp_path / "out"
    assert main([*SWEEP, "--out", str(out)]) == 0
    kept = (out / "sweep.csv").read_text()
    other = [*SWEEP[:3], "tau0=0.2,0.3", *SWEEP[4:]]
    assert main([*other, "--out", str(out)]) == 2
    assert "rows of another table" in capsys.readouterr().err
    assert (out / "sweep.csv").read_text() == kept
    # the default folders of two grids differ
    os.chdir(tmp_path)
    assert main(SWEEP) == 0 and main(other) == 0
    assert len(list((tmp_path / "runs").iterdir())) == 2


def test_a_sweep_whose_every_task_failed_exits_1(tmp_path, capsys):
    assert main(["sweep", "kepler", "--grid", "e=0.9,0.95", "--set", "tau0=0.5",
                 "--methods", "vddvp", "--no-progress", "--workers", "1", "--out",
                 str(tmp_path / "out")]) == 1
    assert "every one of the 2 runs failed" in capsys.readouterr().err


def test_a_grid_file_runs_no_scene_file_it_was_not_allowed(tmp_path, capsys):
    evil = tmp_path / "evil.py"
    evil.write_text(f"open({str(tmp_path / 'pwned')!r}, 'w').write('x')\n")
    grid = tmp_path / "grid.toml"
    grid.write_text(f'scene = "{evil}"\n[grid]\nw = [1.0]\n')
    assert main(["sweep", "--file", str(grid)]) == 2
    assert "--allow-scene" in capsys.readouterr().err and not (tmp_path / "pwned").exists()
    (tmp_path / "deep.toml").write_text("a = " + "[" * 10_000 + "]" * 10_000 + "\n")
    assert main(["sweep", "--file", str(tmp_path / "deep.toml")]) == 2
    assert main(["sweep", "--file", "/dev/zero"]) == 2
    assert "not a regular file" in capsys.readouterr().err


@pytest.mark.parametrize("content, reason", [
    (b"PK\x03\x04 not a zip", "is not a result.npz"),
    (None, "must hold real numbers"),
])
def test_a_bad_guess_is_refused(tmp_path, capsys, content, reason):
    path = tmp_path / "guess.npz"
    if content is None:
        t = np.linspace(0, 1, 5)
        np.savez(path, t=t, q=np.zeros((5, 1)) + 1j, p=np.zeros((5, 1)))
    else:
        path.write_bytes(content)
    assert main(["bvp", "pendulum", "--guess", str(path), "--no-plot", "--out",
                 str(tmp_path / "o")]) == 2
    assert reason in capsys.readouterr().err


# -- scenes, sizes, options ------------------------------------------------------------------

SCENE_HEAD = "from ddvp_nlp import Scene\n"
SCENE_TAIL = "scene = Scene(H, n=1, q0=[1.0], p0=[0.0], tau0=0.1, t_end=1)\n"


@pytest.mark.slow_when(lambda text, **_: "did not return" in text, why="processes")
@pytest.mark.parametrize("body, text", [
    ("raise GeneratorExit('boom')\n", "line 2: loading the file raised GeneratorExit: boom"),
    ("class Boom(BaseException):\n    pass\nraise Boom('x')\n", "line 4: loading the file "
     "raised Boom: x"),
    ("import os\ndef H(q, p, t):\n    os._exit(5)\n", "line 4: H called os._exit(5)"),
    ("import sys\ndef H(q, p, t):\n    sys.exit(7)\n", "line 4: H called sys.exit(7)"),
    ("def H(q, p, t):\n    while True:\n        pass\n", "H did not return within 1 s"),
])
def test_a_scene_that_misbehaves_is_refused_with_its_line(tmp_path, capsys, monkeypatch, body,
                                                          text):
    monkeypatch.setenv("DDVP_SCENE_TIME_LIMIT", "1")
    path = tmp_path / "bad.py"
    path.write_text(SCENE_HEAD + body + SCENE_TAIL)
    assert main(["march", str(path), "--no-progress", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"scene file {str(path)!r}" in err and text in err
    assert os._exit.__module__ in ("posix", "nt", "os")  # restored


@pytest.mark.parametrize("argv, text", [
    (["march", "pendulum", "--set", "tau0=5e-324"], "tau0 = 5e-324 is too small"),
    (["march", "pendulum", "--time-limit", "nan"], "--time-limit must be finite"),
    (["march", "pendulum", "--method", "dop853", "--tol", "0"], "--tol must be > 0"),
    (["compare", "pendulum", "--methods", ""], "--methods must be comma-separated"),
    (["sweep", "harmonic", "--grid", "w=1,1"], "has the value 1.0 twice"),
    (["poincare", "henon_heiles", "--energy", "0.1", "--section", ""], "--section must be"),
    (["poincare", "henon_heiles", "--energy", "0.1", "--seed", "-1"], "--seed must be"),
    (["poincare", "henon_heiles", "--energy", "0.1", "--orbits", "4000000000"],
     "more than this machine can hold"),
    (["periodic", "pendulum", "--family", "0.1:0.5:1000000000"],
     "more than this machine can hold"),
])
def test_numbers_are_checked_by_name_before_anything_is_built(tmp_path, capsys, argv, text):
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    assert text in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow(why="repetition")
def test_default_folders_carry_every_setting_that_changes_the_result(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    base = ["march", "harmonic", "--set", "t_end=1", "--no-progress", "--no-plot"]
    for extra in ([], ["--alpha", "0.3"], ["--clock", "left"], ["--tol", "1e-9"]):
        assert main([*base, *extra]) == 0
    for energy in ("0.3", "0.6"):
        assert main(["periodic", "harmonic", "--energy", energy, "--nodes", "41",
                     "--no-plot"]) == 0
    folders = sorted(p.name for p in (tmp_path / "runs").iterdir())
    assert len(folders) == 6 and len({f.split("-")[-1] for f in folders}) == 6


# -- checkpoints and workers -----------------------------------------------------------------

def test_checkpoints_land_on_their_multiples_of_the_interval():
    """On a test clock: each save costs time proportional to the nodes; the checkpoints start
    early by the measured cost, so they land at 5, 10, 15 ... (the first by a guess of the
    cost; each later one within a tenth of its cost before, or one stepper call after)."""
    from ddvp_nlp.solvers.marching.monitors import Checkpoint

    now = [0.0]

    class Nodes:
        t = np.zeros(200_000)
        z = np.zeros((200_000, 2))
        count = 1

    def save(t, z):
        now[0] += 2e-6 * t.size  # 0.3 s for 150 000 nodes

    saver = Checkpoint(save, 5.0, clock=lambda: now[0])
    nodes = Nodes()
    for _ in range(3000):
        now[0] += 0.01
        nodes.count += 50
        saver.watch(nodes, 0, None)
        if saver.thread is not None:
            saver.thread.join()
    landed = np.array(saver.landed)
    targets = 5.0 * np.arange(1, landed.size + 1)
    assert landed.size == int(now[0] // 5)
    first_cost = 2e-6 * 50 * 5.0 / 0.01  # the first save's own cost, 0.05 s
    assert 5.0 <= landed[0] <= 5.0 + first_cost + 0.01
    # later ones start early by their cost, estimated a tenth high (at most 0.3 s here): they
    # land at most 0.03 s early, or one call (0.01 s) late
    early = landed[1:] - targets[1:]
    assert np.all(early >= -0.031) and np.all(early <= 0.011)


def test_ensemble_workers_end_with_their_killed_parent(tmp_path):
    tag = f"ddvp-test-{os.getpid()}"
    env = {**os.environ, "DDVP_TEST_TAG": tag}
    process = subprocess.Popen([sys.executable, "-m", "ddvp_nlp.cli", "poincare",
                                "henon_heiles", "--energy", "0.1", "--orbits", "8",
                                "--t-end", "5000", "--no-plot", "--out", str(tmp_path / "o")],
                               env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for _ in range(600):  # until its workers are running
        if len(_tagged(tag)) >= 3:
            break
        time.sleep(0.05)
    assert len(_tagged(tag)) >= 3
    process.send_signal(signal.SIGKILL)
    process.wait()
    for _ in range(100):
        if not _tagged(tag):
            break
        time.sleep(0.05)
    assert _tagged(tag) == []


def _tagged(tag: str) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if f"DDVP_TEST_TAG={tag}".encode() in (entry / "environ").read_bytes():
                    found.append(int(entry.name))
            except OSError:
                pass
    return found


def test_read_run_refuses_a_folder_without_a_manifest_naming_it(tmp_path):
    out = tmp_path / "run"
    _set(out, 1)
    meta = json.loads((out / "meta.json").read_text())
    del meta["files"]
    (out / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(InputError, match="lists no files"):
        read_run(out)


def _written_while_stopped(folder, edit=lambda solution: solution):
    """A short pendulum march (``edit``ed) written by ``write_run`` with an interrupt at the
    first optional part: ``(meta, solution)``."""
    import contextlib

    from ddvp_nlp import load_scene, march
    from ddvp_nlp.discrete.scheme import Scheme
    from ddvp_nlp.io.run_folder import write_run

    scene = load_scene("pendulum")
    config = scene.resolve({"t_end": 2.0})
    solution = edit(march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                          tau0=config.tau0))

    @contextlib.contextmanager
    def stopped():
        raise KeyboardInterrupt
        yield

    return write_run(folder, command="march", scene=scene, config=config, scheme=Scheme(),
                     solution=solution, interruptible=stopped), solution


def test_a_run_stopped_by_the_user_is_written_without_its_optional_parts(tmp_path, capsys):
    """What an interrupt leaves out while a run is written (energies at every node, the
    scene's checks, the figure) is said in meta.json, and the summary still prints."""
    from ddvp_nlp.cli.summary import print_summary

    meta, solution = _written_while_stopped(tmp_path / "run")
    assert meta["checks"].startswith("not computed") and "trajectory.png" not in meta["files"]
    arrays, _ = read_run(tmp_path / "run")
    assert arrays["t"].size == solution.t.size
    print_summary(meta, tmp_path / "run")
    assert "not computed: the run was interrupted" in capsys.readouterr().out


def test_residuals_not_computed_are_written_as_none_not_as_zero(tmp_path):
    """An interrupted march of 3.3 million steps is written without its residuals (found by a
    user: meta.json read canonical_residual_max 0.0, residuals that were never computed)."""
    import dataclasses

    meta, unchecked = _written_while_stopped(
        tmp_path / "run", lambda solution: dataclasses.replace(
            solution, canonical_residual=np.zeros(0), energy_residual=np.zeros(0)))
    assert unchecked.steps > 0
    assert meta["canonical_residual_max"] is None and meta["energy_residual_max"] is None
    assert json.loads((tmp_path / "run" / "meta.json").read_text())[
        "canonical_residual_max"] is None
