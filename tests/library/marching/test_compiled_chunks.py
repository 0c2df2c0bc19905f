"""The fast march path accepts by the careful path's test: the same steps and statuses, nodes
that differ only by round-off grown over the run."""

import numpy as np
import pytest
from helpers.common import run_scene

from ddvp_nlp import Compilation, HamiltonianSystem, Status, StepControl, load_scene, march
from ddvp_nlp.solvers.compiler import find_compiler


@pytest.fixture(scope="module")
def cache():
    """The default compiled-code cache (``Compilation``'s ``cache_dir=None``): these tests are
    about what a compiled chunk does, which a library loaded from the cache does as one just
    built (its name is the hash of the generated code, compiler and flags); building and
    loading it is test_compiled_chunks_are_cached's, in a folder of its own. A folder made
    per run cost a C compile per scene (3-4 s of CPU each)."""
    return None


@pytest.mark.slow(why="repetition")
@pytest.mark.parametrize("name, rule, overrides", [
    ("paper_pendulum", "vddvp", {"t_end": 2000.0}),
    # tau0 as the scenes' defaults were when these were measured
    ("kepler", "lee", {"e": 0.6, "t_end": 30.0, "tau0": 0.01}),
    ("fpu", "vddvp", {"t_end": 10.0, "tau0": 0.01}),
    ("henon_heiles", "fixed", {"t_end": 50.0}),
])
@pytest.mark.parametrize("compiler", ["auto", None])
def test_fast_and_careful_paths_give_the_same_trajectory(name, rule, overrides, compiler, cache):
    _, _, careful = run_scene(name, overrides, scheme=rule, compilation=Compilation(fast=False))
    _, _, fast = run_scene(
        name,
        overrides,
        scheme=rule,
        compilation=Compilation(compiler=compiler, cache_dir=cache, chunk=64),
    )
    assert careful.success and fast.success
    assert fast.stats["path"] == ("vm" if compiler is None or find_compiler() is None
                                  else "compiled")
    assert fast.stats["fast_steps"] >= fast.steps - 1
    assert fast.steps == careful.steps
    # Both paths solve every step to round-off but stop Newton at different iterates (and the
    # chunk eliminates where the careful path factors by QR). Bound the difference by how much
    # the careful path itself moves when its initial position or momentum is perturbed by 1e-15
    # (Kepler near pericentre amplifies round-off most), and by 1e-9 in any case.
    scene = load_scene(name)
    config = scene.resolve(overrides)
    nudged = [
        march(
            scene.system,
            config.q0 + dq,
            config.p0 + dp,
            (0.0, config.t_end),
            tau0=config.tau0,
            params=config.params,
            scheme=rule,
            compilation=Compilation(fast=False),
        )
        for dq, dp in ((1e-15, 0.0), (0.0, 1e-15))
    ]
    for field in ("t", "q", "p"):
        sensitivity = 0.0
        for other in nudged:
            n = min(other.t.size, careful.t.size)
            sensitivity = max(sensitivity, np.max(np.abs(getattr(other, field)[:n]
                                                          - getattr(careful, field)[:n])))
        difference = np.max(np.abs(getattr(fast, field) - getattr(careful, field)))
        assert difference <= max(1e-9, 10 * sensitivity), (field, difference, sensitivity)


@pytest.mark.slow_when(lambda compiler, **_: compiler == "auto", why="repetition")
@pytest.mark.parametrize("compiler", ["auto", None])
def test_a_failing_step_inside_a_chunk_is_handled_as_on_the_careful_path(compiler, cache):
    """The rotating pendulum has no positive step after 15 steps: the fast chunk (64 steps) fails
    inside; the careful path takes over from the last good node and ends the same way."""
    system = load_scene("pendulum").system
    careful = march(system, [0.0], [np.sqrt(5.0)], (0.0, 100.0), tau0=0.05,
                    compilation=Compilation(fast=False))
    fast = march(system, [0.0], [np.sqrt(5.0)], (0.0, 100.0), tau0=0.05,
                 compilation=Compilation(compiler=compiler, cache_dir=cache, chunk=64))
    assert careful.status in (Status.NEWTON_FAILED, Status.NO_ADMISSIBLE_STEP)
    assert fast.status is careful.status and fast.message == careful.message
    assert fast.steps == careful.steps
    np.testing.assert_allclose(fast.t, careful.t, rtol=0, atol=1e-12)
    assert fast.stats["fast_steps"] >= 1 and fast.stats["careful_steps"] >= 2


def test_step_bounds_inside_a_chunk(cache):
    _, _, careful = run_scene(
        "paper_pendulum",
        {"t_end": 500.0},
        steps=StepControl(max_step_ratio=1.02),
        compilation=Compilation(fast=False),
    )
    _, _, fast = run_scene(
        "paper_pendulum",
        {"t_end": 500.0},
        steps=StepControl(max_step_ratio=1.02),
        compilation=Compilation(cache_dir=cache, chunk=64),
    )
    assert careful.status is Status.STEP_RATIO and fast.status is Status.STEP_RATIO
    assert fast.steps == careful.steps and fast.message == careful.message


def test_max_steps_inside_a_chunk(cache):
    _, _, fast = run_scene(
        "pendulum",
        {"t_end": 1e9},
        steps=StepControl(max_steps=1000),
        compilation=Compilation(cache_dir=cache, chunk=64),
    )
    assert fast.status is Status.MAX_STEPS and fast.steps == 1000


def test_compiled_chunks_are_cached(tmp_path):
    system = load_scene("harmonic").system
    if find_compiler() is None:
        pytest.skip("no C compiler on this machine")
    march(system, [1.0], [0.0], (0.0, 5.0), tau0=0.1, compilation=Compilation(cache_dir=tmp_path))
    libraries = list(tmp_path.glob("chunk_*.so"))
    assert len(libraries) == 1
    built = libraries[0].stat().st_mtime_ns
    # a fresh system (new in-memory functions) loads the compiled file instead of rebuilding it;
    # made here, as load_scene's copies of a scene share one system (and what was built for it)
    scene = load_scene("harmonic")
    again = HamiltonianSystem(scene.hamiltonian, scene.n, dict(scene.params), name=scene.name)
    assert again is not system
    solution = march(
        again, [1.0], [0.0], (0.0, 5.0), tau0=0.1, compilation=Compilation(cache_dir=tmp_path)
    )
    assert solution.success and solution.stats["path"] == "compiled"
    assert list(tmp_path.glob("chunk_*.so")) == libraries
    assert libraries[0].stat().st_mtime_ns == built


def test_without_a_compiler_the_virtual_machine_is_used(monkeypatch, tmp_path):
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setenv("PATH", str(tmp_path))  # no gcc, no cc
    assert find_compiler("auto") is None
    _, _, fast = run_scene("harmonic", {"t_end": 5.0}, compilation=Compilation(cache_dir=tmp_path))
    _, _, careful = run_scene("harmonic", {"t_end": 5.0}, compilation=Compilation(fast=False))
    assert fast.stats["path"] == "vm" and not list(tmp_path.glob("*.so"))
    np.testing.assert_allclose(fast.q, careful.q, rtol=0, atol=1e-12)


@pytest.mark.slow(why="processes")
def test_two_processes_building_one_cache_entry_at_once(tmp_path):
    import subprocess
    import sys
    if find_compiler() is None:
        pytest.skip("no C compiler on this machine")
    script = ("from ddvp_nlp import Compilation, load_scene, march; import sys; "
              "s = march(load_scene('pendulum').system, [0.5], [0.5], (0.0, 20.0), tau0=0.05, "
              f"compilation=Compilation(cache_dir={str(tmp_path)!r})); "
              "print(s.status.code, s.stats['path'], s.steps)")
    runs = [subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
            for _ in range(2)]
    outputs = [run.communicate(timeout=300)[0].split() for run in runs]
    assert all(run.returncode == 0 for run in runs)
    assert outputs[0] == outputs[1] and outputs[0][:2] == ["success", "compiled"]
    assert len(list(tmp_path.glob("chunk_*.so"))) == 1
    assert not [p for p in tmp_path.iterdir() if p.is_dir()]  # no scratch folder left behind
