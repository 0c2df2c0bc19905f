"""The accuracy check's compiled passes (solvers/exact/kernel.py) give numpy's numbers to the bit:
the dense output of a run read at any times, forward and backward, with tangent columns, at
times outside the run and at non-finite times; and the kernel is only built when asked to
(the caller's work paid for it), never without a compiler. Bit equality is the module's
documented contract (the same IEEE operations in the same order, no FMA contraction)."""

import dataclasses

import numpy as np
import pytest

from ddvp_nlp import load_scene
from ddvp_nlp.solvers.exact import kernel as check
from ddvp_nlp.solvers.exact.flow import exact_flow


@pytest.fixture(scope="module")
def compiled():
    found = check.kernel("auto", build=True)
    if found is None:
        pytest.skip("no C compiler here: numpy reads the dense output")
    return found


def _runs(name, tangent=0):
    scene = load_scene(name)
    config = scene.resolve({})
    theta = scene.system.parameter_vector(config.params)
    z0 = np.concatenate([config.q0, config.p0])
    flow = exact_flow(scene.system, tangent=tangent, compiler=None)
    t_end = config.t0 + min(config.t_end - config.t0, 30.0)
    forward = flow.run(z0, config.t0, t_end, theta, rtol=1e-9)
    backward = flow.run(forward.z_end, t_end, config.t0, theta, rtol=1e-9)
    return forward, backward


@pytest.mark.parametrize("name, tangent", [("henon_heiles", 0), ("kepler", 0), ("pendulum", 2)])
def test_dense_output_is_numpys_to_the_bit(compiled, name, tangent):
    rng = np.random.default_rng(7)
    for run in _runs(name, tangent):
        assert run.steps > 10
        low, high = sorted((run.t0, run.t_end))
        nodes = np.append(run.t_old, run.t_end)
        inside = np.sort(rng.uniform(low, high, 2000))
        outside = rng.uniform(low - 5.0, high + 5.0, 300)
        odd = np.array([np.nan, np.inf, -np.inf, low, high, 0.0, -0.0])
        numpy_run = dataclasses.replace(run, kernel=None)
        compiled_run = dataclasses.replace(run, kernel=compiled)
        for times in (nodes, inside, inside[::-1], outside, odd,
                      np.concatenate([inside, odd, outside])):
            for read in ("__call__", "z") + (("Y",) if tangent else ()):
                expected = getattr(numpy_run, read)(times)
                got = getattr(compiled_run, read)(times)
                assert got.shape == expected.shape
                assert np.array_equal(got, expected, equal_nan=True), (name, read)


def test_kernel_is_built_only_when_paid_for(tmp_path):
    assert check.kernel(None, tmp_path, build=True) is None  # no compiler: numpy
    assert check.kernel("auto", tmp_path) is None  # not in this cache, not paid for: not built
    assert not list(tmp_path.glob("check_*.so"))


def test_the_claim_at_given_times_is_numpys(compiled):
    """The claim read at the nodes from the envelope at the samples (``Reference.at``):
    numpy's ``searchsorted(side="left")``, clipped, in either direction, times in any order,
    before, between, on and after the samples, NaN among them."""
    rng = np.random.default_rng(3)
    samples = np.sort(rng.uniform(0.0, 10.0, 300))
    running = np.maximum.accumulate(rng.uniform(0.0, 1.0, samples.size))
    running[200:210] = np.nan
    sorted_times = np.sort(np.concatenate([rng.uniform(-1.0, 11.0, 2000), samples[::7]]))
    for times in (sorted_times, sorted_times[::-1], rng.permutation(sorted_times),
                  np.array([np.nan, 5.0, np.nan, -3.0, 20.0, 5.0])):
        for forward in (True, False):
            keys = samples if forward else -samples[::-1]
            envelope = running if forward else running[::-1].copy()
            index = np.searchsorted(keys, times if forward else -times, side="left")
            np.clip(index, 0, keys.size - 1, out=index)
            expected = 2.0 * np.maximum(np.take(envelope, index), 0.3)
            got = compiled.claim_at(times, forward, samples if forward else samples[::-1]
                                    .copy(), envelope, 2.0, 0.3)
            assert np.array_equal(got, expected, equal_nan=True)


def test_a_run_read_through_the_kernel_pickles(compiled):
    """A run carrying the compiled kernel pickles without it (a library of this process) and
    reads the same numbers after."""
    import pickle

    run = dataclasses.replace(_runs("kepler")[0], kernel=compiled)
    again = pickle.loads(pickle.dumps(run))
    assert again.kernel is None
    times = np.linspace(run.t0, run.t_end, 101)
    assert np.array_equal(again.z(times), run.z(times))
