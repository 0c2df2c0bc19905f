"""One compiled chunk size per scene and method, and the baselines' calls through numpy buffers."""

import numpy as np
import pytest

from ddvp_nlp import load_scene, march
from ddvp_nlp.solvers import baselines, lee_left, paper_schemes
from ddvp_nlp.solvers.compiler import build_count, find_compiler

COMPILER = find_compiler("auto")
needs_compiler = pytest.mark.skipif(COMPILER is None, reason="no C compiler")


@needs_compiler
@pytest.mark.parametrize("method", [paper_schemes.VDDVP, baselines.RK4, lee_left.LEE_LEFT])
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


@needs_compiler
def test_the_chunk_size_does_not_change_the_nodes(tmp_path):
    scene = load_scene("henon_heiles")
    config = scene.resolve({"t_end": 40.0})
    runs = [march(scene.system, config.q0, config.p0, tau0=config.tau0, t_end=config.t_end,
                  chunk=chunk, cache_dir=tmp_path) for chunk in (64, 1024)]
    assert runs[0].stats["fast_steps"] == runs[0].steps - 1 > 64  # many chunks against one
    for a, b in zip((runs[0].t, runs[0].q, runs[0].p), (runs[1].t, runs[1].q, runs[1].p),
                    strict=True):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("method", ["rk4", "stormer_verlet"])
def test_a_baseline_through_buffers_is_its_chunk_called_with_dm(tmp_path, method):
    scene = load_scene("henon_heiles")
    system = scene.system
    config = scene.resolve({"t_end": 30.0})
    theta = system.parameter_vector(None)
    solution = baselines.fixed_step_run(system, method, config.q0, config.p0, tau=0.05,
                                        t_end=config.t_end, t0=0.0, theta=theta,
                                        compiler=COMPILER, cache_dir=tmp_path)
    function, _ = baselines._fixed_chunk(system, method, baselines.CHUNK, COMPILER, tmp_path)
    assert isinstance(function, baselines.Buffered) and solution.steps == 600
    constants = np.tile(np.concatenate([theta, [0.0, 0.05]])[:, None], (1, baselines.CHUNK))
    state = np.concatenate([[0.0], config.q0, config.p0])
    _, rows = function.function(state, constants)  # the DM call the baselines made before
    rows = np.asarray(rows).T[:600]
    assert np.array_equal(rows[:-1, 0], solution.t[1:-1])  # the last node is put on t_end
    assert np.array_equal(rows[:, 1:5], np.hstack([solution.q, solution.p])[1:])
