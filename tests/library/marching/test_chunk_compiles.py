"""One compiled chunk size per scene and method, and the baselines' calls through numpy buffers."""

import numpy as np
import pytest

from ddvp_nlp import Compilation, StepControl, Tolerance, load_scene, march
from ddvp_nlp.solvers.baselines import (
    chunks,
    fixed_step,
    paper_schemes,
)
from ddvp_nlp.solvers.baselines import (
    lee_left_stepper as lee_left,
)
from ddvp_nlp.solvers.compiler import build_count, find_compiler

COMPILER = find_compiler("auto")
needs_compiler = pytest.mark.skipif(COMPILER is None, reason="no C compiler")


@pytest.mark.slow_when(lambda method, **_: method.name == "vddvp", why="repetition")
@needs_compiler
@pytest.mark.parametrize("method", [paper_schemes.VDDVP, fixed_step.RK4, lee_left.LEE_LEFT])
def test_a_short_and_a_long_run_of_a_scene_compile_once(tmp_path, method):
    scene = load_scene("pendulum")
    short, long = scene.resolve({"t_end": 0.5}), scene.resolve({"t_end": 60.0})
    before = build_count()
    first = method.run(scene.system, short, short.tau0, compiler=COMPILER, cache_dir=tmp_path,
                       max_steps=10**6)
    compiled = build_count() - before
    second = method.run(scene.system, long, long.tau0, compiler=COMPILER, cache_dir=tmp_path,
                        max_steps=10**6)
    assert compiled >= 1 and build_count() - before == compiled  # the long run: no compile
    assert first.steps < 30 < 1024 < second.steps or method is lee_left.LEE_LEFT
    assert second.stats["path"] == "compiled"


@pytest.mark.slow(why="repetition")
@needs_compiler
def test_the_chunk_size_does_not_change_the_nodes(tmp_path):
    scene = load_scene("henon_heiles")
    config = scene.resolve({"t_end": 40.0})
    runs = [
        march(
            scene.system,
            config.q0,
            config.p0,
            (0.0, config.t_end),
            tau0=config.tau0,
            compilation=Compilation(cache_dir=tmp_path, chunk=chunk),
        )
        for chunk in (64, 1024)
    ]
    assert runs[0].stats["fast_steps"] == runs[0].steps - 1 > 64  # many chunks against one
    for a, b in zip((runs[0].t, runs[0].q, runs[0].p), (runs[1].t, runs[1].q, runs[1].p),
                    strict=True):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("method", ["rk4", "stormer_verlet"])
def test_a_baseline_through_buffers_is_its_chunk_called_with_dm(method):
    scene = load_scene("henon_heiles")
    system = scene.system
    config = scene.resolve({"t_end": 30.0})
    theta = system.parameter_vector(None)
    solution = fixed_step.fixed_step_run(system, method, config.q0, config.p0, tau=0.05,
                                        t_end=config.t_end, t0=0.0, theta=theta,
                                        compiler=COMPILER, cache_dir=None)
    # the default cache (cache_dir=None): the compiled chunk is the property, not its build
    # (test_a_short_and_a_long_run_of_a_scene_compile_once builds in a folder of its own)
    function, _ = fixed_step.fixed_chunk(system, method, chunks.CHUNK, COMPILER, None)
    assert isinstance(function, chunks.Buffered) and solution.steps == 600
    constants = np.tile(np.concatenate([theta, [0.0, 0.05]])[:, None], (1, chunks.CHUNK))
    state = np.concatenate([[0.0], config.q0, config.p0])
    _, rows = function.function(state, constants)  # the DM call the baselines made before
    rows = np.asarray(rows).T[:600]
    assert np.array_equal(rows[:-1, 0], solution.t[1:-1])  # the last node is put on t_end
    assert np.array_equal(rows[:, 1:5], np.hstack([solution.q, solution.p])[1:])


def _same(a, b) -> bool:
    return (np.array_equal(a.t, b.t) and np.array_equal(a.q, b.q) and np.array_equal(a.p, b.p)
            and a.status is b.status and a.message == b.message
            and a.written_stats() == b.written_stats()
            and np.array_equal(a.local_error, b.local_error)
            and np.array_equal(a.solvability, b.solvability))


@pytest.mark.slow_when(lambda case, **_: case != "fixed", why="repetition")
@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("case", ["careful windows", "accuracy stop", "max_steps", "fixed"])
def test_batches_of_chunks_give_what_one_call_per_chunk_gives(case):
    """The compiled stepper checks up to ``batch`` chained chunks at once and hands them out
    one by one; nodes, status, message and every statistic are those of one call per chunk,
    also where chunk steps fail and the careful path takes windows in between."""
    from ddvp_nlp.solvers.marching import stepper

    pendulum, henon = load_scene("pendulum").system, load_scene("henon_heiles").system
    runs = {"careful windows": (pendulum, [0.0], [np.sqrt(5.0)], 10.0,
                                dict(steps=StepControl(breakdown="least_squares"))),
            "accuracy stop": (henon, [0.0, 0.1], [0.3, 0.0], 400.0,
                              dict(accuracy=Tolerance(global_tol=1e-3))),
            "max_steps": (henon, [0.0, 0.1], [0.3, 0.0], 1e6,
                          dict(steps=StepControl(max_steps=1500))),
            "fixed": (henon, [0.0, 0.1], [0.3, 0.0], 45.0, dict(scheme="fixed"))}
    system, q0, p0, t_end, options = runs[case]
    found = []
    for calls in (1, stepper.MAX_CALLS):
        found.append(march(system, q0, p0, (0.0, t_end), tau0=0.05, **options,
                           compilation=Compilation(chunk=64, batch=calls)))  # default cache
    one, batched = found
    assert one.stats["fast_steps"] > 3 * 64  # several chunks, so batches of several
    if case == "careful windows":
        assert one.stats["careful_steps"] > 64 and one.success
    assert _same(one, batched)
    # only the fast steps the run kept count (the accuracy check cuts a chunk at step 295)
    assert batched.stats["fast_steps"] <= batched.steps
