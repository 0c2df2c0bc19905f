"""A sweep's map marks every run the accuracy check did not pass (a drifted run's colour alone
read as a good run), and draws a method that ignores a swept ``tau0`` (DOP853) once, saying
so."""

from __future__ import annotations

from types import SimpleNamespace as NS

from ddvp_nlp.io import figures
from ddvp_nlp.io.stress_figure import VERDICT_HATCHES, plot_stress


def kept(draw):
    target = figures.Keep()
    draw(target)
    return target.figure


def sweep(axes=("e", "tau0")):
    """Kepler over e and tau0: vddvp drifted at e = 0.6, failed at 0.9; rk4 inaccurate at
    one cell; dop853 at one rtol whatever tau0."""
    es, taus = (0.3, 0.6, 0.9), (0.001, 0.0005)
    cases = [NS(group="kepler", name=f"{axes[0]}={e}, {axes[1]}={t}") for e in es for t in taus]

    def row(case, method):
        e = float(case.name.split(",")[0].split("=")[1])
        tau = float(case.name.split("=")[-1])
        if method == "vddvp":
            if e == 0.9:
                return {"status": "no_admissible_step", "energy_error": 0.2, "knob": "tau0",
                        "value": tau, "accuracy": "drifted from t = 0.003"}
            return {"status": "success", "energy_error": 1e-4 * e, "knob": "tau0",
                    "value": tau, "accuracy": "drifted from t = 1" if e == 0.6 else "accurate"}
        if method == "rk4":
            return {"status": "success", "energy_error": 1e-9 * e, "knob": "tau", "value": tau,
                    "accuracy": "inaccurate: local at step 3" if (e, tau) == (0.3, 0.001)
                    else "accurate"}
        return {"status": "success", "energy_error": 1e-8 * e, "knob": "rtol", "value": 1e-10,
                "accuracy": "drifted from t = 2" if e == 0.9 else "accurate"}

    return NS(cases=cases, methods=["vddvp", "rk4", "dop853"], row=row)


def hatched(ax):
    return {(round(p.get_x() + 0.5), round(p.get_y() + p.get_height() / 2, 1)): p.get_hatch()
            for p in ax.patches if p.get_hatch()}


def test_every_run_the_check_did_not_pass_is_hatched_and_named_and_dop853_is_drawn_once():
    fig = kept(lambda target: plot_stress(sweep(), target, cells=None, title="sweep"))
    panels = {ax.get_title().split(":")[0]: ax for ax in fig.axes if ax.get_title()}
    vddvp, rk4, dop853 = panels["vddvp"], panels["rk4"], panels["dop853"]
    # vddvp: e = 0.6 (column 1) drifted at both tau0; the failed column is red, not hatched
    assert hatched(vddvp) == {(1, 0.0): VERDICT_HATCHES["drifted"],
                              (1, 1.0): VERDICT_HATCHES["drifted"]}
    assert [t.get_text() for t in vddvp.texts].count("drifted") == 2
    assert hatched(rk4) == {(0, 1.0): VERDICT_HATCHES["inaccurate"]}  # tau0 = 0.001: row 1
    assert "inaccurate" in [t.get_text() for t in rk4.texts]
    # dop853: one row across the tau0 axis, its rtol in the title, its drifted cell once
    assert "rtol = 1e-10" in dop853.get_title() and "every" in dop853.get_title()
    (mesh,) = dop853.collections
    assert mesh.get_array().shape == (1, 3)  # one row of three e cells
    assert hatched(dop853) == {(2, 0.5): VERDICT_HATCHES["drifted"]}
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert any("drifted" in t for t in legend) and any("inaccurate" in t for t in legend)
    assert any("failed" in t for t in legend)


def test_an_axis_other_than_tau0_is_drawn_whole_for_every_method():
    fig = kept(lambda target: plot_stress(sweep(("e", "mu")), target, cells=None,
                                          title="sweep"))
    dop853 = next(ax for ax in fig.axes if ax.get_title().startswith("dop853"))
    assert dop853.get_title() == "dop853"
    assert dop853.collections[0].get_array().shape == (2, 3)


def test_a_case_grid_hatches_the_runs_the_check_did_not_pass():
    import numpy as np

    verdicts = ("accurate", "drifted from t = 4", "inaccurate: energy at step 2")
    cases = [NS(group="a", name=str(i)) for i in range(3)]
    rows = {str(i): {"status": "success", "energy_error": 1e-6, "accuracy": verdict}
            for i, verdict in enumerate(verdicts)}
    result = NS(cases=cases, methods=["vddvp"], row=lambda case, method: rows[case.name])
    cells = (np.array([[-6.0]] * 3), [["1e-06"]] * 3)
    fig = kept(lambda target: plot_stress(result, target, cells=cells, title="stress"))
    ax = fig.axes[0]
    found = {round(p.get_y() + 0.5): p.get_hatch() for p in ax.patches if p.get_hatch()}
    assert found == {1: VERDICT_HATCHES["drifted"], 2: VERDICT_HATCHES["inaccurate"]}
