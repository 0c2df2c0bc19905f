"""The march's bookkeeping shortcuts give exactly what the straightforward computations give.

Each shortcut (a pre-test that clears a block with a few reductions, a row maximum taken column
by column, arrays that grow instead of lists of blocks, chunk calls that keep the parameters in
the buffer) is compared bit for bit with the plain numpy it replaces, on blocks built to sit on and
around every threshold, with zeros, signs, NaN and infinities."""

import math
import warnings

import numpy as np
import pytest

from ddvp_nlp import Compilation, StepControl, load_scene, march
from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.solvers.columns import column_extremes, row_max, row_max_abs, row_max_ratio, row_norm
from ddvp_nlp.solvers.driver import Nodes
from ddvp_nlp.solvers.marching import monitors
from ddvp_nlp.solvers.marching.acceptance import Acceptance
from ddvp_nlp.solvers.marching.chunk import FastChunk
from ddvp_nlp.solvers.marching.monitors import MONITOR_LIMIT, SolvabilityMonitor
from ddvp_nlp.solvers.marching.steps import step_functions


def same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("width", [1, 2, 3, 4, 7, 16, 17, 40])
def test_row_max_abs_is_numpys_reduction(width):
    rng = np.random.default_rng(width)
    values = rng.standard_normal((3000, width)) * 10.0 ** rng.integers(-300, 300, (3000, width))
    values[5] = 0.0
    values[6] = -0.0
    values[7, 0] = -np.inf
    assert same(row_max_abs(values), np.max(np.abs(values), axis=1))
    values[8, -1] = np.nan
    assert np.array_equal(row_max_abs(values), np.max(np.abs(values), axis=1), equal_nan=True)


@pytest.mark.parametrize("width", [1, 2, 3, 4, 7, 16, 17, 40])
def test_column_reductions_are_numpys(width):
    """The column-by-column reductions give numpy's numbers, NaN and inf included."""
    rng = np.random.default_rng(width)
    values = rng.standard_normal((500, width)) * 10.0 ** rng.integers(-100, 100, (500, width))
    scale = rng.uniform(0.1, 10.0, width)
    assert same(row_max(values), np.max(values, axis=1))
    assert same(row_max_ratio(values, scale), np.max(values / scale, axis=1))
    assert np.allclose(row_norm(values / 1e100), np.sqrt(np.sum((values / 1e100) ** 2, axis=1)),
                       rtol=1e-15, atol=0)
    low, high, largest = column_extremes(values)
    assert same(low, values.min(axis=0)) and same(high, values.max(axis=0))
    assert same(largest, np.abs(values).max(axis=0))
    values[3, -1], values[4, 0] = np.nan, np.inf
    assert np.array_equal(row_max(values), np.max(values, axis=1), equal_nan=True)
    assert np.array_equal(row_max_abs(values), np.max(np.abs(values), axis=1), equal_nan=True)
    assert np.isnan(column_extremes(values)[0][-1])


def _weight_blocks(rng):
    """Blocks of w: quiet ones, and ones with every kind of alarm (or near miss) somewhere."""
    edge = math.exp(MONITOR_LIMIT)
    blocks = []
    for kind in range(14):
        w = -0.05 * np.cumprod(1 + 0.01 * rng.standard_normal(300))
        i = int(rng.integers(1, 299))
        if kind == 1:
            w[i] = -w[i]  # sign change
        elif kind == 2:
            w[i] = 0.0
        elif kind == 3:
            w[i:] *= edge * 1.001  # a jump just past the limit
        elif kind == 4:
            w[i:] *= np.nextafter(edge, 0)  # just inside: no alarm, but past the pre-test
        elif kind == 5:
            w[i:] /= edge * (1 - 1e-12)
        elif kind == 6:
            w[i] = np.nan
        elif kind == 7:
            w[i] = -np.inf
        elif kind == 8:
            w *= 1e-300  # ratios of tiny numbers
        elif kind == 9:
            w[:i] *= 1e300
        elif kind == 10:
            w = w[:1]  # one careful node
        elif kind == 11:
            w = -w
        elif kind == 12:
            w[0] = w[0] * edge * 1.5  # the alarm at the block's first node
        blocks.append(w)
    return blocks


def test_solvability_pretest_changes_no_warning(monkeypatch):
    """The monitor with its block pre-test (``monitors._quiet``) against the same monitor with
    the pre-test switched off (every block through the full test, the code before it)."""
    rng = np.random.default_rng(1)
    cleared = []
    quiet = monitors._quiet

    def counting(w, last):
        result = quiet(w, last)
        cleared.append(result)
        return result

    def watch(monitor, pretest, pieces):
        monkeypatch.setattr(monitors, "_quiet", counting if pretest else lambda w, last: False)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for w, t in pieces:
                monitor._observe(w, t)
        return len(caught)

    blocks = _weight_blocks(rng)
    for order in range(30):  # the blocks in many orders: each alarm after various histories
        chosen = [blocks[i] for i in rng.permutation(len(blocks))[:4]]
        starts = np.cumsum([0] + [w.size for w in chosen])
        pieces = [(w, start + np.arange(w.size) * 0.1)
                  for w, start in zip(chosen, starts, strict=False)]
        fast, plain = SolvabilityMonitor(0.0, -0.05), SolvabilityMonitor(0.0, -0.05)
        warned = watch(fast, True, pieces)
        assert warned == watch(plain, False, pieces) == (fast.warning is not None)
        assert same(np.concatenate(fast._weights), np.concatenate(plain._weights))
        assert repr(fast.warning) == repr(plain.warning), order  # NaN c included
    assert True in cleared and False in cleared  # both the shortcut and the full test ran


def test_nodes_keep_their_rows_when_they_grow():
    nodes = Nodes(0.0, [1.0, 2.0])
    t, z = [np.zeros(1)], [np.array([[1.0, 2.0]])]
    rng = np.random.default_rng(3)
    for size in (1000, 1, 5000, 30):
        t.append(rng.random(size))
        z.append(rng.random((size, 2)))
        nodes.extend(t[-1], z[-1])
    kept_t, kept_z = nodes.arrays()
    assert same(kept_t, np.concatenate(t)) and same(kept_z, np.concatenate(z))


def test_chunk_batches_are_the_chained_single_calls():
    """Several chunk calls written into one batch's arrays give the chunks of one call each."""
    scene = load_scene("pendulum")
    config = scene.resolve({})
    system, scheme = scene.system, Scheme.coerce("vddvp")
    start = march(
        system,
        config.q0,
        config.p0,
        (0.0, 1.0),
        tau0=0.05,
        steps=StepControl(max_steps=1),
        compilation=Compilation(fast=False),
    )
    theta = system.parameter_vector(config.params)
    chunk = FastChunk(system, scheme, step_functions(system, scheme), chunk=16, compiler=None,
                      cache_dir=None)
    z = np.column_stack([start.q, start.p])
    state = chunk.energy_state(start.t[0], start.t[1], z[0], z[1], 0.0)
    parameters = chunk.energy_parameters(theta, Acceptance(1e-10, None, None, 10.0))
    batch = chunk.steps(state, parameters, calls=3)
    pieces = []
    for _ in range(3):
        one = chunk.steps(state, parameters)
        pieces.append(one)
        state = chunk.energy_state(one.t_next[-2], one.t_next[-1], one.z_next[-2],
                                   one.z_next[-1], one.drift[-1])
    assert batch.good.all()
    for name in ("t_next", "z_next", "good", "H_node", "w_node", "drift"):
        assert same(getattr(batch, name), np.concatenate([getattr(p, name) for p in pieces])), \
            name


def test_quiet_blocks_skip_the_full_test():
    """The pre-test clears an ordinary block (else it would not save anything)."""
    w = -0.05 * (1 + 0.01 * np.sin(np.arange(1024) * 0.1))
    assert monitors._quiet(w, -0.05)
    w[500] = -w[500]
    assert not monitors._quiet(w, -0.05)
    assert not monitors._quiet(w[:10], 0.0)
