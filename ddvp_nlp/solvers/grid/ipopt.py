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

    Args:
        name: the ``nlpsol``'s name.
        x, p, g: the unknowns, the parameters (``None``: none) and the rows, as CasADi
            expressions (MX or SX).
        settings: ``nlpsol`` options (`ipopt_settings`), including any derivative
            callbacks (``jac_g``, ``hess_lag``) the family supplies.
    """

    def __init__(self, name: str, x, p, g, settings: dict):
        problem = {"x": x, "f": 0, "g": g}
        if p is not None:
            problem["p"] = p
        self.solver = ca.nlpsol(name, "ipopt", problem, settings)

    def solve(self, x0: np.ndarray, *, lbg, ubg, p=None, lbx=None, ubx=None) -> GridResult:
        """IPOPT from ``x0``: its point, ``converged`` its own success flag, ``outcome`` its
        return status (the family's verification comes after)."""
        arguments = {"x0": x0, "lbg": lbg, "ubg": ubg}
        for key, value in (("p", p), ("lbx", lbx), ("ubx", ubx)):
            if value is not None:
                arguments[key] = value
        result = self.solver(**arguments)
        stats = self.solver.stats()
        return GridResult(np.asarray(result["x"], float).ravel(), bool(stats.get("success")),
                          str(stats.get("return_status")), int(stats.get("iter_count", 0)))
