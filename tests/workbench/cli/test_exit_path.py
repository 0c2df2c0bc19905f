"""The command's edges in time: a signal while a cluster starts or closes is acted on only
once it has (``runner/tasks.py``, ``held_signals``), and the supervised child leaves without
the interpreter's finalization, where a daemon thread still holding a stream had aborted it
(exit -6, "Python runtime state: finalizing"; ``cli/supervisor.py``, ``_leave``)."""

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import pytest

from ddvp_nlp.cli import supervisor
from ddvp_nlp.runner.tasks import held_signals

needs_supervisor = pytest.mark.skipif(not supervisor.available(),
                                      reason="the supervisor needs fork and /proc")


@pytest.mark.skipif(not hasattr(signal, "pthread_sigmask"), reason="needs signal masks")
def test_a_held_signal_taken_by_another_thread_waits_for_the_end_of_the_hold():
    """Another thread (Dask's event loop) takes a SIGTERM the main thread blocks; its Python
    handler had then run in the main thread inside the hold (a cluster's close cut short).
    It runs once, after the hold."""
    calls = []
    quiet = threading.Event()
    bystander = threading.Thread(target=quiet.wait, daemon=True)  # signals open in it
    bystander.start()
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: calls.append(signum))
    try:
        with held_signals():
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(20):  # the main thread passes many points where handlers run
                time.sleep(0.005)
                sum(range(1000))
            inside = list(calls)
        for _ in range(20):
            if calls:
                break
            time.sleep(0.005)
    finally:
        signal.signal(signal.SIGTERM, previous)
        quiet.set()
    assert inside == []
    assert calls == [signal.SIGTERM]


def test_an_ignored_signal_stays_ignored_after_the_hold():
    previous = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        with held_signals():
            os.kill(os.getpid(), signal.SIGHUP)
            time.sleep(0.01)
        assert signal.getsignal(signal.SIGHUP) == signal.SIG_IGN
    finally:
        signal.signal(signal.SIGHUP, previous)


LEAVING = textwrap.dedent("""
    import atexit, ctypes, json, os, sys
    from ddvp_nlp.cli import supervisor

    class Teardown:
        def __del__(self, write=os.write):  # freed by the interpreter's finalization
            write(2, b"finalized\\n")

    def work():
        json.teardown_marker = Teardown()  # held by a module: freed only as modules are
        atexit.register(lambda: print("exit hook ran"))
        sys.stdout.write("python's buffer, ")  # a pipe: block-buffered
        ctypes.CDLL(None).printf(b"C's buffer\\n")
        return 7

    sys.exit(supervisor.supervise(work))
""")


@needs_supervisor
def test_the_child_runs_its_exit_hooks_flushes_and_skips_finalization(tmp_path):
    result = subprocess.run([sys.executable, "-c", LEAVING], capture_output=True, text=True,
                            cwd=tmp_path, timeout=120)
    assert result.returncode == 7, result.stderr
    assert "python's buffer, " in result.stdout
    assert "C's buffer" in result.stdout
    assert "exit hook ran" in result.stdout
    assert "finalized" not in result.stderr


SIGNALLED_AT_EXIT = textwrap.dedent("""
    import atexit, os, signal, sys, time
    from ddvp_nlp.cli import supervisor

    def signalled():  # an exit hook during which the supervisor passes a signal on
        for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            os.kill(os.getppid(), signum)
            time.sleep(0.2)

    def work():
        atexit.register(signalled)
        return 3

    sys.exit(supervisor.supervise(work))
""")


@needs_supervisor
def test_a_signal_once_the_work_is_done_changes_no_exit_code(tmp_path):
    """Once its work has returned, the child ignores the signals the parent passes on, however
    it was started (not only through the command's own handling): the exit code is the
    work's, not a death by SIGTERM (-15) or a KeyboardInterrupt in an exit hook."""
    result = subprocess.run([sys.executable, "-c", SIGNALLED_AT_EXIT], capture_output=True,
                            text=True, cwd=tmp_path, timeout=120)
    assert result.returncode == 3, result.stderr
    assert "Traceback" not in result.stderr


SWEEP = ["sweep", "harmonic", "--grid", "tau0=0.1,0.05", "--grid", "w=1,2", "--set",
         "t_end=20", "--methods", "vddvp,rk4", "--workers", "2", "--no-progress", "--out", "out"]


def _sweep_signalled(tmp_path, ready) -> tuple[int, str]:
    """The real ``ddvp sweep`` on a local cluster, SIGTERM to its supervising process as soon
    as ``ready(out)`` holds (polled); its exit code and stderr."""
    process = subprocess.Popen([sys.executable, "-m", "ddvp_nlp.cli", *SWEEP], cwd=tmp_path,
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    while process.poll() is None and not ready(tmp_path / "out"):
        time.sleep(0.002)
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=300)
    return process.returncode, err


def _every_row_in(out) -> bool:
    try:
        return len((out / "sweep.partial.csv").read_text().splitlines()) >= 9
    except OSError:
        return False


@needs_supervisor
@pytest.mark.slow(why="processes")
@pytest.mark.parametrize("ready", [_every_row_in, lambda out: (out / "sweep.csv").exists()],
                         ids=["as-the-cluster-closes", "as-the-table-is-written"])
def test_sigterm_at_the_end_of_a_sweep_ends_it_with_its_code(tmp_path, ready):
    """A SIGTERM as the last row lands (the cluster closing) or as the table is written ends
    the sweep with 0 or 1, no abort (exit -6 in the interpreter's finalization, once), no
    traceback, its folder readable."""
    from ddvp_nlp.io import read_set

    code, err = _sweep_signalled(tmp_path, ready)
    assert code in (0, 1), err
    assert "Fatal Python error" not in err and "Traceback" not in err
    assert "left running" not in err  # the cluster's workers ended with it
    if (tmp_path / "out" / "meta.json").exists():
        read_set(tmp_path / "out")


def _wait_for_interrupt(seconds: float) -> bool:
    """Whether a KeyboardInterrupt reached this thread within ``seconds``."""
    try:
        for _ in range(int(seconds / 0.01)):
            time.sleep(0.01)
    except KeyboardInterrupt:
        return True
    return False


def test_a_swallowed_interrupt_is_raised_again_while_the_command_runs():
    """The first signal's KeyboardInterrupt, swallowed (a compared method's run failed with
    it and the table went on: ``ddvp compare`` then ran every remaining run), is raised again
    AGAIN_S later; not once the command is ending, nor once its handlers are gone."""
    from ddvp_nlp.cli.interrupts import AGAIN_S, Interrupts

    interrupts = Interrupts()
    restore = interrupts.install()
    try:
        with pytest.raises(KeyboardInterrupt):
            interrupts.handle(signal.SIGINT, None)
        assert _wait_for_interrupt(3 * AGAIN_S)  # swallowed above: it comes again
        interrupts.end()
        assert not _wait_for_interrupt(1.5 * AGAIN_S)  # ending: noted only
    finally:
        restore()
    interrupts = Interrupts()
    restore = interrupts.install()
    try:
        with pytest.raises(KeyboardInterrupt):
            interrupts.handle(signal.SIGTERM, None)
    finally:
        restore()
    assert not _wait_for_interrupt(1.5 * AGAIN_S)  # the handlers are gone: nothing
