"""``compare`` on a constrained scene (issue 48): the methods that march on ``g = 0`` (the
paper's schemes, RATTLE, SHAKE) are compared, each run judged against the constrained exact
flow; every method that does not know constraints refuses the scene by its ``applies``, named.
Small knobs (t_end = 5, three steps per method): about 2 s CPU."""

import numpy as np
import pytest

from ddvp_nlp import compare
from ddvp_nlp.errors import InputError
from ddvp_nlp.scenes import load_scene
from ddvp_nlp.solvers import INTEGRATORS
from ddvp_nlp.studies.methods import METHODS
from ddvp_nlp.studies.work_precision import CompareOptions, default_methods

SMALL = CompareOptions(halvings=2, repeats=1)
CONSTRAINED = ("vddvp", "lee", "midpoint", "rattle", "shake")


def _fitted_order(rows):
    steps = np.array([r["value"] for r in rows])
    errors = np.array([r["trajectory_error"] for r in rows])
    return float(np.polyfit(np.log(steps), np.log(errors), 1)[0])


def test_every_method_without_constraints_refuses_a_constrained_scene_by_name():
    system = load_scene("cartesian_pendulum").system
    chosen, left_out = default_methods(system)
    assert [m.name for m in chosen] == ["vddvp", "midpoint", "rattle", "shake"]
    assert left_out[0].startswith("`lee`: for autonomous H")
    for integrator in INTEGRATORS:
        reason = integrator.applies(system)
        if integrator.name in CONSTRAINED:
            assert reason is None, integrator.name
        else:
            assert "does not know holonomic constraints" in reason, integrator.name
            # the same integrator on a system without constraints: the refusal is gone
            unconstrained = load_scene("paper_pendulum").system
            assert "constraints" not in (METHODS[integrator.name].applies(unconstrained) or "")
    for name in ("rk4", "dop853", "stormer_verlet"):
        with pytest.raises(InputError, match=f"method '{name}' does not apply to scene "
                                             "'cartesian_pendulum': it does not know "
                                             "holonomic constraints"):
            compare("cartesian_pendulum", methods=[name], options=SMALL)


def test_a_rotation_compared_every_run_judged_rattle_of_order_two():
    result = compare("cartesian_pendulum", t_span=(0, 5), options=SMALL)
    rows = {m: [r for r in result.rows if r["method"] == m] for m in CONSTRAINED}
    assert not rows["lee"]  # the same equations as vddvp for autonomous H
    for method in ("vddvp", "midpoint", "rattle", "shake"):
        assert len(rows[method]) == 3
        for row in rows[method]:
            assert row["status"] == "success", row["message"]
            assert row["accuracy"] and row["trajectory_error"] > 0 and row["steps"] > 0
            assert row["reference"].startswith("the exact flow")
    # vddvp keeps its energy row to round-off on the rotation (E = 3.5)
    assert max(r["scheme_energy_residual"] for r in rows["vddvp"]) < 1e-13
    assert _fitted_order(rows["rattle"]) == pytest.approx(2.0, abs=0.05)
    assert _fitted_order(rows["vddvp"]) == pytest.approx(2.0, abs=0.1)
    # judged on the scales of the motion: the true error over the momenta's range (6) is
    # under global_tol (1e-2) on every run, and every run is called accurate
    assert all(r["accuracy"] == "accurate" for r in rows["vddvp"] + rows["rattle"])
    assert max(r["trajectory_error"] for r in result.rows if r["method"] != "shake") < 0.06


def test_a_libration_compared_fixed_steps_run_and_the_energy_steps_stop_said():
    start = dict(q0=[np.sin(1.0), -np.cos(1.0)], p0=[0.0, 0.0])
    result = compare("cartesian_pendulum", t_span=(0, 5), options=SMALL, **start)
    by = {m: [r for r in result.rows if r["method"] == m] for m in CONSTRAINED}
    for method in ("midpoint", "rattle"):
        assert all(r["status"] == "success" and r["accuracy"] == "accurate"
                   for r in by[method])
        assert _fitted_order(by[method]) == pytest.approx(2.0, abs=0.05)
    # vddvp: c of theory section 12 changes sign where 2E - 3y = 1 (y = -0.693 here): its
    # runs stop there, each with its reason, never called a success
    for row in by["vddvp"]:
        assert row["status"] != "success" and row["t_reached"] < 1.0 and row["message"]
        assert row["t_reached"] > 0.5


def test_what_a_constrained_comparison_does_not_do_yet_is_refused():
    with pytest.raises(InputError, match="has 1 constraint; compare does not take "
                                         "target_errors"):
        compare("cartesian_pendulum", target_errors=[1e-3])
    with pytest.raises(InputError, match="has 1 constraint; compare does not take a "
                                         "backward span"):
        compare("cartesian_pendulum", t_span=(0, -1), options=SMALL)


def _swapped_pendulum(swap):
    """The Cartesian pendulum with its coordinates in either order (height last or first)."""
    from ddvp_nlp import HamiltonianSystem

    up = 0 if swap else 1

    def hamiltonian(q, p, t):
        return (p[0] ** 2 + p[1] ** 2) / 2 + q[up]

    def rod(q, t):
        return q[0] ** 2 + q[1] ** 2 - 1
    return HamiltonianSystem(hamiltonian, 2, name="swapped" if swap else "plain",
                             constraints=rod)


RELABEL_START = np.array([0.0, -1.0]), np.array([3.0, 0.0])
RELABEL_OPTIONS = CompareOptions(methods=["rattle", "midpoint"], halvings=1, repeats=1)


@pytest.fixture(scope="module")
def unrelabelled():
    """The comparison both cases below are measured against, made once (and only read)."""
    q0, p0 = RELABEL_START
    return compare(_swapped_pendulum(False), q0=q0, p0=p0, t_span=(0, 4),
                   options=RELABEL_OPTIONS)


@pytest.mark.parametrize("swap, t0", [(True, 0.0), (False, 3.0)])
def test_a_system_compared_relabelled_or_shifted_in_time_gives_the_same_errors(
        unrelabelled, swap, t0):
    """A constrained HamiltonianSystem compared from a start over a span (its first step from
    the constrained exact flow's time scale): its coordinates swapped, or its span shifted,
    leave every run's errors and verdict as they were."""
    q0, p0 = RELABEL_START
    options, base = RELABEL_OPTIONS, unrelabelled
    other = compare(_swapped_pendulum(swap), q0=q0[::-1] if swap else q0,
                    p0=p0[::-1] if swap else p0, t_span=(t0, t0 + 4), options=options)
    assert len(base.rows) == len(other.rows) == 4
    for a, b in zip(base.rows, other.rows, strict=True):
        assert (a["method"], a["status"], a["steps"]) == (b["method"], b["status"], b["steps"])
        assert a["value"] == pytest.approx(b["value"], rel=1e-9)
        assert b["trajectory_error"] == pytest.approx(a["trajectory_error"], rel=1e-6)
        assert _verdict(b["accuracy"], t0) == pytest.approx(_verdict(a["accuracy"], 0.0))


def _verdict(accuracy: str, t0: float):
    """A row's verdict with its drift time counted from the start of the span."""
    if " from t = " not in accuracy:
        return (accuracy, 0.0)
    name, when = accuracy.split(" from t = ")
    return (name, float(when) - t0)
