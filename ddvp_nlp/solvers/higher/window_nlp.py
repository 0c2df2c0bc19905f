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

from ..grid.ipopt import FeasibilityNlp, equilibrated_sizes, ipopt_settings
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
                           ubg=np.r_[np.zeros(g_size), np.full(steps, np.inf)],
                           sizes=_sizes(problem, guess, z, l, g_size, steps))
    z[l:N - l, 1:] = result.x[:free * n].reshape(free, n)
    if variable:
        z[l:N - l, 0] = result.x[free * n:]
    return z.ravel(), result.converged, result.outcome, result.iterations


def _sizes(problem: FeasibilityNlp, guess: np.ndarray, z: np.ndarray, l: int,  # noqa: E741
           g_size: int, steps: int):
    """``(d, r)`` of the scaled NLP (`grid.ipopt.equilibrated_sizes`): each free position by
    its coordinate's range over the nodes ``z`` (rows ``(t, q)``), each free time by the
    span, the Euler-Lagrange and energy rows by what they change by when those move by their
    sizes, the step rows by the mean step. On the raw rows IPOPT's one absolute tolerance made
    the solve depend on the units: Pais-Uhlenbeck's fixed-step problem was not verified in
    lengths of ``1e6`` with time units of ``1e-3``, its energy rule failed in lengths of
    ``1e-8``, where units of 1 solved both."""
    N, m = z.shape
    n = m - 1
    free = N - 2 * l
    ranges = np.ptp(z, axis=0)
    known = np.where(ranges > 0, ranges, np.nan)
    sized = np.concatenate([np.tile(known[1:], free), np.full(guess.size - free * n, known[0])])
    jacobian = problem.jacobian(guess)[:g_size, :]
    d, r = equilibrated_sizes(jacobian, sized)
    mean = ranges[0] / max(N - 1, 1)
    return d, np.concatenate([r, np.full(steps, mean if mean > 0 else 1.0)])


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
    return FeasibilityNlp("bvp_higher", unknowns, None, ca.vertcat(*g, steps), settings,
                          scaled=True), free
