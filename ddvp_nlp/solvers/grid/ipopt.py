"""IPOPT on the fixed-endpoint system, with the layout of ``bvp_assembly.py``.

This is the MX build, kept for comparison (``bvp_phase.IPOPT_BUILD = "mx"``); the default build
feeds IPOPT the banded assembly through callbacks (``bvp_ipopt_assembly.py``, 4-6 times faster
on the pendulum at N = 1e3..1e5, docs/benchmarks/bench_bvp.md). Both share
:data:`DEFAULT_OPTIONS`, :func:`ipopt_settings` and :func:`pinned_bounds`.

The NLP: unknowns ``x`` interleaved by node, ``z_k = (t_k, q_k, p_k)``; the fixed end values
(``t_0, q_0, t_{N-1}, q_{N-1}``, and for ``fixed`` every ``t_k``) pinned by ``lbx = ubx`` (IPOPT
removes them, ``fixed_variable_treatment = make_parameter``); objective ``0``; constraints,
interval by interval::

    canonical equations of interval k = 0      (2n rows)
    energy equation of node k+1 / energy_scale = 0
    t_{k+1} - t_k >= tau_floor

All of them are per-interval CasADi functions (the equations of ``discrete/``) mapped over the
grid on MX, so the Jacobian and the exact Hessian of the Lagrangian are built by CasADi as maps
of per-interval derivative functions: the build does not grow faster than ``N`` and no SX
expression of the whole grid is formed.

IPOPT's options (measured on the pendulum, ``scripts/bench_bvp.py``): MUMPS with METIS ordering
and neither permuting scaling nor scaling (MUMPS's analysis phase took 129 of 155 s at N = 1e5
with its defaults, 3.5 s without); a small initial barrier parameter and bound multipliers from
it, since the start is already close to the solution and the step bounds inactive there.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ...cache import cached
from ...discrete.scheme import Scheme
from ..bvp.assembly import Ends, NodeLayout, node_expressions


def residual_functions(system, scheme: Scheme):
    """Per-interval canonical equations and per-node energy equation (``None`` for ``fixed``)
    as functions of stacked node vectors ``z = (t, q, p)``."""
    def build():
        z, r, e = node_expressions(system, scheme)
        theta = system.theta
        interval = ca.Function("interval_residual", [z[0], z[1], theta], [r])
        if e is None:
            return interval, None
        return interval, ca.Function("node_residual", [z[0], z[1], z[2], theta], [e])
    return cached(system, ("bvp_residuals", scheme), build)


DEFAULT_OPTIONS = {
    "ipopt.linear_solver": "mumps",
    "ipopt.mumps_pivot_order": 5,  # METIS
    "ipopt.mumps_permuting_scaling": 0,
    "ipopt.mumps_scaling": 0,
    # The start is close and the step bounds inactive at the solution: start the barrier small
    # and the bound multipliers from it. IPOPT's defaults (mu 0.1, multipliers 1) pushed the
    # iterate away first: 7-13 iterations instead of 2-3 at N = 1e4 (measured).
    "ipopt.mu_init": 1e-9, "ipopt.bound_push": 1e-12, "ipopt.bound_frac": 1e-12,
    "ipopt.bound_mult_init_method": "mu-based",
}


def ipopt_settings(tol: float, max_iter: int, verbose: bool, time_limit: float | None,
                   options: dict) -> dict:
    """``nlpsol`` options: IPOPT's tolerances 100 times below the verification's ``tol``, its
    output if ``verbose``, its wall-time limit, then ``options``."""
    settings = {"print_time": verbose, "ipopt.print_level": 5 if verbose else 0,
                "ipopt.sb": "yes", "ipopt.max_iter": max_iter,
                "ipopt.tol": tol * 1e-2, "ipopt.constr_viol_tol": tol * 1e-2, **options}
    if time_limit is not None:
        settings["ipopt.max_wall_time"] = float(time_limit)
    return settings


def pinned_bounds(layout: NodeLayout, scheme: Scheme, ends: Ends):
    """``(lbx, ubx)``: free values unbounded; the end positions, the end times (every time for
    ``fixed``) pinned by ``lbx = ubx``."""
    n, m, N = layout.n, layout.m, layout.nodes
    lbx = np.full((N, m), -np.inf)
    ubx = np.full((N, m), np.inf)
    for bound in (lbx, ubx):
        bound[0, 1:n + 1], bound[-1, 1:n + 1] = ends.q_start, ends.q_end
        if scheme.variable_steps:
            bound[0, 0], bound[-1, 0] = ends.times[0], ends.times[-1]
        else:
            bound[:, 0] = ends.times
    return lbx.ravel(), ubx.ravel()


class IpoptProblem:
    """The NLP of one system, scheme and node count; ``solve`` takes the data of one problem."""

    def __init__(self, system, scheme: Scheme, nodes: int, *, tol: float, max_iter: int,
                 verbose: bool = False, time_limit: float | None = None,
                 options: dict | None = None):
        self.layout = NodeLayout(system.n, nodes)
        self.scheme = scheme
        n, m = system.n, self.layout.m
        x = ca.MX.sym("x", self.layout.size)
        theta = ca.MX.sym("theta", system.theta.numel())
        energy_scale = ca.MX.sym("energy_scale")
        Z = ca.reshape(x, m, nodes)
        interval, node = residual_functions(system, scheme)
        rows = [interval.map(nodes - 1)(Z[:, :-1], Z[:, 1:], theta)]
        if node is not None:
            energy = node.map(nodes - 2)(Z[:, :-2], Z[:, 1:-1], Z[:, 2:], theta) / energy_scale
            rows.append(ca.horzcat(energy, 0))
            rows.append(Z[0, 1:] - Z[0, :-1])
        g = ca.vec(ca.vertcat(*rows))
        # rows per interval: 2n equations, then (energy rules) 1 equation and 1 step bound
        self.kinds = np.tile(np.r_[np.zeros(2 * n), [0, 1] if node is not None else []],
                             nodes - 1)
        if node is not None:
            self.kinds[-2] = -1  # the energy row of the (absent) node N-1: 0 = 0, dropped
            keep = self.kinds >= 0
            g = g[np.flatnonzero(keep).tolist()]
            self.kinds = self.kinds[keep]
        settings = ipopt_settings(tol, max_iter, verbose, time_limit,
                                  {**DEFAULT_OPTIONS, **(options or {})})
        self.solver = ca.nlpsol("bvp", "ipopt", {"x": x, "p": ca.vertcat(theta, energy_scale),
                                                 "f": 0, "g": g}, settings)

    def solve(self, x0: np.ndarray, ends: Ends, tau_floor: float):
        """``(x, converged, return_status, iterations)`` from ``x0``."""
        lbx, ubx = pinned_bounds(self.layout, self.scheme, ends)
        lbg = np.where(self.kinds == 1, tau_floor, 0.0)
        ubg = np.where(self.kinds == 1, np.inf, 0.0)
        result = self.solver(x0=x0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg,
                             p=np.concatenate([ends.theta, [ends.energy_scale]]))
        stats = self.solver.stats()
        return (np.asarray(result["x"]).ravel(), bool(stats.get("success")),
                str(stats.get("return_status")), int(stats.get("iter_count", 0)))
