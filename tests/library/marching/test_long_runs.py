"""Long runs (issue 38): ``Output(keep_every=k)`` and ``Output(keep="t_eval")`` keep a subset of
the nodes with memory proportional to it, the verdict still computed on every node as the march
goes (``solvers/marching/thinning.py``, ``solvers/accuracy/streaming.py``)."""

import json

import numpy as np
import pytest

from ddvp_nlp import Compilation, InputError, StepControl, load_scene
from ddvp_nlp.cli import main
from ddvp_nlp.solvers import Output
from ddvp_nlp.solvers.marching import MarchState, continue_march, march, thinning

WINDOW = 3000  # small windows: a short march crosses many of them


@pytest.fixture
def small_windows(monkeypatch):
    rows = []
    settle = thinning.Thinning.settle

    def watched(self, nodes):
        rows.append(nodes.t.size)  # rows the driver holds (allocated), kept or not
        settle(self, nodes)
    monkeypatch.setattr(thinning.Thinning, "settle", watched)
    return rows


# loaded once: a march's functions are built once per system (ddvp_nlp/cache.py)
PENDULUM = load_scene("pendulum")


def _pendulum(t_end=400.0, **output):
    scene = PENDULUM
    config = scene.resolve({})
    if "keep_every" in output or "keep" in output:
        output.setdefault("window", WINDOW)
    return march(scene.system, config.q0, config.p0, (config.t0, t_end), tau0=config.tau0,
                 params=config.params, output=Output(**output) if output else None)


def _kept(n, every):
    return np.append(np.arange(0, n - 1, every), n - 1)


def test_keep_every_keeps_exactly_the_full_runs_nodes_and_its_verdict(small_windows):
    times = np.linspace(0.0, 399.0, 9)
    full = _pendulum(t_eval=times)
    thin = _pendulum(keep_every=7, t_eval=times)
    idx = _kept(full.t.size, 7)
    assert full.status == thin.status and full.message == thin.message
    # the same steps: the kept nodes are the full run's, bit for bit
    assert np.array_equal(full.t[idx], thin.t)
    assert np.array_equal(full.q[idx], thin.q) and np.array_equal(full.p[idx], thin.p)
    kept = thin.march.kept
    assert kept["nodes_marched"] == full.t.size and kept["nodes_kept"] == idx.size
    assert kept["windows"] >= full.t.size // WINDOW
    # the residuals and local errors of the steps from the kept nodes, the largest of all
    assert np.array_equal(full.canonical_residual[idx[:-1]], thin.canonical_residual)
    assert np.array_equal(full.energy_residual[idx[1:-1] - 1], thin.energy_residual)
    assert np.array_equal(full.solvability[idx], thin.solvability)
    assert kept["canonical_residual_max"] == np.max(full.canonical_residual)
    assert np.array_equal(full.local_error[idx[:-1]], thin.local_error)
    # the verdict on every node: the same, its figures to round-off
    a, b = full.verdict.as_dict(), thin.verdict.as_dict()
    assert a["verdict"] == b["verdict"] == "drifted"
    assert a["t_drift"] == b["t_drift"] and a["drift_step"] == b["drift_step"]
    assert a["steps"] == b["steps"] and b["streamed"]
    for name in ("error_max", "local_error_max", "energy_drift", "energy_scale",
                 "level_error"):
        assert b[name] == pytest.approx(a[name], rel=1e-6), name
    np.testing.assert_allclose(b["scale"], a["scale"], rtol=1e-9)
    # t_eval from the same dense output
    assert np.array_equal(full.t_eval, thin.t_eval)
    np.testing.assert_allclose(thin.z_eval, full.z_eval, rtol=0, atol=1e-14)


def test_memory_is_proportional_to_what_is_kept(small_windows):
    thin = _pendulum(t_end=2000.0, keep_every=1000)
    marched = thin.march.kept["nodes_marched"]
    assert marched > 10 * WINDOW
    k = thin.t.size
    assert k == len(range(0, marched - 1, 1000)) + 1
    assert thin.q.shape == thin.p.shape == (k, 1)
    assert thin.canonical_residual.size == thin.local_error.size == k - 1
    assert thin.energy_residual.size == k - 2 and thin.solvability.size == k
    # the driver held at most a window and one batch of chunks (8 x 1024 steps) at a time
    assert max(small_windows) <= 2 * (WINDOW + 8 * 1024)


def test_keep_t_eval_keeps_the_states_and_events_only(small_windows):
    def up(t, q, p):
        return q[0]
    up.direction = 1
    times = np.linspace(0.0, 300.0, 5)
    full = _pendulum(t_end=300.0, t_eval=times, events=up)
    thin = _pendulum(t_end=300.0, t_eval=times, events=up, keep="t_eval")
    assert thin.t.size == 2 and thin.t[-1] == full.t[-1] and thin.t[0] == full.t[0]
    np.testing.assert_allclose(thin.z_eval, full.z_eval, rtol=0, atol=1e-14)
    assert np.array_equal(thin.t_events[0], full.t_events[0])
    assert thin.verdict.name == full.verdict.name


def test_the_careful_path_and_fallbacks_keep_the_same_nodes(small_windows, scene_of):
    """Kepler with chunk steps refused and redone on the careful path: the index of a node in
    the run (not its row) decides the careful step's clock and the chunk's state."""
    scene = scene_of("kepler")
    config = scene.resolve({"e": 0.5, "t_end": 30.0})
    common = dict(tau0=0.01, params=config.params, accuracy=None,
                  compilation=Compilation(chunk=64),
                  steps=StepControl(breakdown="least_squares", tau_max=0.95 * 0.0512))
    full = march(scene.system, config.q0, config.p0, (config.t0, config.t_end), **common)
    thin = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                 output=Output(keep_every=5, window=100), **common)
    assert full.stats["careful_steps"] > 10 and thin.march.kept["windows"] > 5
    idx = _kept(full.t.size, 5)
    assert np.array_equal(full.t[idx], thin.t) and np.array_equal(full.q[idx], thin.q)
    assert thin.stats["careful_steps"] == full.stats["careful_steps"]


def test_an_interrupted_thinned_march_keeps_what_it_had(small_windows):
    calls = []

    def stop():
        calls.append(1)
        return len(calls) > 12  # after 12 stepper calls (no clock: counts)
    thin = _pendulum(t_end=5000.0, keep_every=10, stop=stop)
    assert thin.status.code == "interrupted"
    marched = thin.march.kept["nodes_marched"]
    assert thin.march.kept["windows"] >= 2
    full = _pendulum(t_end=5000.0)
    idx = _kept(marched, 10)
    assert np.array_equal(full.t[idx], thin.t) and np.array_equal(full.q[idx], thin.q)
    assert thin.verdict.steps == marched - 1  # judged up to the last node


@pytest.mark.parametrize("options, words", [
    (dict(keep_every=0), "keep_every must be a positive integer, got 0"),
    (dict(keep_every=2.5), "keep_every must be a positive integer, got 2.5"),
    (dict(keep_every=10**23), "keep_every must be at most 4611686018427387904, got 10000"),
    (dict(keep="some"), "keep must be one of nodes, t_eval, got 'some'"),
    (dict(keep="t_eval"), "give t_eval or events"),
    (dict(keep_every=3, checkpoint=lambda t, z: None), "takes no checkpoints"),
])
def test_bad_values_are_refused_by_name(options, words):
    with pytest.raises(InputError, match=words.replace("(", r"\(")):
        Output(**options)


def test_continue_march_refuses_a_thinned_output():
    scene = PENDULUM
    config = scene.resolve({})
    run = march(scene.system, config.q0, config.p0, (config.t0, 1.0), tau0=config.tau0,
                params=config.params, accuracy=None)
    state = MarchState.of(run.t, run.q, run.p, 1.0, run.march.carried)
    with pytest.raises(InputError, match="continue_march keeps every node"):
        continue_march(scene.system, state, 2.0, tau0=config.tau0, params=config.params,
                       output=Output(keep_every=2))


@pytest.mark.parametrize("argv", [["--keep-every", "0"], ["--keep-every", "x"],
                                  ["--keep", "some"], ["--keep", "t_eval"],
                                  ["--keep-every", "3", "--method", "rk4"]])
def test_the_command_refuses_bad_values_with_exit_2(argv, tmp_path, capsys):
    try:
        code = main(["march", "pendulum", *argv, "--no-plot", "--out", str(tmp_path / "run")])
    except SystemExit as exc:  # argparse's own refusals (a choice, a type)
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err and "internal error" not in err
    assert "keep" in err
    assert not (tmp_path / "run" / "meta.json").exists()


def test_the_command_writes_what_it_keeps_and_refuses_to_resume_it(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["march", "pendulum", "--set", "t_end=300", "--keep-every", "100",
                 "--no-plot", "--out", str(out)]) == 0
    meta = json.loads((out / "meta.json").read_text())
    assert meta["kept_every"] == 100 and meta["nodes"] == meta["nodes_kept"]
    assert meta["steps"] == meta["nodes_marched"] - 1 > 100 * (meta["nodes"] - 2)
    assert meta["kept"]["keep"] == "nodes" and meta["accuracy"]["streamed"]
    data = np.load(out / "result.npz")
    assert data["t"].size == meta["nodes"]
    capsys.readouterr()
    assert main(["march", "--resume", str(out), "--no-plot"]) == 2
    assert "kept only some of its nodes" in capsys.readouterr().err


def test_a_stopped_long_march_is_returned_without_the_work_over_every_node(monkeypatch):
    """Ctrl-C on a march of millions of nodes: no recheck or whole-run check after it (they
    had taken 8 s of the 10.7 s from the signal to the exit); here 'millions' is 1000."""
    from ddvp_nlp.solvers.marching import session

    monkeypatch.setattr(session, "_too_many_to_judge", lambda nodes: nodes > 1000)
    calls = []

    def stop():
        calls.append(1)
        return len(calls) > 3  # after 3 stepper calls (counts, no clock)
    run = _pendulum(t_end=5000.0, stop=stop)
    assert run.status.code == "interrupted" and run.t.size > 1000
    assert run.verdict is None and "left out" in run.accuracy_skipped
    assert run.canonical_residual.size == 0 and run.energy_residual.size == 0
    short = _pendulum(t_end=5000.0, stop=lambda: len(calls) > 0)  # stopped at once
    # no step: nothing to judge, and no verdict claimed for work not done
    assert short.t.size == 1 and short.verdict is None and "no step" in short.accuracy_skipped
