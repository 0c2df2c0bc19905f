"""A scene's code is bounded by its work, not by the clock (issue 39): CPU time, and time
asleep, each up to the limit, while the time it waits for a processor on a loaded machine
counts for neither; a scene that defeats the in-process timers, ends the process or leaves a
thread behind is handled from outside by the command's supervising process
(``cli/supervisor.py``), and the command always ends after saving."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from ddvp_nlp import load_scene
from ddvp_nlp.cli import main
from ddvp_nlp.errors import InputError

HEAD = "from ddvp_nlp import Scene\ndef H(q, p, t):\n    return p[0]**2/2 + q[0]**2/2\n"
TAIL = "scene = Scene(H, n=1, q0=[1.0], p0=[0.0], tau0=0.1, t_end=1)\n"
LONG = ["--set", "t_end=1e7", "--max-steps", "3000000", "--checkpoint-every", "0.05"]


def scene(tmp_path, body: str, name="scene.py"):
    path = tmp_path / name
    path.write_text(HEAD + body + "\n" + TAIL)
    return path


def command(tmp_path, *argv, limit="0.5"):
    """The real command (supervised), its output and exit code."""
    env = {**os.environ, "DDVP_SCENE_TIME_LIMIT": limit}
    process = subprocess.Popen([sys.executable, "-m", "ddvp_nlp.cli", *argv], cwd=tmp_path,
                               env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    out, err = process.communicate()
    return process.returncode, out, err


@pytest.mark.slow(why="processes")
@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="needs CPU affinity")
def test_a_scene_that_waits_for_a_busy_processor_is_not_refused(tmp_path):
    """0.6 s of CPU work with a limit of 1 s, sharing one processor with a busy process: it
    takes over a second of the clock, which the old limit (wall time) refused; its work is
    what counts."""
    path = scene(tmp_path, "import time\nstart = time.process_time()\n"
                           "while time.process_time() - start < 0.6:\n    pass\n")
    cpu = sorted(os.sched_getaffinity(0))[0]
    pin = lambda: os.sched_setaffinity(0, {cpu})  # noqa: E731
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"], preexec_fn=pin)
    try:
        loader = subprocess.run(
            [sys.executable, "-c", "import sys, time; from ddvp_nlp import load_scene; "
             "start = time.monotonic(); load_scene(sys.argv[1]); "
             "print(time.monotonic() - start)", str(path)],
            env={**os.environ, "DDVP_SCENE_TIME_LIMIT": "1"}, preexec_fn=pin,
            capture_output=True, text=True)
    finally:
        busy.kill()
        busy.wait()
    assert loader.returncode == 0, loader.stderr
    assert float(loader.stdout) > 1.0  # it did wait for the processor: the clock alone refused


def test_a_scene_asleep_past_the_limit_is_refused_with_its_line(tmp_path, monkeypatch):
    monkeypatch.setenv("DDVP_SCENE_TIME_LIMIT", "0.3")
    path = scene(tmp_path, "import threading\nthreading.Event().wait()")
    with pytest.raises(InputError, match=r"line 5: loading the file waited .* s without "
                                         r"computing \(asleep"):
        load_scene(str(path))


def test_a_scene_is_put_back_where_it_was_found(tmp_path, monkeypatch):
    """A scene's os.chdir had moved where a relative --out landed."""
    monkeypatch.chdir(tmp_path)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    path = scene(tmp_path, f"import os, signal\nos.chdir({str(elsewhere)!r})\nos.umask(0)\n"
                           "signal.signal(signal.SIGTERM, signal.SIG_IGN)")
    before = signal.getsignal(signal.SIGTERM)
    assert main(["march", str(path), "--no-plot", "--no-progress", "--out", "run"]) == 0
    assert (tmp_path / "run" / "meta.json").exists() and not (elsewhere / "run").exists()
    assert signal.getsignal(signal.SIGTERM) == before
    mask = os.umask(0o022)
    os.umask(mask)
    assert mask != 0


@pytest.mark.slow(why="processes")
def test_a_scene_that_defeats_the_timers_is_ended_from_outside(tmp_path):
    """It ignores the timers' signals and loops: only another process can end it."""
    scene(tmp_path, "import signal\nfor s in (signal.SIGALRM, signal.SIGPROF):\n"
                    "    signal.signal(s, signal.SIG_IGN)\nwhile True:\n    pass")
    code, _, err = command(tmp_path, "march", "scene.py", "--out", "run")
    assert code == 2, err
    assert "scene file 'scene.py': loading the file went on past its limit of 0.5 s" in err
    assert "of CPU time) and did not stop when told" in err and "Traceback" not in err
    assert not (tmp_path / "run").exists()


def test_a_scene_that_ends_the_process_is_exit_2_naming_it(tmp_path):
    """posix._exit slipped past the os._exit guard; a signal to itself passes any guard."""
    scene(tmp_path, "import posix\nposix._exit(0)", name="exits.py")
    scene(tmp_path, "import os, signal\nos.kill(os.getpid(), signal.SIGKILL)", name="kills.py")
    code, _, err = command(tmp_path, "march", "exits.py", "--out", "run")
    assert code == 2 and "line 5: loading the file called os._exit(0)" in err
    code, _, err = command(tmp_path, "march", "kills.py", "--out", "run")
    assert code == 2 and "scene file 'kills.py': loading the file ended the process (signal " \
                         "SIGKILL); a scene may not end the command" in err


def test_a_thread_left_behind_does_not_keep_the_command_alive(tmp_path):
    """A non-daemon thread had kept the command alive after its result was saved, deaf to
    SIGTERM; the command ends once saved."""
    scene(tmp_path, "import threading\nthreading.Thread(target=threading.Event().wait).start()")
    code, out, err = command(tmp_path, "march", "scene.py", "--no-plot", "--no-progress",
                             "--out", "run")
    assert code == 0, err
    assert "written to run/" in out
    assert json.loads((tmp_path / "run" / "meta.json").read_text())["status"] == "success"


def test_a_process_ended_mid_run_by_a_scene_thread_never_exits_0(tmp_path):
    """A scene's thread that calls _exit(0) once the first checkpoint is written: the run is
    not finished, and the exit code had said success."""
    scene(tmp_path, "import os, posix, threading, time\n"
                    "def end():\n"
                    "    while not os.path.exists('run/meta.json'):\n"
                    "        time.sleep(0.01)\n"
                    "    posix._exit(0)\n"
                    "threading.Thread(target=end, daemon=True).start()")
    code, _, err = command(tmp_path, "march", "scene.py", "--no-plot", "--no-progress", *LONG,
                           "--out", "run")
    assert code == 1, err
    assert "ended (exit 0) before it was done" in err
    assert json.loads((tmp_path / "run" / "meta.json").read_text())["status"] == "running"


# Every command is supervised: io/test_run_folder_faults.py's
# test_interrupts_end_with_the_run_written[sigterm] checks the same (exit 1, these words, the
# run written whole and "interrupted") by default.
@pytest.mark.slow(why="repetition")
def test_sigterm_still_ends_a_supervised_march_after_saving(tmp_path):
    process = subprocess.Popen([sys.executable, "-m", "ddvp_nlp.cli", "march", "pendulum",
                                "--no-plot", "--no-progress", *LONG, "--out", "run"],
                               cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    meta = tmp_path / "run" / "meta.json"
    for _ in range(100_000):  # polls for the first checkpoint, not a time bound
        if meta.exists() or process.poll() is not None:
            break
        time.sleep(0.01)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate()
    assert process.returncode == 1, err
    assert "interrupted (SIGTERM); the run was written whole" in err
    assert json.loads(meta.read_text())["status"] == "interrupted"


# A scene's plain subprocess is the daemon's repetition: both are left to the supervisor (the
# subprocess once its parent, the child, is gone; the daemon at once, in a session of its own,
# out of the child's process group); the daemon case keeps the property by default.
@pytest.mark.slow_when(lambda how, **_: how == "subprocess", why="processes")
@pytest.mark.parametrize("how", ["subprocess", "daemon"])
def test_the_processes_a_scene_starts_end_with_the_command(tmp_path, how):
    """A scene's subprocess, or a daemon it detaches (double fork, new session), outlived the
    command (issue 45): the supervisor adopts what is left behind and ends it, and says so."""
    start = {
        "subprocess": "import subprocess\nchild = subprocess.Popen(['sleep', '300'])\n"
                      "open('pid', 'w').write(str(child.pid))\n",
        "daemon": "import os\nif os.fork() == 0:\n    os.setsid()\n    if os.fork() == 0:\n"
                  "        open('pid', 'w').write(str(os.getpid()))\n"
                  "        os.execvp('sleep', ['sleep', '300'])\n    os._exit(0)\n"
                  "os.wait()\n",
    }[how]
    scene(tmp_path, start)
    code, out, err = command(tmp_path, "march", "scene.py", "--no-plot", "--no-progress",
                             "--out", "run")
    assert code == 0, err
    pid = int((tmp_path / "pid").read_text())
    with pytest.raises(ProcessLookupError):  # ended and reaped: no such process left
        os.kill(pid, 0)
    assert "left running" in err and f"{pid} (sleep)" in err
