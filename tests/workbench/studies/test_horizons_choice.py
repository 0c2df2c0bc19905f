"""The comparison over horizons (issue 49): ``best(error, horizon)`` and its rule on synthetic
tables, the crossovers, the horizons reader (hypothesis), a harmonic run of horizons x errors
with its counts, and the metamorphic checks (time units scaled, an energy offset)."""

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import InputError, Scene, compare
from ddvp_nlp.io import figures
from ddvp_nlp.studies import CompareOptions
from ddvp_nlp.studies.horizons import check_horizons, parse_horizons
from ddvp_nlp.studies.horizons_choice import CROSSOVER_RTOL, HorizonComparison


def rows(*runs):
    """Rows of successful runs ``(method, cost, error)``: the same number in every cost and
    error column."""
    return [{"method": m, "status": "success", "run_s": c, "cpu_s": c, "steps": c,
             "trajectory_error": e, "energy_error": e} for m, c, e in runs]


def study(table: dict) -> HorizonComparison:
    return HorizonComparison({h: NS(rows=rows(*runs)) for h, runs in table.items()})


# A: cost proportional to T (at the error 1e-4: 1 s at T = 10, 100 s at T = 1000); B: the
# same 10 s at every horizon. Their costs cross at T = 100.
TABLE = {10.0: [("A", 0.5, 1e-2), ("A", 2.0, 1e-6), ("B", 5.0, 1e-2), ("B", 20.0, 1e-6)],
         1000.0: [("A", 50.0, 1e-2), ("A", 200.0, 1e-6), ("B", 5.0, 1e-2), ("B", 20.0, 1e-6)]}


def test_best_reads_the_front_in_log_log_and_the_horizons_in_log_t():
    result = study(TABLE)
    at_10 = result.best(1e-4, 10.0)
    assert at_10.method == "A" and at_10.seconds == pytest.approx(1.0)  # sqrt(0.5 * 2)
    assert at_10.certain and not at_10.upper_bound and "measured at T = 10" in at_10.why
    between = result.best(1e-4, 10.0 ** 1.5)
    assert between.method == "A" and between.seconds == pytest.approx(10 ** 0.5)
    assert "interpolated in log T" in between.why
    assert result.best(1e-4, 10.0 ** 2.5).method == "B"
    (crossing,) = result.crossovers([1e-4])
    assert (crossing.before, crossing.after) == ("A", "B")
    assert crossing.horizon == pytest.approx(100.0, rel=2 * CROSSOVER_RTOL)
    assert "`A` from T = 10; `B` from T = 100" in result.crossover_words([1e-4])[0]


def test_an_error_no_method_reaches_is_none_with_why():
    result = study(TABLE)
    for error, horizon, said in [(1e-9, 10.0, "no method reaches trajectory error 1e-09"),
                                 (1e-4, 1e5, "outside the measured horizons"),
                                 (1e-4, 1.0, "outside the measured horizons")]:
        choice = result.best(error, horizon)
        assert choice.method is None and not choice and said in choice.why
        assert math.isnan(choice.seconds) and choice.ranking == ()


def test_a_bound_is_said_and_makes_the_choice_uncertain():
    # C's cheapest run is already below the error: its cost there is only an upper bound
    result = study({10.0: [("A", 1.0, 1e-2), ("A", 4.0, 1e-6), ("C", 3.0, 1e-8)]})
    choice = result.best(1e-4, 10.0)
    assert choice.method == "A" and not choice.certain and "`C`" in choice.why
    assert choice.ranking[1] == ("C", 3.0, True)
    alone = result.best(1e-7, 10.0)
    assert alone.method == "C" and alone.upper_bound and "at most 3 s" in alone.why


def test_a_method_reaching_the_error_at_one_horizon_only_has_no_cost_between():
    table = {10.0: [("A", 1.0, 1e-5), ("B", 8.0, 1e-5)],
             100.0: [("A", 10.0, 1e-3), ("B", 30.0, 1e-5)]}
    result = study(table)
    assert result.best(1e-4, 10.0).method == "A"
    assert result.best(1e-4, 30.0).ranking[0][0] == "B"  # A has no cost at 30
    (crossing,) = result.crossovers([1e-4])
    assert crossing.horizon == pytest.approx(10.0, rel=2 * CROSSOVER_RTOL)
    assert "from just above T = 10" in result.crossover_words([1e-4])[0]


@pytest.mark.parametrize("call, said", [
    (lambda r: r.best(-1e-3, 10.0), "error must be > 0"),
    (lambda r: r.best(1e-3, float("nan")), "horizon must be finite"),
    (lambda r: r.best(1e-3, 10.0, kind="phase"), "kind must be one of"),
    (lambda r: r.best(1e-3, 10.0, cost="joules"), "cost must be one of"),
    (lambda r: r.crossovers([0.0]), "error must be > 0")])
def test_bad_questions_are_refused_by_name(call, said):
    with pytest.raises(InputError, match=said):
        call(study(TABLE))


@pytest.mark.parametrize("scale, speed", [(1e3, 1.0), (1e-2, 7.0), (3.0, 0.01)])
def test_time_units_and_a_faster_machine_move_the_crossover_not_the_winner(scale, speed):
    """Horizons times ``scale`` (another time unit), costs times ``speed`` (another machine):
    the same winner at the scaled horizon, the crossover scaled with the horizons."""
    base = study(TABLE)
    moved = study({h * scale: [(m, c * speed, e) for m, c, e in runs]
                   for h, runs in TABLE.items()})
    for horizon in (10.0, 30.0, 99.0, 101.0, 500.0, 1000.0):
        for error in (1e-3, 1e-4, 1e-5):
            assert moved.best(error, horizon * scale).method == \
                base.best(error, horizon).method
    (a,), (b,) = base.crossovers([1e-4]), moved.crossovers([1e-4])
    assert b.horizon / scale == pytest.approx(a.horizon, rel=2 * CROSSOVER_RTOL)


finite = st.floats(min_value=1e-6, max_value=1e12, allow_nan=False, allow_infinity=False)


@settings(max_examples=150, deadline=None, derandomize=True, database=None)
@given(st.lists(finite, min_size=1, max_size=6, unique=True), st.booleans())
def test_the_horizons_reader_sorts_what_it_accepts(values, as_text):
    given_ = ",".join(repr(v) for v in values) if as_text else values
    assert parse_horizons(given_) == sorted(values)


@settings(max_examples=150, deadline=None, derandomize=True, database=None)
@given(st.lists(finite, min_size=1, max_size=5, unique=True),
       st.sampled_from([0.0, -1.0, float("nan"), float("inf"), "x", "dup"]),
       st.integers(min_value=0, max_value=5))
def test_the_horizons_reader_refuses_what_is_not_a_horizon_by_name(values, bad, where):
    bad = values[0] if bad == "dup" else bad
    values = [*values[:where], bad, *values[where:]]
    with pytest.raises(InputError, match="horizon"):
        parse_horizons(",".join(str(v) for v in values))
    with pytest.raises(InputError, match="horizon"):
        parse_horizons(values)


def test_empty_horizons_and_a_horizon_shorter_than_a_step_are_refused():
    for empty in ("", " , ", []):
        with pytest.raises(InputError, match="at least one horizon"):
            parse_horizons(empty)
    config = NS(tau0=0.1)
    with pytest.raises(InputError, match=r"horizon 0.05 .* shorter than the scene's first "
                                         r"step tau0 = 0.1"):
        check_horizons([0.05, 10.0], 1.0, config)
    check_horizons([0.05], 2.0, config)  # 0.1 time units: one step
    with pytest.raises(InputError, match="horizons must name at least one"):
        compare("harmonic", ["rk4"], horizons="")  # before anything runs


def harmonic(scale=1.0, offset=0.0):
    """H = (p^2 + q^2) / 2 in time units ``scale`` times longer (H / scale: the same orbit,
    ``scale`` times slower), plus ``offset``."""
    def H(q, p, t):
        return (p[0] ** 2 + q[0] ** 2) / (2 * scale) + offset
    return Scene(H, n=1, q0=[1.0], p0=[0.0], tau0=0.1 * scale, t_end=10.0 * scale,
                 name="harmonic")


FIXED = ["rk4", "stormer_verlet", "avf"]
OPTIONS = CompareOptions(halvings=2, repeats=1, budget_s=0.1)


@pytest.fixture(scope="module")
def harmonic_horizons():
    """The harmonic comparison over horizons 10 and 40, made once: the next two tests read it
    (and change nothing in it)."""
    return compare(harmonic(), FIXED, horizons=[10.0, 40.0], options=OPTIONS)


def test_horizons_times_errors_on_the_harmonic_oscillator(harmonic_horizons):
    result = harmonic_horizons
    assert result.horizons == [10.0, 40.0]
    for horizon, found in result.results.items():
        assert len(found.rows) == 3 * 3 and not found.failed  # 3 methods x 3 steps
        for row in found.rows:
            assert row["steps"] == round(horizon / row["value"])
            assert row["t_reached"] == pytest.approx(horizon)
            assert row["run_s"] <= row["run_s_median"] <= row["run_s_max"]
            assert row["cpu_s_median"] <= row["cpu_s_max"]
    assert len(result.rows) == 18 and {r["horizon"] for r in result.rows} == {10.0, 40.0}
    # by steps (no clock): rk4, fourth order, reaches 1e-5 in the fewest steps at both
    for horizon in (10.0, 20.0, 40.0):
        choice = result.best(1e-5, horizon, cost="steps")
        assert choice.method == "rk4" and choice.certain, choice.why
    # the energy of the quadratic H: avf keeps it to round-off at its coarsest step
    energy = result.best(1e-12, 40.0, kind="energy_error", cost="steps")
    assert energy.method == "avf" and energy.upper_bound
    assert result.best(1e-14, 40.0).method is None  # no trajectory that exact


def test_scaled_time_units_and_an_energy_offset_keep_the_winners(harmonic_horizons):
    """The same motion in time units 1000 times shorter (horizons / 1000), and with 5 added
    to H: the same steps, the same trajectory errors (to the reference's error), the same
    winner by steps at every error and horizon, the crossovers scaled with the horizons."""
    base = harmonic_horizons
    slow = compare(harmonic(scale=1e-3), FIXED, horizons=[1e-2, 4e-2], options=OPTIONS)
    lifted = compare(harmonic(offset=5.0), FIXED, horizons=[10.0, 40.0], options=OPTIONS)
    for other, factor in ((slow, 1e-3), (lifted, 1.0)):
        for (h, a), (k, b) in zip(base.results.items(), other.results.items(), strict=True):
            assert k == pytest.approx(h * factor)
            assert [r["steps"] for r in a.rows] == [r["steps"] for r in b.rows]
            assert np.allclose([r["trajectory_error"] for r in a.rows],
                               [r["trajectory_error"] for r in b.rows], rtol=1e-4)
        for error in (1e-2, 1e-4, 1e-6):
            for horizon in (10.0, 17.0, 40.0):
                assert other.best(error, horizon * factor, cost="steps").method == \
                    base.best(error, horizon, cost="steps").method
        levels = [1e-2, 1e-3, 1e-4, 1e-5, 1e-6]
        moved = [c.horizon / factor for c in other.crossovers(levels, cost="steps")]
        assert moved == pytest.approx([c.horizon for c in base.crossovers(levels,
                                                                          cost="steps")],
                                      rel=1e-2)


def test_the_crossover_figure_fits_a_column_and_writes_pdf_and_svg(tmp_path):
    result = study(TABLE)
    fig = result.plot_crossover(errors=[1e-3, 1e-4, 1e-5])
    assert tuple(fig.get_size_inches())[0] == figures.COLUMN_WIDTH
    assert [ax.get_title() for ax in fig.axes][0].startswith("trajectory error (absolute")
    for suffix in ("pdf", "svg", "png"):
        result.plot_crossover(tmp_path / f"crossover.{suffix}", errors=[1e-4])
        head = (tmp_path / f"crossover.{suffix}").read_bytes()[:200]
        assert {"pdf": b"%PDF", "svg": b"<svg", "png": b"PNG"}[suffix] in head


def test_target_errors_run_the_march_at_each_horizon_and_the_others_sweep():
    result = compare("harmonic", ["vddvp", "rk4"], horizons=[10.0, 20.0], target_errors=[1e-2],
                     options=CompareOptions(halvings=1, repeats=1, budget_s=0.1))
    for horizon, found in result.results.items():
        marched = [r for r in found.rows if r["method"] == "vddvp"]
        assert [(r["knob"], r["value"]) for r in marched] == [("target_error", 1e-2)]
        assert marched[0]["chosen_tau0"] > 0 and marched[0]["t_reached"] >= horizon
        assert [r["knob"] for r in found.rows if r["method"] == "rk4"] == ["tau", "tau"]
