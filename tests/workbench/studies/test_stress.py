"""The stress grid (quick version): every method on stiff and extreme cases, predicted and
observed breakdowns side by side, nothing lost."""

import csv
import math
import warnings

import pytest

from ddvp_nlp import Compilation
from ddvp_nlp.cli import main
from ddvp_nlp.studies.stress import COLUMNS, default_cases
from ddvp_nlp.studies.stress_report import read_rows, stress


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("stress")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        rows = stress(out, quick=True, compilation=Compilation(compiler=None))
    return out, rows


def _row(rows, case, method):
    (row,) = [r for r in rows if r["case"] == case and r["method"] == method]
    return row


@pytest.mark.slow(why="study")
def test_every_case_runs_every_method_that_applies(quick):
    out, rows = quick
    cases = default_cases(quick=True)
    for case in cases:
        methods = {r["method"] for r in rows if r["case"] == case.name}
        expected = {"vddvp", "midpoint", "stormer_verlet", "rk4", "dop853"}
        if case.scene == "paper_pendulum":  # lee differs from vddvp only where H depends on t
            expected.add("lee")
        assert methods == expected, case.name
    with open(out / "stress.csv", newline="") as handle:
        assert next(csv.reader(handle)) == COLUMNS
    assert len(read_rows(out / "stress.csv")) == len(rows)


@pytest.mark.slow(why="study")
def test_predicted_breakdowns_are_the_observed_ones(quick):
    out, rows = quick
    text = (out / "stress.md").read_text()
    # c(z) changes sign on the e = 0.9 Kepler orbit and on the rotating pendulum: the energy
    # step breaks down there, and only there
    assert "| kepler: e=0.9 | yes |" in text and "| pendulum: H=2.5 (rotation) | yes |" in text
    for case in ("e=0.9", "H=2.5 (rotation)"):
        assert _row(rows, case, "vddvp")["status"] in ("newton_failed", "no_admissible_step",
                                                       "residual_too_large")
    for case in ("e=0.5", "H=2-1e-2", "omega=50, omega*tau=4"):
        assert _row(rows, case, "vddvp")["status"] == "success"
    assert "**no**" not in text.split("## Predicted and observed")[1].split("## Where")[0]


@pytest.mark.slow(why="study")
def test_explicit_methods_blow_up_beyond_their_stability_limit(quick):
    _, rows = quick
    for method in ("stormer_verlet", "rk4"):  # omega*tau = 4 > 2 and > 2.83
        row = _row(rows, "omega=50, omega*tau=4", method)
        assert row["status"] == "non_finite" and row["t_reached"] < 2.0
        assert _row(rows, "omega=50, omega*tau=0.5", method)["status"] == "success"
    # the implicit midpoint-type schemes stay stable with the same large step
    assert _row(rows, "omega=50, omega*tau=4", "midpoint")["status"] == "success"


@pytest.mark.slow(why="study")
def test_failed_runs_say_where_and_why_and_lose_nothing(quick):
    out, rows = quick
    failed = [r for r in rows if r["status"] != "success"]
    assert failed
    for r in failed:
        assert r["message"].startswith(("a step", "Newton", "the step"))
        assert "from t = " in r["message"] and math.isfinite(r["t_reached"])
        assert r["steps"] >= 0
    text = (out / "stress.md").read_text()
    assert "## Where and why each failed run stopped" in text
    assert (out / "stress.png").stat().st_size > 10_000


@pytest.mark.slow(why="study")
def test_long_run_separates_symplectic_from_dissipative_energy_error(quick):
    _, rows = quick
    harmonic = "harmonic, 10 periods"
    assert _row(rows, harmonic, "midpoint")["energy_error"] < 1e-13  # quadratic H kept exactly
    assert _row(rows, harmonic, "vddvp")["energy_error"] < 1e-11


def test_stress_command(tmp_path, capsys, monkeypatch):
    from ddvp_nlp.studies import stress as stress_module

    # the command on a smaller set of cases (a function replaced, not a setting switched), in
    # this process (--workers 1): a local cluster's two workers cost more than the runs; the
    # cluster ddvp starts is cli/test_seams.py's (a grid on the default workers), a cluster
    # at a scheduler runner/test_dask_grids.py's (test_killing_a_worker_loses_no_...)
    cases = [c for c in stress_module.default_cases(quick=True) if c.group == "pendulum"]
    monkeypatch.setattr(stress_module, "default_cases", lambda quick=False: cases)
    code = main(["stress", "--quick", "--no-compile", "--no-progress", "--workers", "1",
                 "--out", str(tmp_path)])
    assert code == 0
    out = capsys.readouterr().out
    assert out.startswith("stress: 10 runs")
    assert "vddvp           1 reached t_end; newton_failed 1" in out
    assert main(["stress", "--time-limit", "0", "--out", str(tmp_path / "x")]) == 2
    assert "ddvp stress: error: --time-limit must be > 0, got 0.0" in capsys.readouterr().err


def test_a_sweep_reports_every_method_it_ran(tmp_path, capsys):
    """The report's columns are the methods that ran: lee_left is in no default grid, but a
    sweep that asks for it gets its column."""
    out = tmp_path / "sweep"
    assert main(["sweep", "harmonic", "--grid", "w=1", "--methods", "lee_left,rk4", "--set",
                 "t_end=2", "--workers", "1", "--no-compile", "--no-progress",
                 "--out", str(out)]) == 0
    assert "lee_left" in capsys.readouterr().out
    table = (out / "sweep.md").read_text().split("## harmonic")[1]
    header = table.strip().splitlines()[0]
    assert header == "| case | tau | predicted for vddvp | `rk4` | `lee_left` |"
