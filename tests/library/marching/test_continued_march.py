"""A march continued from its run folder or its state: the continued nodes equal an
uninterrupted run's bit for bit (a documented property: ``solvers/marching/resume.py``), on the
compiled and the careful path, also where chunk steps failed and the careful path took windows."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from ddvp_nlp import Compilation, InputError, StepControl
from ddvp_nlp.solvers.marching import MarchState, continue_march, march


def _same(a, b) -> bool:
    return all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("t", "q", "p"))


@pytest.mark.slow_when(lambda fast, **_: not fast, why="repetition")
@pytest.mark.parametrize("fast", [True, False])
def test_a_march_cut_anywhere_continues_bit_for_bit(fast, scene_of):
    """Kepler e = 0.5 with tau_max just under the free steps: chunk steps fail their check and
    the careful path's least-squares step takes the rest of each chunk's window, so where the
    run was inside a chunk decides which path takes which step."""
    scene = scene_of("kepler")
    config = scene.resolve({"e": 0.5, "t_end": 30.0 if fast else 8.0})
    # tau0 = 0.01 (the scene's default before it was made accurate at 0.001): the free steps
    # pass tau_max below, so chunk steps fail and the careful path takes over
    common = dict(tau0=0.01, params=config.params, accuracy=None,
                  compilation=Compilation(fast=fast, chunk=64))
    steps = dict(breakdown="least_squares", tau_max=0.95 * 0.0512)
    whole = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                  steps=StepControl(**steps), **common)
    assert whole.success
    if fast:  # the case that needs the carried state: failed chunk steps
        assert whole.stats["careful_steps"] > 10 and whole.stats["fast_steps"] > 100
    for cut in (37, 100, whole.steps // 2):
        part = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                     steps=StepControl(**steps, max_steps=cut), **common)
        assert part.steps == cut
        state = MarchState.of(part.t, part.q, part.p, config.t_end, part.march.carried)
        continued = continue_march(scene.system, state, steps=StepControl(**steps), **common)
        assert _same(continued, whole), cut


def test_a_finished_march_extends_to_a_later_end_bit_for_bit(scene_of):
    scene = scene_of("henon_heiles")
    c = scene.resolve()
    whole = march(scene.system, c.q0, c.p0, (0.0, 120.0), tau0=c.tau0)
    half = march(scene.system, c.q0, c.p0, (0.0, 60.0), tau0=c.tau0)
    state = MarchState.of(half.t, half.q, half.p, 60.0, half.march.carried)
    assert _same(continue_march(scene.system, state, 120.0, tau0=c.tau0), whole)


def test_a_continuation_refuses_what_would_not_be_the_same_run(scene_of):
    scene = scene_of("henon_heiles")
    c = scene.resolve()
    half = march(scene.system, c.q0, c.p0, (0.0, 10.0), tau0=c.tau0)
    state = MarchState.of(half.t, half.q, half.p, 10.0, half.march.carried)
    with pytest.raises(InputError, match="t_end must be at least"):
        continue_march(scene.system, state, 5.0, tau0=c.tau0)
    other = 2.5 * c.tau0  # not the first step the run took
    with pytest.raises(InputError, match=f"tau0 = {other!r} did not make"):
        continue_march(scene.system, state, 20.0, tau0=other)
    with pytest.raises(InputError, match="carried state"):
        MarchState.of(half.t, half.q, half.p, 10.0, None)
    fixed = march(scene.system, c.q0, c.p0, (0.0, 10.0), tau0=c.tau0, scheme="fixed")
    state = MarchState.of(fixed.t, fixed.q, fixed.p, 10.0, fixed.march.carried)
    with pytest.raises(InputError, match="fixed-step march cannot be extended"):
        continue_march(scene.system, state, 20.0, tau0=c.tau0, scheme="fixed")


def _ddvp(*args, cwd):
    return subprocess.run([sys.executable, "-m", "ddvp_nlp.cli", *args], cwd=cwd,
                          capture_output=True, text=True)


@pytest.mark.slow(why="processes")
def test_a_killed_march_resumes_from_its_checkpoint_bit_for_bit(tmp_path):
    """SIGKILL once a checkpoint has landed, then `ddvp march --resume`: the same nodes as a
    run that was never stopped."""
    args = ["henon_heiles", "--set", "t_end=40000", "--no-plot", "--no-progress"]
    child = subprocess.Popen([sys.executable, "-m", "ddvp_nlp.cli", "march", *args,
                              "--out", "killed", "--checkpoint-every", "0.05"], cwd=tmp_path,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    meta = tmp_path / "killed" / "meta.json"
    for _ in range(6000):  # polls, not a time bound: the kill waits for the first checkpoint
        if meta.exists() and json.loads(meta.read_text()).get("status") == "running":
            break
        if child.poll() is not None:
            break
        time.sleep(0.01)
    killed = child.poll() is None
    os.kill(child.pid, signal.SIGKILL)
    child.wait()
    if not killed:
        pytest.skip("the march finished before a checkpoint could be killed")
    assert json.loads(meta.read_text())["status"] == "running"
    resumed = _ddvp("march", "--resume", "killed", "--no-progress", cwd=tmp_path)
    assert resumed.returncode == 0, resumed.stderr
    whole = _ddvp("march", *args, "--out", "whole", cwd=tmp_path)
    assert whole.returncode == 0, whole.stderr
    a, b = np.load(tmp_path / "killed" / "result.npz"), np.load(tmp_path / "whole" / "result.npz")
    assert all(np.array_equal(a[k], b[k]) for k in "tqp")


@pytest.mark.slow(why="repetition")
def test_resume_on_the_careful_path_and_to_a_later_end(tmp_path):
    first = _ddvp("march", "pendulum", "--careful", "--set", "t_end=6", "--max-steps", "50",
                  "--no-plot", "--out", "run", cwd=tmp_path)
    assert first.returncode == 1 and "max_steps" in first.stdout + first.stderr
    later = _ddvp("march", "--resume", "run", "--t-end", "12", "--no-plot", cwd=tmp_path)
    assert later.returncode == 0, later.stderr
    whole = _ddvp("march", "pendulum", "--careful", "--set", "t_end=12", "--no-plot",
                  "--out", "whole", cwd=tmp_path)
    assert whole.returncode == 0, whole.stderr
    a, b = np.load(tmp_path / "run" / "result.npz"), np.load(tmp_path / "whole" / "result.npz")
    assert a["t"].size > 51 and all(np.array_equal(a[k], b[k]) for k in "tqp")
    meta = json.loads((tmp_path / "run" / "meta.json").read_text())
    assert meta["resumed_from"]["nodes"] == 51


def test_resume_refuses_a_folder_without_a_march(tmp_path):
    bad = _ddvp("march", "--resume", str(tmp_path / "nothing"), cwd=tmp_path)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr
