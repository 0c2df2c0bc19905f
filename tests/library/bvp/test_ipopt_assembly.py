"""IPOPT fed by the banded assembly (``solvers/bvp/ends_nlp.py``, through the grid's one IPOPT
build): its functions against CasADi's own derivatives of the same rows, its nodes against
Newton's, few iterations (issue 16)."""

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import GridOptions, Scheme, load_scene, solve_bvp
from ddvp_nlp.cache import PROBLEMS
from ddvp_nlp.solvers.bvp.ends_nlp import BvpIpopt, residual_functions
from ddvp_nlp.solvers.bvp.interleaved import NodeLayout
from ddvp_nlp.solvers.bvp.phases import Boundary, ends, ipopt_scales
from ddvp_nlp.solvers.grid.ipopt import solver_tolerance
from ddvp_nlp.solvers.grid.problem import GridRequest


def _reference_rows(system, scheme: Scheme, nodes: int):
    """The IPOPT rows written as one MX expression of ``x`` and ``p = (theta, energy_scale)``:
    the canonical rows of every interval and the energy rows over the energy scale, in the
    assembly's order (node by node, the node ``N - 1``'s energy row dropped), then the step rows
    ``t_{k+1} - t_k`` in units of the energy scale: what CasADi differentiates for the oracle."""
    m = 2 * system.n + 1
    x = ca.MX.sym("x", nodes * m)
    p = ca.MX.sym("p", system.theta.numel() + 1)
    theta, scale = p[:-1], p[-1]
    Z = ca.reshape(x, m, nodes)
    interval, node = residual_functions(system, scheme)
    canonical = interval.map(nodes - 1)(Z[:, :-1], Z[:, 1:], theta)
    rows = []
    for k in range(nodes - 1):
        rows.append(canonical[:, k])
        if node is not None and k < nodes - 2:
            rows.append(node(Z[:, k], Z[:, k + 1], Z[:, k + 2], theta) / scale)
    if node is not None:
        rows.append(((Z[0, 1:] - Z[0, :-1]) / scale).T)
    return x, p, ca.vertcat(*rows)


@pytest.mark.parametrize("name, rule", [("pendulum", "vddvp"), ("pendulum", "fixed"),
                                        ("kepler", "lee"), ("pendulum_lagrangian", "vddvp"),
                                        ("paper_pendulum", "vddvp")])
def test_callbacks_match_casadis_derivatives_of_the_same_rows(name, rule):
    """g, its Jacobian and the Lagrangian's Hessian of the callbacks equal CasADi's own
    derivatives of the rows written as one MX expression, at a random point, in the columns of
    the values IPOPT varies (``fixed`` pins every node time for the whole build: those columns
    are left out of the patterns, and are zero in the callbacks')."""
    system = load_scene(name).system
    nodes, n = 7, system.n
    problem = BvpIpopt(system, Scheme(rule), nodes, tol=1e-9, max_iter=5)
    x_sym, p_sym, rows = _reference_rows(system, Scheme(rule), nodes)
    rng = np.random.default_rng(3)
    t = np.sort(rng.random(nodes)) + np.arange(nodes)
    x = problem.layout.pack(t, rng.random((nodes, n)) + 1, rng.random((nodes, n)))
    parameters = np.r_[system.parameter_vector(None), 0.7]
    reference = ca.Function("reference", [x_sym, p_sym], [rows, ca.jacobian(rows, x_sym)])
    g_ref, J_ref = (np.asarray(ca.DM(v)) for v in reference(x, parameters))
    g, jac_g, hess_lag = problem._callbacks
    assert np.max(np.abs(np.asarray(g(x, parameters)).ravel() - g_ref.ravel())) < 1e-13
    free = ~problem.nlp.fixed_columns
    assert free.sum() == (nodes * (2 * n + 1) if rule != "fixed" else nodes * 2 * n)
    J = np.asarray(ca.DM(jac_g(x, parameters)[1]))
    assert J.shape == J_ref.shape and np.max(np.abs(J - J_ref)[:, free]) < 1e-12
    assert not np.any(J[:, ~free])
    lam = rng.standard_normal(g_ref.size)
    lam_sym = ca.MX.sym("lam", g_ref.size)
    hessian = ca.Function("hessian", [x_sym, p_sym, lam_sym],
                          [ca.triu(ca.hessian(ca.dot(lam_sym, rows), x_sym)[0])])
    H_ref = np.asarray(ca.DM(hessian(x, parameters, lam)))
    H = np.asarray(ca.DM(hess_lag(x, parameters, 1.0, lam)))
    assert np.max(np.abs(H_ref[np.ix_(free, free)])) > 0.1
    assert np.max(np.abs(H - H_ref)[np.ix_(free, free)]) < 1e-12
    assert not np.any(H[~free]) and not np.any(H[:, ~free])


def test_ipopt_and_newton_return_the_same_nodes():
    """Two solvers of the same rows, both verified, return the same solution (to a few
    hundred round-offs of the rows carried through the problem's condition)."""
    system = load_scene("pendulum").system
    solved = {solver: solve_bvp(system, [0.5], [-0.036], (0.0, 9.0), nodes=181,
                                options=GridOptions(solver=solver))
              for solver in ("ipopt", "newton")}
    for solution in solved.values():
        assert solution.success, solution.message
    assert solved["ipopt"].stats["solver"] == "ipopt"
    for key in ("t", "q", "p"):
        assert np.max(np.abs(getattr(solved["ipopt"], key) - getattr(solved["newton"], key))) \
            < 1e-10, key


@pytest.fixture(scope="module")
def twenty_thousand():
    """The pendulum's swing on 20 000 nodes by IPOPT, solved twice on one system (the second
    from the problems the first left cached): for the repeat test and the skipped-phase test
    (read only)."""
    system = load_scene("pendulum").system
    return system, [solve_bvp(system, [0.5], [-0.036], (0.0, 9.0), nodes=20_000,
                              options=GridOptions(solver="ipopt")) for _ in range(2)]


def test_assembly_ipopt_iterations_stay_few_and_repeat_at_twenty_thousand_nodes(twenty_thousand):
    """Bounded iteration counts (never time), the same in two runs, ending Solve_Succeeded (not
    "acceptable") or not run at all: the start phases' point already passes the verification
    here (5 + 1 + 0, measured)."""
    _, runs = twenty_thousand
    assert all(r.success for r in runs), runs[0].message
    counts = [[ph.iterations for ph in r.ends.stages] for r in runs]
    assert counts[0] == counts[1]
    assert counts[0][-1] <= 6 and max(counts[0]) <= 8, counts
    assert runs[0].stats["return_status"] in ("Solve_Succeeded",
                                              "not run: the start passes the verification")


def test_ipopt_is_not_run_from_a_start_that_passes_the_verification(twenty_thousand):
    """The released phase is skipped when its start already verifies (the point returned is
    that start, verified again by the same rule), run when it does not; the start phases'
    problems are dropped from the cache before the final phase."""
    system, (fine, _) = twenty_thousand
    coarse = solve_bvp(system, [0.5], [-0.036], (0.0, 9.0), nodes=181,
                       options=GridOptions(solver="ipopt"))
    for solution in (coarse, fine):
        assert solution.success, solution.message
        assert all(key[1] == Scheme("vddvp") for key in PROBLEMS.keys(system)
                   if key[0] == "bvp_ipopt")
    assert coarse.ends.stages[-1].iterations > 0
    assert coarse.stats["return_status"] == "Solve_Succeeded"
    assert fine.ends.stages[-1].iterations == 0
    assert fine.ends.energy_residual_max <= fine.ends.energy_limit
    assert "not run: the start passes the verification" in fine.message


def test_ipopt_tolerance_sits_at_the_rows_round_off():
    """IPOPT's tolerance is 1e-2 tol, raised to the round-off of its rows and never above tol.
    IPOPT sees the rows divided by their sizes (`phases.ipopt_scales`), so the round-off it is
    held to is relative: a few eps, whatever the number of nodes (the energy rows divided by
    the mean step carry a few ``eps |E| / h``, and so do their sizes) and whatever the energy
    (read off the rows, `row_round_offs`)."""
    assert solver_tolerance(1e-10) == pytest.approx(1e-12)
    assert solver_tolerance(1e-10, 3e-11) == pytest.approx(3e-11)
    assert solver_tolerance(1e-10, 5e-10) == pytest.approx(1e-10)
    system = load_scene("pendulum").system
    floors = {}
    for nodes, level in ((1_000, 1.0), (10_000, 1.0), (10_000, 1e3)):
        request = GridRequest(system, Scheme("vddvp"), nodes, system.parameter_vector(None),
                              Boundary(np.array([0.5]), np.array([-0.036]), 0.0, 9.0,
                                       np.linspace(0.0, 9.0, nodes)),
                              GridOptions(tol=1e-9).resolved(max_iter=5))
        layout = NodeLayout(1, nodes)
        t = np.linspace(0.0, 9.0, nodes)
        # a swing whose interval energies are about ``level``
        q = 0.5 * np.sin(t)[:, None]
        x = layout.pack(t, q, np.sqrt(2 * level) * np.cos(t)[:, None])
        data = ends(request, request.scheme)
        scales, floors[nodes, level] = ipopt_scales(request, x, request.scheme, data)
        assert np.all(np.isfinite(scales.unknowns) & (scales.unknowns > 0))
        eps = np.finfo(float).eps
        assert eps <= floors[nodes, level] <= 32 * eps  # 3.6-4.0 eps measured
    assert floors[10_000, 1.0] / floors[1_000, 1.0] == pytest.approx(1.0, rel=0.5)
    assert floors[10_000, 1e3] / floors[10_000, 1.0] == pytest.approx(1.0, rel=0.5)


@pytest.mark.parametrize("nodes", [6, 40])
def test_the_scales_of_each_kind_of_row_are_read_off_the_band_as_off_the_matrix(nodes):
    """`end_scales` reads each kind of row's size off the band's table by kinds (the interior
    nodes at once, the first and last few with the pins' rows masked); the same sizes as a
    pass over the Jacobian's body rows: ``max_i |J_ij| d_j`` over the rows of each kind. (A
    loop variable had shadowed the first body row, and the first nodes' mask dropped the first
    interval's rows where the interior was read in chunks.)"""
    from ddvp_nlp.solvers.bvp.ends_nlp import end_scales, row_kinds  # noqa: F401
    from ddvp_nlp.solvers.bvp.phases import assembly

    system = load_scene("pendulum").system
    request = GridRequest(system, Scheme("vddvp"), nodes, system.parameter_vector(None),
                          Boundary(np.array([0.5]), np.array([-0.036]), 0.0, 9.0,
                                   np.linspace(0.0, 9.0, nodes)),
                          GridOptions(tol=1e-9).resolved(max_iter=5))
    t = np.linspace(0.0, 9.0, nodes)
    # the largest entries in the first interval's rows, which the first nodes' mask must keep
    p = 0.5 * np.cos(t) + 5.0 * np.exp(-5.0 * t)
    x = NodeLayout(1, nodes).pack(t, 0.5 * np.sin(t)[:, None], p[:, None])
    data = ends(request, request.scheme)
    grid = assembly(request, request.scheme)
    _, blocks = grid.evaluate(x, data, jacobian=True)
    sizes = np.array([9.0, 1.0, 1.0])
    scales = end_scales(grid.layout, grid.banded(blocks), sizes, data.energy_scale)
    J = abs(grid.sparse(blocks)).toarray()
    m, n = 3, 1
    body = np.arange(n + 1, n + 1 + (nodes - 1) * m - 1)  # the last energy row is a pin
    weighted = J[body] * np.tile(sizes, nodes)[None, :]
    expected = [np.max(weighted[(body - n - 1) % m == k]) for k in range(m)]
    np.testing.assert_allclose(scales.rows, expected, rtol=1e-15)
    grid.release()
