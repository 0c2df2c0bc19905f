"""IPOPT on the periodic system of ``closed_grid.py``: the same unknowns, the same rows.

The NLP: unknowns ``x`` in the layout of `ClosedLayout` (node
states and times interleaved, then the unfolding parameters ``lambda, mu_1 .. mu_r``), so a
point found here goes through the verification of ``orbit.py`` exactly as Newton's does.
Constraints, all equalities but the last group::

    t_0 = 0,  z_0[section] = value,  g_i . (z_0 - z_0^ref) = 0       (2 + r rows)
    the m rows of every interval (assembly.interval_rows)   (N m rows)
    z_N - z_0 - shift = 0                                            (2n rows)
    t_{k+1} - t_k >= tau_floor                                       (N rows)

Objective: ``0`` (``grid/ipopt.py``). The equality constraints are as many as the unknowns and
their solution is isolated (that is what the unfolding parameters are for), so IPOPT's job is a
feasibility problem; any objective would only pull its multipliers away from zero and add its own
curvature to the Hessian of the Lagrangian, and minimising the sum of squares of the rows
instead would square the Jacobian's condition number and make a non-zero local minimum (no
orbit) look like an answer. With ``f = 0`` IPOPT's steps are Newton steps on the rows,
globalised by its filter line search, with the step bounds kept by the barrier.

The interval rows are one CasADi function (SX) mapped over the grid on MX: the constraint
Jacobian and the exact Hessian of the Lagrangian are maps of per-interval derivatives. The
problem's data (parameters, energy, section value, the integrals' reference node and
generators, the closure shift) are NLP parameters, so one built problem serves a whole family.
The build is the grid's one IPOPT build (``grid/ipopt.py``), with its options
(``DEFAULT_OPTIONS``: the start is close and the step bounds inactive at the orbit).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ...cache import PROBLEMS
from ..grid.ipopt import DEFAULT_OPTIONS, FeasibilityNlp, ipopt_settings, node_grid_sizes
from ..grid.problem import GridResult
from .closed_grid import ClosedLayout, Closure, interval_rows


class PeriodicIpopt:
    """The NLP of one system, scheme, interval count, set of integrals and section
    coordinate; `solve` takes the data of one orbit (a `Closure`)."""

    def __init__(self, system, scheme, intervals: int, integrals, section_index: int, *,
                 tol: float, max_iter: int, verbose: bool = False,
                 time_limit: float | None = None):
        integrals = tuple(integrals)
        self.layout = layout = ClosedLayout(system.n, intervals, len(integrals))
        N, m, n, r = intervals, layout.m, system.n, len(integrals)
        x = ca.MX.sym("x", layout.size)
        theta = ca.MX.sym("theta", system.theta.numel())
        energy, value = ca.MX.sym("E"), ca.MX.sym("value")
        reference, shift = ca.MX.sym("reference", 2 * n), ca.MX.sym("shift", 2 * n)
        generators = ca.MX.sym("generators", r, 2 * n)
        metric = ca.MX.sym("metric", 2 * n)
        Z = ca.reshape(x[:(N + 1) * m], m, N + 1)
        u = x[(N + 1) * m:]
        rows = interval_rows(system, scheme, integrals).map(N)(
            Z[:, :-1], Z[:, 1:], ca.repmat(u, 1, N), energy, ca.repmat(metric, 1, N), theta)
        g = ca.vertcat(Z[0, 0], Z[section_index, 0] - value,
                       ca.mtimes(generators, Z[1:, 0] - reference), ca.vec(rows),
                       Z[1:, N] - Z[1:, 0] - shift, ca.vec(Z[0, 1:] - Z[0, :-1]))
        self.equalities = 2 + r + N * m + 2 * n
        self.steps = N
        settings = ipopt_settings(tol, max_iter, verbose, time_limit,
                                  {"ipopt.hessian_approximation": "exact", **DEFAULT_OPTIONS})
        parameters = ca.vertcat(theta, energy, value, reference, shift, ca.vec(generators),
                                metric)
        self.problem = FeasibilityNlp("periodic", x, parameters, g, settings, scaled=True)

    def solve(self, x0: np.ndarray, closure: Closure, tau_floor: float,
              sizes: tuple[np.ndarray, np.ndarray]) -> GridResult:
        """IPOPT from ``x0`` (``converged`` is IPOPT's own success, the verification of
        ``orbit.py`` comes after), in unknowns and rows scaled by their ``sizes``
        (`scaled_sizes`)."""
        n = self.layout.n
        shift = np.broadcast_to(np.asarray(closure.shift, float), (2 * n,))
        reference = closure.reference if closure.reference.size else np.zeros(2 * n)
        parameters = np.concatenate([closure.theta, [closure.energy, closure.section_value],
                                     reference, shift, np.ravel(closure.generators, "F"),
                                     closure.unfolding_metric(n)])
        lbg = np.concatenate([np.zeros(self.equalities), np.full(self.steps, tau_floor)])
        ubg = np.concatenate([np.zeros(self.equalities), np.full(self.steps, np.inf)])
        result = self.problem.solve(x0, p=parameters, lbg=lbg, ubg=ubg, sizes=sizes)
        result.outcome = f"ipopt: {result.outcome} after {result.iterations} iterations"
        return result


def scaled_sizes(layout, jacobian, x0: np.ndarray, sizes: np.ndarray):
    """``(d, r)``: the sizes of the NLP's unknowns and rows (`grid.ipopt.node_grid_sizes`)
    from the assembly's ``jacobian`` at ``x0`` (scipy sparse) and the orbit's ``sizes``
    (``(2n,)``, `grid.motion_size.orbit_sizes`): each node's time by the period, its ``q`` and
    ``p`` by ``sizes``, the unfolding by the rows; the step rows by the mean step."""
    return node_grid_sizes(jacobian, x0, layout.intervals + 1, layout.m, layout.m,
                           layout.intervals, sizes)


def periodic_ipopt(system, scheme, intervals: int, integrals, section_index: int, *,
                   tol: float, max_iter: int, verbose: bool = False,
                   time_limit: float | None = None) -> PeriodicIpopt:
    """The built problem, kept in ``cache.PROBLEMS`` (a family reuses it; a time limit is an
    option of the build, so a limited solve builds its own)."""
    key = ("periodic_ipopt", scheme, intervals, tuple(integrals), section_index, tol,
           max_iter, verbose, time_limit)
    return PROBLEMS.get(system, key, lambda: PeriodicIpopt(
        system, scheme, intervals, integrals, section_index, tol=tol, max_iter=max_iter,
        verbose=verbose, time_limit=time_limit))
