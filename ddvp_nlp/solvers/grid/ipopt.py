"""IPOPT on a grid problem: the one build every family's IPOPT path goes through.

A grid problem is square and its solution isolated, so IPOPT's job is a feasibility problem:
objective ``0``, the problem's rows as equality constraints, the steps
``t_{k+1} - t_k >= tau_floor`` as bounded rows (or pinned values as ``lbx = ubx``, which IPOPT
removes). Any objective would only pull the multipliers away from zero and add its own
curvature to the Hessian of the Lagrangian; minimising the sum of squares of the rows instead
would square the Jacobian's condition number and make a non-zero local minimum (no solution)
look like an answer. With ``f = 0`` IPOPT's steps are Newton steps on the rows, globalised by
its filter line search, with the step bounds kept by the barrier.

`FeasibilityNlp` builds the ``nlpsol`` from the family's rows (an MX or SX expression of
the unknowns and parameters, or functions given as callbacks with their derivatives, as the
fixed-endpoint assembly does) and returns IPOPT's point and verdict as a
`GridResult`. The families say how their rows are made:
``solvers/bvp/ends_nlp.py`` (callbacks on the banded assembly),
``solvers/periodic/orbit_nlp.py`` and ``solvers/higher/window_nlp.py`` (per-interval or
per-window functions mapped over the grid on MX).

Every family's IPOPT works on its unknowns and rows divided by their sizes (``scaled``
`FeasibilityNlp`, `equilibrated_sizes`; the fixed-endpoint callbacks scale their own values the
same way, ``bvp/ends_nlp.end_scales``): the unknowns by the motion's span and ranges, the rows by
what they change by when those move. IPOPT's tolerance is one number for every row, and its
regularisation and line search measure the unknowns and rows in their own norms, so on the raw
rows its iterates depended on the units: in lengths of ``1e-8`` or ``1e6``, or time units of
``1e5``, it failed on fixed ends, constrained fixed ends, higher-order fixed ends and Hill's
Lyapunov orbit, each solved in units of 1; scaled, each is solved in any units, the fixed-end
families in the same iterations (the Lyapunov orbit's IPOPT path changes by a few iterations
under a change of its start in the last digit, in any units; each family's tests of units).

IPOPT's options (measured on the pendulum's fixed-endpoint problem,
``scripts/benchmarks/bench_bvp.py``):
MUMPS with neither permuting scaling nor scaling (MUMPS's analysis phase took 129 of 155 s at
N = 1e5 with its defaults, 3.5 s without); a small initial barrier parameter and bound
multipliers from it, since the start is already close to the solution and the step bounds are
inactive there.
"""

from __future__ import annotations

from types import MappingProxyType

import casadi as ca
import numpy as np
import scipy.sparse as sp

from .newton import column_sizes
from .problem import GridResult

DEFAULT_OPTIONS = MappingProxyType({
    "ipopt.linear_solver": "mumps",
    "ipopt.mumps_pivot_order": 5,  # METIS
    "ipopt.mumps_permuting_scaling": 0,
    "ipopt.mumps_scaling": 0,
    # The start is close and the step bounds inactive at the solution: start the barrier small
    # and the bound multipliers from it. IPOPT's defaults (mu 0.1, multipliers 1) pushed the
    # iterate away first: 7-13 iterations instead of 2-3 at N = 1e4 (measured).
    "ipopt.mu_init": 1e-9, "ipopt.bound_push": 1e-12, "ipopt.bound_frac": 1e-12,
    "ipopt.bound_mult_init_method": "mu-based",
})


def solver_tolerance(tol: float, floor: float = 0.0) -> float:
    """IPOPT's ``tol`` and ``constr_viol_tol`` for a verification at ``tol``: 100 times below
    it, but never below ``floor``, the round-off of the problem's rows as IPOPT sees them, and
    never above ``tol`` itself.

    Below the rows' round-off IPOPT cannot converge, only iterate on noise: the fixed-endpoint
    problem's energy rows divided by the mean step ``h`` carry ``eps |E| / h`` of it, 1e-11 at
    N = 1e6 on the pendulum, and with 1e-12 asked IPOPT took 15 regularised iterations, failed
    line searches and a restoration phase from a start that already passed the verification
    (314 s CPU, 10.5 GB, ended at an acceptable point that failed it; measured)."""
    return min(tol, max(tol * 1e-2, floor))


def ipopt_settings(tol: float, max_iter: int, verbose: bool, time_limit: float | None,
                   options: dict, floor: float = 0.0) -> dict:
    """``nlpsol`` options: IPOPT's tolerances `solver_tolerance` of the verification's
    ``tol`` and the rows' round-off ``floor``, its output if ``verbose``, its wall-time limit,
    then ``options``."""
    inner = solver_tolerance(tol, floor)
    # show_eval_warnings: CasADi's "Inf detected ... oracle_function.cpp" lines only with
    # --verbose; the verdict says what failed in the tool's words
    settings = {"print_time": verbose, "ipopt.print_level": 5 if verbose else 0,
                "show_eval_warnings": verbose,
                "ipopt.sb": "yes", "ipopt.max_iter": max_iter,
                "ipopt.tol": inner, "ipopt.constr_viol_tol": inner, **options}
    if time_limit is not None:
        # IPOPT takes only a positive limit; a deadline already passed stops it at once
        settings["ipopt.max_wall_time"] = max(float(time_limit), 1e-6)
    return settings


class FeasibilityNlp:
    """IPOPT on ``g(x, p) = 0`` (the equality rows) and bounded rows, objective ``0``.

    With ``scaled``, IPOPT works in ``xi = x / d`` on the rows ``g / r``, ``d`` and ``r``
    given to each solve (extra NLP parameters, so one build serves every solve): IPOPT's
    tolerance is one number, and its regularisation and line search measure the unknowns and
    rows in their own norms, so on the raw problem its iterates depend on the units of length,
    momentum and time (Hill's Lyapunov orbit was found in lengths of 1, not in lengths of
    ``1e-8`` or ``1e6``). With ``d`` each unknown's size and ``r`` each row's
    (`equilibrated_sizes`), the scaled problem is the same in any units.

    Args:
        name: the ``nlpsol``'s name.
        x, p, g: the unknowns, the parameters (``None``: none) and the rows, as CasADi
            expressions (MX or SX).
        settings: ``nlpsol`` options (`ipopt_settings`), including any derivative
            callbacks (``jac_g``, ``hess_lag``) the family supplies (not with ``scaled``).
        scaled: solve in scaled unknowns and rows (above).
    """

    def __init__(self, name: str, x, p, g, settings: dict, *, scaled: bool = False):
        self.scaled = scaled
        if scaled:
            rows = ca.Function(f"{name}_rows", [x] + ([p] if p is not None else []), [g])
            d = ca.MX.sym("x_sizes", x.numel())
            r = ca.MX.sym("row_sizes", g.numel())
            xi = ca.MX.sym("xi", x.numel())
            extra = ca.MX.sym("p", p.numel()) if p is not None else None
            g = rows(xi * d, *([extra] if extra is not None else [])) / r
            x, p = xi, ca.vertcat(*([extra] if extra is not None else []), d, r)
        problem = {"x": x, "f": 0, "g": g}
        if p is not None:
            problem["p"] = p
        self.solver = ca.nlpsol(name, "ipopt", problem, settings)
        self._rows = rows if scaled else None
        self._jacobian = None

    def jacobian(self, x0: np.ndarray, p=None):
        """``dg/dx`` of the raw rows at ``x0`` (scipy CSC), for the sizes of a ``scaled``
        problem (`equilibrated_sizes`); the function is built on first use."""
        if self._jacobian is None:
            rows = self._rows
            x = ca.MX.sym("x", rows.size1_in(0))
            extra = [ca.MX.sym("p", rows.size1_in(1))] if rows.n_in() > 1 else []
            self._jacobian = ca.Function("rows_jacobian", [x, *extra],
                                         [ca.jacobian(rows(x, *extra), x)])
        J = self._jacobian(x0, *([] if p is None else [p]))
        J = ca.DM(J) if not isinstance(J, ca.DM) else J
        rows, columns = J.sparsity().get_triplet()
        return sp.csc_matrix((np.asarray(J.nonzeros(), float), (rows, columns)), shape=J.shape)

    def solve(self, x0: np.ndarray, *, lbg, ubg, p=None, lbx=None, ubx=None,
              sizes=None) -> GridResult:
        """IPOPT from ``x0``: its point, ``converged`` its own success flag, ``outcome`` its
        return status (the family's verification comes after). ``sizes = (d, r)``: the
        unknowns' and the rows' sizes of a ``scaled`` problem."""
        if self.scaled:
            d, r = (np.asarray(v, float) for v in sizes)
            x0, lbg, ubg = np.asarray(x0, float) / d, np.asarray(lbg) / r, np.asarray(ubg) / r
            lbx = None if lbx is None else np.asarray(lbx) / d
            ubx = None if ubx is None else np.asarray(ubx) / d
            p = np.concatenate([[] if p is None else np.ravel(p), d, r])
        arguments = {"x0": x0, "lbg": lbg, "ubg": ubg}
        for key, value in (("p", p), ("lbx", lbx), ("ubx", ubx)):
            if value is not None:
                arguments[key] = value
        result = self.solver(**arguments)
        stats = self.solver.stats()
        x = np.asarray(result["x"], float).ravel()
        if self.scaled:
            x = x * d
        return GridResult(x, bool(stats.get("success")), str(stats.get("return_status")),
                          int(stats.get("iter_count", 0)))


def equilibrated_sizes(jacobian, sizes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(d, r)`` of a `FeasibilityNlp` with ``scaled``, from the unknowns' ``sizes`` (the
    motion's: its period, its range in each coordinate; ``nan`` for an unknown without one, an
    unfolding parameter) and the Jacobian at the start (scipy sparse): each row's size
    ``r_i = max_j |J_ij| d_j`` over the sized unknowns (what the row changes by when they move
    by their sizes), then each other unknown's ``d_j = 1 / max_i |J_ij| / r_i`` (the move that
    changes some row by its size). Both carry the units of their rows and unknowns and are
    read off the motion alone, so the scaled problem is the same, to round-off, in any units
    of length, momentum and time (sizes from the rows' round-off, a factor of up to 2 apart
    from one unit system to another by where the numbers fall between powers of 2, gave IPOPT
    another path on Hill's Lyapunov orbit)."""
    A = abs(jacobian.tocsc()).astype(float)
    sizes = np.asarray(sizes, float)
    known = np.isfinite(sizes) & (sizes > 0)
    d = np.where(known, sizes, 0.0)
    r = np.asarray((A @ sp.diags(d)).max(axis=1).todense()).ravel()
    if not np.all(known):
        unsized = np.flatnonzero(~known)
        # a row of unsized unknowns alone: sized by them once they are (below)
        d[unsized] = column_sizes(A[:, unsized], np.where(r > 0, r, np.inf))
        alone = np.flatnonzero(~(r > 0))
        if alone.size:
            r[alone] = np.asarray((A[alone] @ sp.diags(d)).max(axis=1).todense()).ravel()
    return d, np.where(r > 0, r, 1.0)  # 1: a row of no unknown (a constant)


def node_grid_sizes(jacobian, x0: np.ndarray, nodes: int, width: int, sized: int,
                    step_rows: int, sizes=None) -> tuple[np.ndarray, np.ndarray]:
    """`equilibrated_sizes` of a grid whose unknowns are ``nodes`` blocks of ``width`` values
    (then any others, unfolding parameters), the first ``sized`` of each block ``(t, q, p)``
    sized by the span of the times and ``sizes`` (each coordinate's size over the motion,
    `grid.motion_size.motion_sizes`: a coordinate that does not move, an orbit's in an
    invariant plane, is sized by the motion's action, not by the round-off it carries; default
    the coordinates' ranges over ``x0``), the rest (multipliers) by the rows, which see a node
    time move by a mean step (by the span, the rows that hold the times were sized by far
    more than they ever change, and IPOPT failed Duffing's orbit from its linearised start 12
    times in 24 where it fails none); followed by ``step_rows`` rows ``t_{k+1} - t_k`` sized
    by the mean step. ``jacobian``: the rows' Jacobian at ``x0`` (scipy sparse), without the
    step rows."""
    z = np.asarray(x0, float)[:nodes * width].reshape(nodes, width)
    ranges = np.ptp(z, axis=0)
    block = ranges.copy()
    if sizes is not None:
        block[1:1 + np.size(sizes)] = np.asarray(sizes, float)
    block = np.where(block > 0, block, np.nan)
    block[sized:] = np.nan
    mean = ranges[0] / max(nodes - 1, 1)
    local = block.copy()
    local[0] = mean if mean > 0 else np.nan  # what a row sees a node time move by: a step
    tail = np.full(np.size(x0) - nodes * width, np.nan)
    d, r = equilibrated_sizes(jacobian, np.concatenate([np.tile(local, nodes), tail]))
    d[:nodes * width].reshape(nodes, width)[:, 0] = ranges[0] if ranges[0] > 0 else 1.0
    return d, np.concatenate([r, np.full(step_rows, mean if mean > 0 else 1.0)])
