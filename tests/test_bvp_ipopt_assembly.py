"""IPOPT fed by the banded assembly (bvp_ipopt_assembly.py): the same functions as the MX build,
the same nodes, few iterations (issue 16)."""

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import Scheme, load_scene
from ddvp_nlp.solvers.bvp import phase as bvp_phase
from ddvp_nlp.solvers.bvp.ipopt import AssemblyIpoptProblem
from ddvp_nlp.solvers.bvp.solve import solve_bvp
from ddvp_nlp.solvers.grid.ipopt import IpoptProblem


@pytest.mark.parametrize("name, rule", [("pendulum", "vddvp"), ("pendulum", "fixed"),
                                        ("kepler", "lee"), ("pendulum_lagrangian", "vddvp"),
                                        ("paper_pendulum", "vddvp")])
def test_callbacks_match_the_mx_build(name, rule):
    """g, its Jacobian and the Lagrangian's Hessian of the callbacks equal CasADi's own
    derivatives of the MX NLP at a random point (rows reordered: the MX build interleaves the
    step rows, the assembly appends them, in units of the mean step)."""
    system = load_scene(name).system
    nodes, n = 7, system.n
    assembly = AssemblyIpoptProblem(system, Scheme(rule), nodes, tol=1e-9, max_iter=5)
    mx = IpoptProblem(system, Scheme(rule), nodes, tol=1e-9, max_iter=5)
    rng = np.random.default_rng(3)
    t = np.sort(rng.random(nodes)) + np.arange(nodes)
    x = assembly.layout.pack(t, rng.random((nodes, n)) + 1, rng.random((nodes, n)))
    scale = 0.7
    parameters = np.r_[system.parameter_vector(None), scale]
    order = np.r_[np.flatnonzero(mx.kinds == 0), np.flatnonzero(mx.kinds == 1)]
    unit = np.where(mx.kinds[order] == 1, 1 / scale, 1.0)  # step rows in mean steps
    g_mx, J_mx = mx.solver.get_function("nlp_jac_g")(x, parameters)
    g_mx = np.asarray(g_mx).ravel()[order] * unit
    J_mx = np.asarray(ca.DM(J_mx))[order] * unit[:, None]
    g, jac_g, hess_lag = assembly._callbacks
    assert np.max(np.abs(np.asarray(g(x, parameters)).ravel() - g_mx)) < 1e-13
    J = np.asarray(ca.DM(jac_g(x, parameters)[1]))
    assert J.shape == J_mx.shape and np.max(np.abs(J - J_mx)) < 1e-12
    lam = rng.standard_normal(order.size)
    lam_mx = np.empty_like(lam)
    lam_mx[order] = lam * unit
    H = np.asarray(ca.DM(hess_lag(x, parameters, 1.0, lam)))
    H_mx = np.asarray(ca.DM(mx.solver.get_function("nlp_hess_l")(x, parameters, 1.0, lam_mx)))
    assert np.max(np.abs(H_mx)) > 0.1
    assert np.max(np.abs(H - H_mx)) < 1e-12


def test_both_ipopt_builds_return_the_same_nodes(monkeypatch):
    system = load_scene("pendulum").system
    solved = {}
    for build in ("mx", "assembly"):
        monkeypatch.setattr(bvp_phase, "IPOPT_BUILD", build)
        solved[build] = solve_bvp(system, [0.5], [-0.036], t0=0.0, t_end=9.0, nodes=181,
                                  solver="ipopt")
        assert solved[build].success, solved[build].message
    for key in ("t", "q", "p"):
        assert np.max(np.abs(getattr(solved["mx"], key) - getattr(solved["assembly"], key))) \
            < 1e-10, key


def test_assembly_ipopt_iterations_stay_few_and_repeat_at_twenty_thousand_nodes():
    """Bounded iteration counts (never time), the same in two runs: measured 5 + 1 + 5 here,
    ending Solve_Succeeded (not "acceptable")."""
    system = load_scene("pendulum").system
    runs = [solve_bvp(system, [0.5], [-0.036], t0=0.0, t_end=9.0, nodes=20_000,
                      solver="ipopt") for _ in range(2)]
    assert all(r.success for r in runs), runs[0].message
    counts = [[ph["iterations"] for ph in r.stats["phases"]] for r in runs]
    assert counts[0] == counts[1]
    assert counts[0][-1] <= 6 and max(counts[0]) <= 8, counts
    assert runs[0].stats["return_status"] == "Solve_Succeeded"
