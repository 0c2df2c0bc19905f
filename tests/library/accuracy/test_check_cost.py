"""What the accuracy check of a march costs, counted, never timed: the nodes its RK4 look
evaluates, the attempts of its reference flow, the compiles its rent buys; and that what it
skips changes no figure of its report."""

from __future__ import annotations

import os

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from ddvp_nlp import load_scene, march
from ddvp_nlp.solvers import compiler as compiled_code
from ddvp_nlp.solvers.accuracy import judgement, node_values
from ddvp_nlp.solvers.columns import column_argmax, column_span
from ddvp_nlp.solvers.exact import reference
from ddvp_nlp.solvers.exact.flow import AdaptiveFlow


def _pendulum(t_end=3000.0):
    scene = load_scene("paper_pendulum")
    config = scene.resolve({"t_end": t_end})
    return lambda: march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                         tau0=config.tau0, params=config.params)


def _counting(monkeypatch, cls, name, count):
    original = getattr(cls, name)

    def counted(self, *args, **kwargs):
        result = original(self, *args, **kwargs)
        count(args, result)
        return result
    monkeypatch.setattr(cls, name, counted)


def test_the_first_steps_are_looked_at_once_and_the_report_is_the_same(monkeypatch):
    """The early verdict looks at the first 4096 steps while the march runs; the check of the
    finished march reads those rows back (the same bits in, so the same bits out: the report
    is compared exactly) and evaluates each other node once."""
    run = _pendulum()
    run()  # compiled or loaded once
    looked = []
    _counting(monkeypatch, node_values.NodeValues, "_look",
              lambda args, _: looked.append(args[0].size))
    solution = run()
    nodes = solution.t.size
    assert nodes > node_values.KEPT_STEPS + 1000
    # the early verdict's windows share their end nodes; the final check starts again at the
    # last kept node, and the last node is evaluated alone (at most a row each)
    assert nodes <= sum(looked) <= nodes + 8
    looked.clear()
    monkeypatch.setattr(node_values.Kept, "prefix", lambda *args: None)
    again = run()
    assert sum(looked) >= nodes + node_values.KEPT_STEPS  # read back before, not now
    assert again.verdict.as_dict() == solution.verdict.as_dict()


def test_a_run_that_drifts_early_is_not_integrated_a_call_past_it(monkeypatch):
    """The paper's pendulum drifts at its fourth node (t = 2): the reference's first piece
    ends at the 64th node, so the reference flow makes fewer attempts than one compiled call
    holds (it made a whole call of 1024 fine attempts and the coarse run to their end, t =
    218); the verdict and its figures are those of a reference grown without the first piece,
    to the reference's own claimed error."""
    run = _pendulum()
    run()
    attempts = []
    _counting(monkeypatch, AdaptiveFlow, "run", lambda _, trajectory:
              attempts.append(trajectory.attempts))
    first = run().verdict
    assert first.name == "drifted"
    assert 0 < sum(attempts) < 1024
    grown = judgement.GrowingReference  # grown a compiled call at a time from the start
    monkeypatch.setattr(judgement, "GrowingReference",
                        lambda *args, first=None, **options: grown(*args, **options))
    attempts.clear()
    whole = run().verdict
    assert sum(attempts) > 1024
    assert (whole.name, whole.t_drift, whole.drift_step) == \
        (first.name, first.t_drift, first.drift_step)
    claimed = max(first.reference_error, whole.reference_error)
    assert abs(whole.error_max - first.error_max) <= claimed


def test_the_first_piece_on_a_short_chunk_gives_the_same_report(monkeypatch):
    """From the second check of a system in a process, the reference's first piece runs on the
    flow of `FIRST_SLOTS` attempts a call (its skipped slots are what a 1024-slot call costs
    there): the same attempts, so the same report, bit for bit, as on the full flow."""
    run = _pendulum(t_end=200.0)
    run()  # the first check of the system in this process
    slots = []
    original = AdaptiveFlow.run

    def counted(self, *args, **kwargs):
        slots.append(self.slots)
        return original(self, *args, **kwargs)
    monkeypatch.setattr(AdaptiveFlow, "run", counted)
    short = run().verdict
    assert slots[:2] == [reference.FIRST_SLOTS] * 2  # the first piece's fine and coarse runs
    slots.clear()
    monkeypatch.setattr(judgement, "first_flow", lambda *args: None)
    full = run().verdict
    assert reference.FIRST_SLOTS not in slots
    assert short.as_dict() == full.as_dict()


def _rented_function():
    x = ca.SX.sym("x", 2)
    a = ca.SX.sym("a")
    return ca.Function("rent_ledger_case", [x, a], [ca.cos(a * x) * x[0] + a])


@pytest.fixture
def cache(tmp_path):
    if compiled_code.find_compiler("auto") is None:
        pytest.skip("no C compiler")
    return tmp_path / "cache"


def test_rent_is_summed_over_processes_and_buys_the_compile_once(cache):
    """A buffer not in the cache pays rent on the virtual machine; what one process paid is
    in the cache's ledger for the next (each `RentedBuffer` here stands for a process), and
    once the sum reaches ``compile_after`` the next buffer compiles at once: one build."""
    function = _rented_function()
    first = compiled_code.RentedBuffer(function, "auto", cache, compile_after=1e9)
    assert not first.compiled and first.ledger.spent == 0.0
    first.ledger.add(0.004)  # below LEDGER_EVERY_S: kept in memory
    first.ledger.save()  # what a process's exit or its buffer's collection does
    second = compiled_code.RentedBuffer(function, "auto", cache, compile_after=1e9)
    assert second.ledger.saved == pytest.approx(0.004)
    second.ledger.add(compiled_code.LEDGER_EVERY_S)  # written at once
    assert compiled_code.RentedBuffer(function, "auto", cache, compile_after=1e9).ledger.saved \
        == pytest.approx(0.004 + compiled_code.LEDGER_EVERY_S)
    builds = compiled_code.build_count()
    paid = compiled_code.RentedBuffer(function, "auto", cache, compile_after=0.01)
    assert paid.compiled and compiled_code.build_count() == builds + 1
    assert paid.ledger is not None and not os.path.exists(cache / paid.ledger.name)
    assert paid(np.array([0.5, -1.0]), 0.3)[0].shape == (1, 2)
    # now in the cache: loaded, no ledger, no build
    assert compiled_code.RentedBuffer(function, "auto", cache).ledger is None
    assert compiled_code.build_count() == builds + 1


@pytest.mark.parametrize("planted", [b"nan\n", b"not a number", b"-5", b"1e400"])
def test_a_ledger_that_holds_no_finite_rent_counts_none(cache, planted):
    function = _rented_function()
    ledger = compiled_code.RentedBuffer(function, "auto", cache, compile_after=1e9).ledger
    path = cache / ledger.name
    path.write_bytes(planted)
    os.chmod(path, 0o600)
    again = compiled_code.RentedBuffer(function, "auto", cache, compile_after=1e-9)
    assert again.ledger.saved == 0.0 and not again.compiled  # rent only from its own calls


def test_a_ledger_behind_a_link_is_not_read(cache, tmp_path):
    function = _rented_function()
    ledger = compiled_code.RentedBuffer(function, "auto", cache, compile_after=1e9).ledger
    elsewhere = tmp_path / "elsewhere"
    elsewhere.write_text("100.0\n")
    os.symlink(elsewhere, cache / ledger.name)
    assert compiled_code.RentedBuffer(function, "auto", cache,
                                      compile_after=1e9).ledger.saved == 0.0


@settings(max_examples=40, deadline=None)
@given(arrays(np.float64, st.tuples(st.integers(1, 30), st.integers(1, 20)),
              elements=st.floats(allow_nan=True, allow_infinity=True, width=64)))
def test_the_column_reductions_are_numpys(values):
    with np.errstate(invalid="ignore"):  # inf - inf: NaN in both
        np.testing.assert_array_equal(column_span(values), np.ptp(values, axis=0))
    np.testing.assert_array_equal(column_argmax(values), np.argmax(values, axis=0))


def test_the_check_of_a_march_imports_nothing_the_march_does_not():
    """In a fresh process, a checked march leaves the modules an unchecked one leaves but its
    own: np.unique's first call imported numpy.ma (30-70 ms of a short march's process)."""
    import subprocess
    import sys

    code = ("import sys\n"
            "from ddvp_nlp import load_scene, march\n"
            "scene = load_scene('harmonic')\n"
            "config = scene.resolve({'t_end': 5.0})\n"
            "before = set(sys.modules)\n"
            "solution = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),\n"
            "                 tau0=config.tau0, params=config.params)\n"
            "assert solution.verdict is not None\n"
            "print(sorted(m for m in set(sys.modules) - before\n"
            "             if not m.startswith('ddvp_nlp')))\n")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                         text=True).stdout
    assert "numpy.ma" not in out and "scipy" not in out, out


@pytest.fixture(scope="module")
def check_kernel():
    from ddvp_nlp.solvers.exact import kernel

    found = kernel.kernel("auto", build=True)
    if found is None:
        pytest.skip("no C compiler: the check runs numpy")
    return found


def _scan_state(scan):
    return (scan.low, scan.high, scan.largest, scan.column_max, scan.column_node, scan.column_t,
            scan.claim_max, scan.drift, scan.lost, scan.until, scan.times)


@settings(max_examples=60, deadline=None)
@given(rows=st.integers(1, 60), d=st.sampled_from([2, 4, 6, 18, 34]),
       seed=st.integers(0, 2**32 - 1),
       drift_at=st.integers(0, 80), lost_at=st.integers(0, 80), claim_at=st.integers(0, 80),
       growth=st.floats(0.0, 3.0))
def test_the_compiled_scan_is_numpys(check_kernel, rows, d, seed, drift_at, lost_at, claim_at,
                                     growth):
    """`Scan.measure` through the compiled pass (``exact/kernel.py``) leaves every figure as
    the numpy pass does, to the bit: windows that pass, drift, lose their reference (a
    non-finite state, a claim over its share) or grow the scales, narrow and wide (the
    column reductions switch to numpy's own past 16 columns)."""
    rng = np.random.default_rng(seed)
    n = d // 2
    t = np.cumsum(rng.uniform(0.1, 1.0, rows + 1))
    z = rng.normal(size=(rows + 1, d))
    states = z[1:] + 1e-4 * rng.normal(size=(rows, d))
    states[drift_at:] += 0.05 * growth  # the error passes the tolerance from there
    states[rows // 2:] *= 1.0 + growth  # the reference's states widen the scales
    claim = np.full(rows, 1e-6)
    claim[claim_at:] = 1.0
    if lost_at < rows:
        states[lost_at, rng.integers(d)] = [np.nan, np.inf][lost_at % 2]
    found = []
    for kernel in (None, check_kernel):
        scan = judgement.Scan(judgement.Extent(z), n, 1e-2, kernel)
        with np.errstate(invalid="ignore", over="ignore"):
            scan.measure(t, z, 0, rows, states.copy(), claim)
        found.append(_scan_state(scan))
    for numpy_value, compiled_value in zip(*found, strict=True):
        if isinstance(numpy_value, np.ndarray):
            np.testing.assert_array_equal(compiled_value, numpy_value)
        else:
            assert compiled_value == numpy_value


@pytest.mark.parametrize("name, overrides, stop", [
    ("paper_pendulum", {"t_end": 300.0}, True), ("kepler", {}, True),
    ("henon_heiles", {"t_end": 60.0}, True),
    # wrong from its first step: the early verdict stops it, or (not stopping) the final
    # check finds the local error past the screen, against the exact flow
    ("kepler", {"e": 0.95, "tau0": 0.01, "t_end": 4.0}, True),
    ("kepler", {"e": 0.95, "tau0": 0.01, "t_end": 4.0}, False)])
def test_the_compiled_passes_change_no_figure(check_kernel, monkeypatch, name, overrides,
                                              stop):
    """The check of a march through the compiled passes (``exact/kernel.py``: the reference
    read at the nodes, its claim, the scan, the screen read without divisions, the energy
    scale, the extremes) reports what numpy's passes report, to the bit: the status and
    message, every figure of the verdict and the local error of every step."""
    from ddvp_nlp import Tolerance

    scene = load_scene(name)
    config = scene.resolve(overrides)

    def run():
        return march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                     tau0=config.tau0, params=config.params, accuracy=Tolerance(stop=stop))
    run()  # the early verdict's kept looks: the same for both
    found = []
    for kernel in (check_kernel, None):
        monkeypatch.setattr(AdaptiveFlow, "kernel", lambda self, kernel=kernel: kernel)
        monkeypatch.setattr(judgement.Judgement, "kernel", lambda self, kernel=kernel: kernel)
        found.append(run())
    compiled, plain = found
    assert (compiled.status, compiled.message) == (plain.status, plain.message)
    assert compiled.verdict.as_dict() == plain.verdict.as_dict()
    np.testing.assert_array_equal(compiled.local_error, plain.local_error)
    if overrides.get("e") == 0.95:
        assert compiled.verdict.inaccurate


@pytest.mark.parametrize("seed", range(2))
def test_the_screen_read_without_divisions_is_step_errors(check_kernel, monkeypatch, seed):
    """`judgement.screened_errors` (the compiled screen: ``|d| <= CANDIDATE * bound`` without
    a division) gives `step_errors`' figures where its callers read them: every step's local
    error, the largest relative one, and the ratio and relative error of every step whose
    ratio may pass ``CANDIDATE``; every other step's ratio is at most ``CANDIDATE``. Screens
    drawn around the bound, NaN among them (those steps go to the exact flow)."""
    scene = load_scene("harmonic")
    config = scene.resolve({"t_end": 5.0})
    solution = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                     tau0=config.tau0, params=config.params, accuracy=None)
    t, z = solution.t, np.hstack([solution.q, solution.p])
    rng = np.random.default_rng(seed)
    check = judgement.Judgement(scene.system, scene.system.parameter_vector(config.params),
                                judgement.Tolerance(), compiler="auto")
    scale = column_span(z) * rng.uniform(0.5, 2.0, z.shape[1])
    limit = check.tolerance.rtol * scale
    d = limit * judgement.CANDIDATE * rng.choice([0.5, 1.0, np.nextafter(1.0, 2.0), 1.1, 3.0],
                                                 size=(t.size - 1, z.shape[1]))
    d *= rng.choice([-1.0, 1.0], size=d.shape)
    d[rng.integers(d.shape[0], size=3), rng.integers(d.shape[1], size=3)] = np.nan
    look = (d, None, None)
    monkeypatch.setattr(judgement.Judgement, "kernel", lambda self: None)
    local, relative, ratio = check.step_errors(t, z, scale, look)
    monkeypatch.setattr(judgement.Judgement, "kernel", lambda self: check_kernel)
    local_c, relative_max, steps, relative_c, ratio_c = judgement.screened_errors(
        check, t, z, scale, look)
    np.testing.assert_array_equal(local_c, local)
    assert relative_max == float(np.max(relative, initial=0.0))
    np.testing.assert_array_equal(ratio_c, ratio[steps])
    np.testing.assert_array_equal(relative_c, relative[steps])
    others = np.setdiff1d(np.arange(ratio.size), steps)
    assert np.all(ratio[others] <= judgement.CANDIDATE)
    assert 0 < steps.size < ratio.size
