"""Crash safety of a run folder: the real command in a subprocess, killed, interrupted, starved
of disk or raced by other writers; then the folder is read back with the checking reader.

No test has a wall-clock bound: waiting is a bounded number of polls for a file to appear.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from ddvp_nlp.errors import InputError
from ddvp_nlp.io.run_folder import read_run

# A march far longer than any test waits for: it is always stopped from outside.
ENDLESS = ["march", "pendulum", "--set", "t_end=1e7", "--no-progress", "--no-plot",
           "--checkpoint-every", "0.2"]
POLLS = 3000  # of 0.05 s each: how long a test waits for a checkpoint, at most


def ddvp(args, **kwargs) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "ddvp_nlp.cli", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs)


def wait_for_checkpoint(out, process, *, after: float = 0.0) -> dict:
    """The metadata of the first checkpoint written after ``after`` (a ``meta.json`` mtime)."""
    meta = out / "meta.json"
    for _ in range(POLLS):
        if meta.exists() and meta.stat().st_mtime > after:
            data = json.loads(meta.read_text())
            if data["status"] == "running":
                return data
        assert process.poll() is None, process.communicate()
        time.sleep(0.05)
    process.kill()
    raise AssertionError("no checkpoint was written")


@pytest.mark.slow(why="repetition")  # test_sigkill_over_an_earlier_run_... checks it all too
def test_sigkill_mid_run_keeps_the_last_checkpoint_whole(tmp_path):
    out = tmp_path / "run"
    process = ddvp([*ENDLESS, "--out", str(out)])
    first = wait_for_checkpoint(out, process)
    wait_for_checkpoint(out, process, after=(out / "meta.json").stat().st_mtime)
    process.kill()
    process.wait()
    arrays, meta = read_run(out)
    assert meta["status"] == "running" and meta["nodes"] == arrays["t"].size
    assert arrays["t"].size > first["nodes"] > 1
    assert np.all(np.diff(arrays["t"]) > 0) and arrays["q"].shape == (arrays["t"].size, 1)


def test_sigkill_over_an_earlier_run_leaves_one_whole_run(tmp_path):
    from ddvp_nlp.cli import main

    out = tmp_path / "run"  # the earlier run, written in this process (one start less)
    assert main(["march", "pendulum", "--no-progress", "--no-plot", "--out", str(out)]) == 0
    process = ddvp([*ENDLESS, "--out", str(out)])
    first = wait_for_checkpoint(out, process)  # over the earlier run
    wait_for_checkpoint(out, process, after=(out / "meta.json").stat().st_mtime)  # over itself
    process.kill()
    process.wait()
    arrays, meta = read_run(out)  # the checkpoint, whole, never the old meta with a new npz
    assert meta["status"] == "running" and arrays["t"].size == meta["nodes"]
    assert arrays["t"].size > first["nodes"] > 1
    assert np.all(np.diff(arrays["t"]) > 0) and arrays["q"].shape == (arrays["t"].size, 1)


@pytest.mark.slow_when(lambda signals, **_: len(signals) == 2, why="processes")
@pytest.mark.parametrize("signals", [[signal.SIGINT, signal.SIGINT], [signal.SIGTERM],
                                     [signal.SIGHUP]],
                         ids=["two-ctrl-c", "sigterm", "sighup"])  # sighup: a closed terminal
def test_interrupts_end_with_the_run_written(tmp_path, signals):
    out = tmp_path / "run"
    process = ddvp([*ENDLESS, "--out", str(out)])
    wait_for_checkpoint(out, process)
    for sig in signals:
        process.send_signal(sig)
    _, stderr = process.communicate()
    assert process.returncode == 1
    assert "Traceback" not in stderr
    arrays, meta = read_run(out)
    assert meta["status"] == "interrupted" and meta["nodes"] == arrays["t"].size > 1
    assert meta["message"].startswith("interrupted by the user")
    assert f"interrupted ({signals[0].name}); the run was written whole" in stderr


@pytest.mark.slow(why="processes")
def test_concurrent_writers_leave_one_whole_run(tmp_path):
    """Writers racing for one folder: each either writes its run whole and says so, or is
    refused (exit 1) while another holds the folder; none is replaced in silence."""
    out = tmp_path / "run"
    ends = ["3", "4", "5", "6"]
    processes = [ddvp(["march", "harmonic", "--set", f"t_end={end}", "--no-progress",
                       "--out", str(out)]) for end in ends]
    written = []
    for end, process in zip(ends, processes, strict=True):
        stdout, stderr = process.communicate()
        assert "Traceback" not in stderr
        if process.returncode == 0:
            assert "written to" in stdout
            written.append(float(end))
        else:
            assert process.returncode == 1 and "is writing this folder" in stderr, stderr
            assert "written to" not in stdout
    arrays, meta = read_run(out)
    assert written and meta["params"]["t_end"] in written
    assert arrays["t"][-1] >= meta["params"]["t_end"] and meta["nodes"] == arrays["t"].size
    assert not [p for p in out.iterdir() if ".tmp" in p.name]


def test_a_full_disk_ends_with_exit_1_naming_the_file(tmp_path):
    out = tmp_path / "run"

    def small_files():  # files past 64 kB fail with EFBIG, as on a full disk
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (64_000, 64_000))

    done = subprocess.run([sys.executable, "-m", "ddvp_nlp.cli", "march", "pendulum",
                           "--set", "t_end=200", "--no-progress", "--no-plot", "--out", str(out)],
                          capture_output=True, text=True, preexec_fn=small_files)
    assert done.returncode == 1
    assert done.stderr.startswith(f"ddvp march: error: cannot write {out / 'result.npz'}: "
                                  "File too large; the run (")
    assert f"was not saved; {out}/ holds no complete result" in done.stderr
    assert "Traceback" not in done.stderr
    assert not out.exists()  # the folder it created for the run is gone again


def wait_until_stopped(group: int) -> None:
    """Until every process of ``group`` is stopped: ``killpg(SIGSTOP)`` returns once the signal
    is sent, and a writer on the other core may still be inside a write (a removal then failed
    with 'Directory not empty' once in six runs under load). Polls /proc, a bounded count."""
    for _ in range(20_000):
        states = []
        for entry in os.listdir("/proc"):
            try:
                with open(f"/proc/{entry}/stat") as stat:
                    fields = stat.read().rsplit(")", 1)[1].split()
            except (OSError, IndexError):  # not a process, or gone
                continue
            if int(fields[2]) == group:
                states.append(fields[0])
        if states and all(state in "tT" for state in states):
            return
        time.sleep(0.001)
    raise AssertionError(f"process group {group} did not stop: {states}")


def test_a_folder_gone_mid_run_ends_with_exit_1_naming_the_path(tmp_path):
    """The folder is removed while the command is frozen (SIGSTOP to its process group): a
    removal racing the checkpoints written meanwhile had failed with 'Directory not empty'."""
    out = tmp_path / "run"
    process = ddvp([*ENDLESS, "--out", str(out)], start_new_session=True)
    wait_for_checkpoint(out, process)
    os.killpg(process.pid, signal.SIGSTOP)  # no writer runs while the folder goes
    try:
        wait_until_stopped(process.pid)
        shutil.rmtree(out)
        out.write_text("not a folder any more")
    finally:
        os.killpg(process.pid, signal.SIGCONT)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate()
    assert process.returncode == 1
    assert "Traceback" not in stderr
    assert f"ddvp march: error: cannot write {out}/" in stderr
    assert "was not saved" in stderr


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes to read-only folders")
def test_a_read_only_folder_is_refused_before_the_march(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    out.chmod(0o555)
    done = subprocess.run([sys.executable, "-m", "ddvp_nlp.cli", "march", "harmonic",
                           "--no-progress", "--out", str(out)], capture_output=True, text=True)
    assert done.returncode == 1
    assert f"cannot write {out / '.ddvp.lock'}: Permission denied" in done.stderr


def test_reader_refuses_a_result_beside_another_runs_meta(tmp_path):
    from ddvp_nlp.cli import main

    for name, end in (("a", "3"), ("b", "4")):
        assert main(["march", "harmonic", "--set", f"t_end={end}", "--no-progress",
                     "--no-plot", "--out", str(tmp_path / name)]) == 0
    shutil.copy(tmp_path / "a" / "meta.json", tmp_path / "b" / "meta.json")
    with pytest.raises(InputError) as info:
        read_run(tmp_path / "b")
    assert str(info.value) == (
        f"{tmp_path / 'b' / 'result.npz'} is not the file {tmp_path / 'b' / 'meta.json'} "
        "describes (result.npz: its checksum differs; .result.npz.previous: No such file or "
        "directory): the set was cut while writing, or changed by another tool")


@pytest.mark.slow(why="processes")
def test_a_study_told_to_stop_never_exits_0(tmp_path):
    """SIGTERM a second into `ddvp compare`: wherever it lands (the imports, a march's Newton
    inside CasADi, where it surfaces as that run's failure, or between runs) the command exits
    1 and says it was interrupted; it never reports a finished study (scripts/pages/faults.py had
    caught compare writing its files and exiting 0 after the signal)."""
    process = subprocess.Popen(
        [sys.executable, "-m", "ddvp_nlp.cli", "compare", "harmonic", "--set", "t_end=400",
         "--no-progress", "--out", str(tmp_path / "out")],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(1.0)
    process.send_signal(signal.SIGTERM)
    out, err = process.communicate(timeout=600)
    assert process.returncode == 1, (out, err)
    assert "interrupted" in err and "Traceback" not in err


@pytest.mark.parametrize("signo", [0, 1234, int(signal.SIGCONT)])
def test_a_wait_for_signals_cut_short_forwards_nothing_it_was_not_sent(monkeypatch, signo):
    """CPython's ``sigtimedwait`` interrupted by a stop and continue after its timeout returns
    an unfilled siginfo (garbage number): forwarding it had ended the command with a traceback
    ('os.kill: Invalid argument') when a run was frozen and continued."""
    from types import SimpleNamespace

    from ddvp_nlp.cli import supervisor

    sent = []
    fake = SimpleNamespace(si_signo=signo, si_code=0)
    monkeypatch.setattr(supervisor.signal, "sigtimedwait", lambda *_: fake)
    monkeypatch.setattr(supervisor.os, "kill", lambda *a: sent.append(a))
    parent = supervisor.Parent.__new__(supervisor.Parent)
    parent.child, parent.stop = 12345, None
    parent._signals()
    assert sent == [] and parent.stop is None
    fake.si_signo = int(signal.SIGINT)
    monkeypatch.setattr(parent, "_sample", lambda: "sampled", raising=False)
    parent._signals()
    assert sent == [(12345, int(signal.SIGINT))] and parent.stop == "sampled"
