"""IPOPT on a higher-order fixed-endpoint problem: the grid's one IPOPT build (``grid/ipopt.py``)
on an MX graph of the window gradient mapped over the grid.

Unknowns: the free positions (node by node) then, for an energy rule, their times; constraints:
the Euler-Lagrange rows (scaled as in the verification, ``window_solve.py``), the energy rows
and the steps ``t_{k+1} - t_k >= tau_floor``; objective ``0``. The window gradient
(``assembly.window_functions``) is mapped over the grid and added node by node by ``l + 1``
shifted slices, so that no expression grows with ``N`` (the SX expression of the whole action it
replaces took 7.8 s to build at N = 1e4 of the spline, this 1.9 s, measured); IPOPT's
derivatives are CasADi's of that graph. IPOPT runs with its own defaults for the linear solver
and the barrier (only the tolerances and the iteration limit are set).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..grid.ipopt import FeasibilityNlp, ipopt_settings
from ..grid.problem import GridRequest
from .fixed_nodes import el_scale, order, uniform
from .windows import window_functions


def higher_ipopt(request: GridRequest, rule: str, x0: np.ndarray):
    """``(x, converged, said, iterations)`` of IPOPT from ``x0`` (packed like Newton's)."""
    # a time limit is an option of the build: with one, each solve builds its own
    remaining = request.remaining()
    problem, free = request.built(("higher_ipopt", rule != "fixed", request.nodes,
                                   request.tol, request.max_iter, request.verbose, remaining),
                                  lambda: _problem(request, rule, order(request),
                                                   uniform(request)))
    N, n, l = request.nodes, request.system.n, order(request)  # noqa: E741 (the order)
    z = np.array(x0, float).reshape(N, n + 1)
    inner = z[l:N - l]
    guess = inner[:, 1:].ravel()
    variable = rule != "fixed"
    if variable:
        guess = np.concatenate([guess, inner[:, 0]])
    g_size, steps = free * n + (free if variable else 0), N - 1 if variable else 0
    result = problem.solve(guess, lbg=np.r_[np.zeros(g_size), np.full(steps, request.tau_floor)],
                           ubg=np.r_[np.zeros(g_size), np.full(steps, np.inf)])
    z[l:N - l, 1:] = result.x[:free * n].reshape(free, n)
    if variable:
        z[l:N - l, 0] = result.x[free * n:]
    return z.ravel(), result.converged, result.outcome, result.iterations


def _problem(request: GridRequest, rule: str, l: int, uniform_times):  # noqa: E741 (the order)
    """The NLP (module docstring) and the number of free nodes."""
    n, N = request.system.n, request.nodes
    m, free, K = n + 1, N - 2 * l, N - l
    variable = rule != "fixed"
    data = request.data
    Q = ca.MX.sym("q", n, free)
    T = ca.MX.sym("t", 1, free) if variable else ca.DM(uniform_times[l:N - l]).T
    start = ca.DM(np.column_stack([data.t_start, data.q_start]).T)
    stop = ca.DM(np.column_stack([data.t_stop, data.q_stop]).T)
    Z = ca.horzcat(start, ca.vertcat(T, Q), stop)
    mapped = window_functions(request.system)[2].map(K)
    windows = mapped(*[Z[:, j:j + K] for j in range(l + 1)],
                     ca.repmat(ca.DM(request.theta), 1, K))
    G = 0
    for j in range(l + 1):  # window k's node j is node k + j
        G = G + ca.horzcat(ca.MX(m, j), windows[j * m:(j + 1) * m, :], ca.MX(m, l - j))
    g, unknowns, steps = [ca.vec(G[1:, l:N - l]) * el_scale(request)], ca.vec(Q), ca.MX(0, 1)
    if variable:
        g.append(G[0, l:N - l].T)
        unknowns = ca.vertcat(unknowns, T.T)
        steps = (Z[0, 1:] - Z[0, :-1]).T
    settings = ipopt_settings(request.tol, request.max_iter, request.verbose,
                              request.remaining(), {})
    return FeasibilityNlp("bvp_higher", unknowns, None, ca.vertcat(*g, steps), settings), free
