"""The Python ``compare`` (issue 40): the object ``ddvp compare`` builds and writes, its rows
against a direct march, failed runs kept with their reasons, its figure, the command's rows,
refused input; and every compared method on drawn smooth bound one-degree-of-freedom orbits."""

import math

import casadi as ca
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from ddvp_nlp import Compilation, HamiltonianSystem, InputError, compare, march
from ddvp_nlp.cli import main
from ddvp_nlp.studies import CompareOptions
from ddvp_nlp.studies.methods import METHODS
from ddvp_nlp.studies.work_precision_report import read_rows

MORSE_SCENE = '''
import casadi as ca
from ddvp_nlp import Scene

def hamiltonian(q, p, t, D, a):
    return p[0] ** 2 / 2 + D * (1 - ca.exp(-a * q[0])) ** 2

scene = Scene(hamiltonian, n=1, params={"D": 1.0, "a": 1.0}, q0=[0.0], p0=[1.0], tau0=0.1,
              t_end=4.0, name="morse")
'''
VM = Compilation(compiler=None)
QUICK = {"halvings": 0, "repeats": 1}


def morse(D=1.0, a=1.0):
    def H(q, p, t, D, a):
        return p[0] ** 2 / 2 + D * (1 - ca.exp(-a * q[0])) ** 2
    return HamiltonianSystem(H, 1, {"D": D, "a": a}, name="morse")


def test_rows_are_those_of_a_direct_march_of_the_same_method_and_knob():
    system = morse()
    result = compare(system, ["vddvp"], q0=[0.0], p0=[1.0], t_span=(0.0, 4.0),
                     options=CompareOptions(knobs={"vddvp": [0.1]}, repeats=1), compilation=VM)
    (row,) = result.rows
    direct = march(system, [0.0], [1.0], (0.0, 4.0), tau0=0.1, accuracy=None)
    assert row["method"] == "vddvp" and row["knob"] == "tau0" and row["value"] == 0.1
    assert row["status"] == "success" and row["steps"] == direct.steps
    assert row["t_reached"] == pytest.approx(direct.t[-1], rel=1e-12)
    H = direct.energy(system)
    assert row["energy_error"] == pytest.approx(np.max(np.abs(H - H[0])), rel=1e-9, abs=1e-15)
    assert 0 < row["trajectory_error"] < 0.05 and row["accuracy"] == "accurate"
    assert row["run_s"] > 0 and row["cpu_s"] >= 0 and math.isnan(row["chosen_tau0"])
    assert result.best(1.0)["method"] == "vddvp" and result.best(1e-14) is None


def test_failed_runs_are_kept_with_their_reason_and_the_plot_is_a_figure(tmp_path):
    from matplotlib.figure import Figure

    result = compare(morse(), ["rk4", "lee_left"], q0=[0.0], p0=[1.0], t_span=(0.0, 4.0),
                     options=CompareOptions(**QUICK), compilation=VM)
    failed = result.failed
    assert failed and {r["method"] for r in failed} == {"lee_left"}
    assert all(r["message"] and r["status"] != "success" for r in failed)
    assert "turning point" in result.limitations()["lee_left"]
    assert isinstance(result.plot(), Figure)
    assert isinstance(result.plot(tmp_path / "wp.png"), Figure)
    assert (tmp_path / "wp.png").stat().st_size > 0
    result.to_csv(tmp_path / "rows.csv")
    assert (tmp_path / "rows.csv").read_text().count("\n") == len(result.rows) + 1


def test_target_errors_run_the_march_once_per_target():
    result = compare(morse(), ["vddvp", "rk4"], q0=[0.0], p0=[1.0], t_span=(0.0, 4.0),
                     target_errors=[1e-2], options=CompareOptions(**QUICK), compilation=VM)
    aimed = [r for r in result.rows if r["method"] == "vddvp"]
    assert [(r["knob"], r["value"]) for r in aimed] == [("target_error", 1e-2)]
    assert aimed[0]["chosen_tau0"] > 0 and aimed[0]["accuracy"] == "accurate"
    assert [r["knob"] for r in result.rows if r["method"] == "rk4"] == ["tau"]


def test_the_command_writes_the_rows_the_python_call_returns(tmp_path):
    scene_file = tmp_path / "morse.py"
    scene_file.write_text(MORSE_SCENE)
    args = ["compare", str(scene_file), "--methods", "vddvp,rk4", "--halvings", "0",
            "--repeats", "1", "--no-compile", "--no-progress", "--out", str(tmp_path / "out")]
    assert main(args) == 0
    written = read_rows(tmp_path / "out" / "work_precision.csv")
    returned = compare(str(scene_file), "vddvp,rk4", options=CompareOptions(**QUICK),
                       compilation=VM).rows
    same = ("method", "knob", "value", "status", "steps", "t_reached", "trajectory_error",
            "energy_error", "accuracy", "message")
    assert [{k: r[k] for k in same} for r in written] == \
        [{k: r[k] for k in same} for r in returned]


@pytest.mark.parametrize("call, message", [
    (lambda: compare("harmonic", ["verlet", "rk4"]), r"unknown method 'verlet' \(choose from"),
    (lambda: compare(morse(), ["rk4"], q0=[0.0]), "give p0, t_span"),
    (lambda: compare("harmonic", ["rk4"], target_errors=[2.0]), "below 1"),
    (lambda: compare("harmonic", ["rk4"], target_errors=[]), "target_errors must be"),
    (lambda: compare(3.0), "problem must be a scene name"),
    (lambda: compare("harmonic", ["rk4"], params={"omega": 2.0}), "has no parameter 'omega'"),
    (lambda: compare("harmonic", ["rk4"], t_span=(0.0,)), "t_span must be a pair"),
])
def test_bad_input_is_refused_by_name(call, message):
    with pytest.raises(InputError, match=message):
        call()


def _well(kind, coefficients):
    """A smooth bound well: Morse ``D (1 - exp(-a q))^2`` or a polynomial ``q^2/2 + c3 q^3 +
    c4 q^4`` with ``c4 > 0`` and ``c3^2 < 2 c4`` (one minimum, at 0)."""
    if kind == "morse":
        D, a = coefficients
        return lambda q: D * (1 - ca.exp(-a * q)) ** 2
    c3, c4 = coefficients
    return lambda q: q ** 2 / 2 + c3 * q ** 3 + c4 * q ** 4


wells = st.one_of(
    st.tuples(st.just("morse"), st.tuples(st.floats(0.5, 4.0), st.floats(0.5, 2.0)),
              st.floats(0.1, 0.8)),
    st.tuples(st.just("polynomial"),
              st.floats(0.05, 1.0).flatmap(lambda c4: st.tuples(
                  st.floats(-0.9, 0.9).map(lambda s: s * math.sqrt(2 * c4)), st.just(c4))),
              st.floats(0.05, 1.0)))


@pytest.mark.slow(why="repetition")
@settings(max_examples=3, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(wells)
@example(("polynomial", (1.2374368670764582, 1.0), 1.0))  # the energy rules' breakdown
def test_every_method_runs_at_its_middle_knob_on_a_smooth_bound_orbit(well):
    """Starting at the bottom of the well with ``p0`` for the drawn energy (a fraction of
    ``D`` for Morse), about two periods: each method at the middle of its default sweep
    succeeds, or fails with a message and a limitation its integrator states."""
    kind, coefficients, level = well
    V = _well(kind, coefficients)
    energy = level * coefficients[0] if kind == "morse" else level
    system = HamiltonianSystem(lambda q, p, t: p[0] ** 2 / 2 + V(q[0]), 1, name=kind)
    methods = [name for name in METHODS if METHODS[name].applies(system) is None]
    result = compare(system, methods, q0=[0.0], p0=[math.sqrt(2 * energy)],
                     t_span=(0.0, 12.0), options=CompareOptions(halvings=2, repeats=1,
                                                                reference="none"),
                     compilation=VM)
    middle = {}
    for row in result.rows:
        middle.setdefault(row["method"], []).append(row)
    for name, rows in middle.items():
        row = rows[len(rows) // 2]
        if row["status"] != "success":
            assert row["message"] and METHODS[name].limitation, (name, row["message"])


@pytest.mark.parametrize("text", ["-1", "1e-3,nan", "2", ","])
def test_the_command_names_its_own_option_for_bad_target_errors(text, tmp_path, capsys):
    assert main(["compare", "harmonic", "--target-errors", text, "--out",
                 str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "--target-errors" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()
