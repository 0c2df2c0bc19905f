"""The fixed-endpoint system of a constrained system (``g(q, t) = 0``, ``m`` rows) on one grid:
the equations of ``discrete/constrained.py`` (RATTLE's form, written once there) over every
interval, with the node multipliers as unknowns.

Unknowns, by node: ``w_k = (t_k, q_k, p_k, lambda_k, mu_k)``, ``M = 1 + 2n + 2m`` values; the
multipliers of node ``k`` are those of interval ``k`` (``k = 0 .. N-2``), the last node's are
unused and pinned to zero. Rows, ``N M`` of them (a square system):

- ``t_0 - t_start``, ``q_0 - q_start`` and the hidden constraint at node 0 (``1 + n + m``);
- per interval ``k``: its ``2n`` equations and the hidden constraint at node ``k + 1`` (``m``);
- ``g(q_k, t_k)`` at the interior nodes (``m`` each; at the ends ``q`` is pinned on ``g = 0``);
- the time rows: an energy rule's row at each interior node divided by the mean step (as the
  unconstrained grid's, ``interleaved.py``) and ``t_{N-1} - t_end``; for ``fixed`` steps
  ``t_k - t_k(given)``;
- ``q_{N-1} - q_end`` and the unused last multipliers.

Count: the interval's ``2n + 2m`` rows fix ``(q_{k+1}, p_{k+1}, lambda_k, mu_k)`` as in the march
(``g`` at the pinned last node holds by the pin, its row is ``q_{N-1} - q_end``'s); the hidden
constraint at node 0 takes the ``m`` directions of ``p_0`` it fixes, and ``q_end`` the rest.

`ConstrainedGrid` evaluates the rows and their sparse Jacobian from one MX graph of per-interval
SX functions mapped over the grid (CasADi's own sparsity; no expression grows with ``N``): a
`grid.GridProblem` whose Jacobian goes to the sparse LU (its rows are grouped, not interleaved,
so its ``bandwidth`` is its size). `ConstrainedIpopt` gives IPOPT the same rows without the pinned
ones (the pins as ``lbx = ubx``) and ``t_{k+1} - t_k >= tau_floor``.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ...cache import cached
from ...discrete.constrained import (
    energy_expression,
    interval_expression,
    interval_momenta,
    node_expression,
)
from ...discrete.equations import action_for
from ...discrete.scheme import Scheme
from ..grid.ipopt import DEFAULT_OPTIONS, FeasibilityNlp, ipopt_settings, node_grid_sizes
from ..grid.motion_size import energy_rate, motion_sizes
from ..grid.problem import GridResult


@dataclass(frozen=True)
class ConstrainedLayout:
    """Where node values sit: node ``k``'s ``(t, q, p, lambda, mu)`` at ``x[k M:(k+1) M]``."""

    n: int
    m: int
    nodes: int

    @property
    def width(self) -> int:
        return 1 + 2 * self.n + 2 * self.m

    @property
    def size(self) -> int:
        return self.nodes * self.width

    @property
    def bandwidth(self) -> int:
        return self.size  # grouped rows: the sparse LU

    def time_index(self) -> np.ndarray:
        return np.arange(self.nodes) * self.width

    def pack(self, t, q, p, multipliers) -> np.ndarray:
        """``x`` from ``t`` (N,), ``q``, ``p`` (N, n) and the multipliers (N-1, 2m)."""
        last = np.zeros((1, 2 * self.m))
        return np.column_stack([np.asarray(t, float), q, p,
                                np.vstack([np.asarray(multipliers, float), last])]).ravel()

    def unpack(self, x):
        """``(t, q, p, multipliers)``: node arrays and the (N-1, 2m) multipliers (copies)."""
        n = self.n
        w = np.asarray(x, float).reshape(self.nodes, self.width)
        return (w[:, 0].copy(), w[:, 1:n + 1].copy(), w[:, n + 1:2 * n + 1].copy(),
                w[:-1, 2 * n + 1:].copy())


@dataclass
class ConstrainedData:
    """The data of one problem: end positions, node times (``t_0, t_end`` for an energy rule,
    all ``N`` for ``fixed``), parameters and the energy rows' scale (the mean step)."""

    q_start: np.ndarray
    q_end: np.ndarray
    times: np.ndarray
    theta: np.ndarray
    energy_scale: float

    def vector(self, nodes: int) -> np.ndarray:
        times = self.times if self.times.size == nodes else \
            np.linspace(self.times[0], self.times[-1], nodes)
        return np.concatenate([self.theta, self.q_start, self.q_end, [self.energy_scale],
                               times])


def block_functions(system, scheme: Scheme):
    """``(interval, energy, node)``: the rows of one interval ``w_a -> w_b`` (its ``2n``
    equations, the hidden constraint and ``g`` at ``b``), the energy row at the middle of
    ``w_a, w_b, w_c`` (``None`` for ``fixed``) and a node's ``(g, hidden)``, from
    ``discrete/constrained.py``."""
    def build():
        n, m, theta = system.n, system.n_constraints, system.theta
        w = [ca.SX.sym(f"w{j}", 1 + 2 * n + 2 * m) for j in range(3)]
        t, q, p = ([wj[0] for wj in w], [wj[1:n + 1] for wj in w],
                   [wj[n + 1:2 * n + 1] for wj in w])
        lam = [wj[2 * n + 1:2 * n + 1 + m] for wj in w]
        mu = [wj[2 * n + 1 + m:] for wj in w]
        rows = interval_expression(system, scheme, t[0], t[1], q[0], p[0], q[1], p[1], lam[0],
                                   mu[0], theta)
        at_b = node_expression(system, q[1], p[1], t[1], theta)
        interval = ca.Function("constrained_interval", [w[0], w[1], theta],
                               [ca.vertcat(rows, at_b[m:], at_b[:m])])
        node = ca.Function("constrained_node", [w[0], theta],
                           [node_expression(system, q[0], p[0], t[0], theta)])
        if not scheme.variable_steps:
            return interval, None, node
        e = energy_expression(system, scheme, scheme.rule,
                              (*t, q[0], p[0], q[1], p[1], q[2], p[2]),
                              (lam[0], mu[0], lam[1], mu[1]), theta)
        return interval, ca.Function("constrained_energy", [*w, theta], [e]), node
    return cached(system, ("constrained_bvp_blocks", scheme), build)


def action_function(system, scheme: Scheme) -> ca.Function:
    """``S_k(w_a, w_b)``: the interval's action with its own momenta (the augmented action's
    multiplier terms vanish on ``g = 0``)."""
    def build():
        n, m, theta = system.n, system.n_constraints, system.theta
        w = [ca.SX.sym(f"w{j}", 1 + 2 * n + 2 * m) for j in range(2)]
        t_a, q_a, p_a = w[0][0], w[0][1:n + 1], w[0][n + 1:2 * n + 1]
        t_b, q_b, p_b = w[1][0], w[1][1:n + 1], w[1][n + 1:2 * n + 1]
        lam, mu = w[0][2 * n + 1:2 * n + 1 + m], w[0][2 * n + 1 + m:]
        plus, minus = interval_momenta(system, t_a, t_b, q_a, p_a, q_b, p_b, lam, mu, theta)
        S = action_for(system, scheme).action(t_a, t_b, q_a, plus, q_b, minus, theta)
        return ca.Function("constrained_action", [w[0], w[1], theta], [S])
    return cached(system, ("constrained_bvp_action", scheme), build)


def _rows(system, scheme: Scheme, layout: ConstrainedLayout, x, P):
    """The rows (module docstring) as an MX column and the slices of its groups."""
    n, m, N, M = layout.n, layout.m, layout.nodes, layout.width
    interval, energy, node = block_functions(system, scheme)
    k = system.theta.numel()
    theta, q_start, q_end = P[:k], P[k:k + n], P[k + n:k + 2 * n]
    scale, times = P[k + 2 * n], P[k + 2 * n + 1:]
    W = ca.reshape(x, M, N)
    blocks = interval.map(N - 1)(W[:, :-1], W[:, 1:], theta)
    start = ca.vertcat(W[0, 0] - times[0], W[1:n + 1, 0] - q_start,
                       node(W[:, 0], theta)[m:])
    if scheme.variable_steps:
        time_rows = ca.vertcat(ca.vec(energy.map(N - 2)(W[:, :-2], W[:, 1:-1], W[:, 2:],
                                                        theta)) / scale, W[0, N - 1] - times[-1])
    else:
        time_rows = ca.vec(W[0, 1:]) - times[1:]
    groups = [("start", start), ("intervals", ca.vec(blocks[:2 * n + m, :])),
              ("constraint", ca.vec(blocks[2 * n + m:, :-1])), ("time", time_rows),
              ("end", W[1:n + 1, N - 1] - q_end), ("unused", W[2 * n + 1:, N - 1])]
    slices, at = {}, 0
    for name, rows in groups:
        slices[name] = slice(at, at + rows.numel())
        at += rows.numel()
    return ca.vertcat(*[rows for _, rows in groups]), slices


class ConstrainedGrid:
    """The rows and sparse Jacobian of one system, scheme and node count (module docstring),
    a `grid.GridProblem` (sparse LU) whose data is a `ConstrainedData`."""

    def __init__(self, system, scheme: Scheme, nodes: int):
        self.system, self.scheme = system, scheme
        self.layout = ConstrainedLayout(system.n, system.n_constraints, nodes)
        x = ca.MX.sym("x", self.layout.size)
        P = ca.MX.sym("P", system.theta.numel() + 2 * system.n + 1 + nodes)
        F, self.slices = _rows(system, scheme, self.layout, x, P)
        self.x, self.P, self.F = x, P, F
        self._F = ca.Function("constrained_rows", [x, P], [F])
        J = ca.jacobian(F, x)
        self._J = ca.Function("constrained_jacobian", [x, P], [F, J])
        colind, row = J.sparsity().get_ccs()
        self._pattern = (np.asarray(row), np.asarray(colind), J.shape)
        self._dtheta = ca.Function("constrained_rows_theta", [x, P], [
            ca.jacobian(F, P)[:, :system.theta.numel()]])
        assert J.shape[0] == J.shape[1] == self.layout.size, "the constrained grid is square"

    def evaluate(self, x: np.ndarray, data: ConstrainedData, jacobian: bool = True):
        P = data.vector(self.layout.nodes)
        if not jacobian:
            return np.asarray(self._F(x, P), float).ravel(), None
        _, J = self._J(x, P)
        row, colind, shape = self._pattern
        values = np.asarray(J.nonzeros(), float)  # the output's sparsity is J's
        # F from the same function with and without J: the same bits (the grid contract)
        return np.asarray(self._F(x, P), float).ravel(), sp.csc_matrix((values, row, colind),
                                                                      shape=shape)

    def sparse(self, jacobian):
        return jacobian

    def release(self) -> None:
        pass

    def parameter_jacobian(self, x: np.ndarray, data: ConstrainedData):
        """``dF/dtheta`` at ``x``, ``(size, len(theta))``, sparse (the rows' own derivative)."""
        D = self._dtheta(x, data.vector(self.layout.nodes))
        return sp.csc_matrix(D.sparse()) if hasattr(D, "sparse") else sp.csc_matrix(
            np.asarray(D, float))

    def parts(self, x: np.ndarray, data: ConstrainedData) -> dict:
        """The unscaled rows of ``x``: ``interval`` (N-1, 2n), ``g`` and ``hidden`` (N, m) at
        every node, ``energy`` (N-2,) (energy rules; unscaled)."""
        n, m, N = self.layout.n, self.layout.m, self.layout.nodes
        w = np.asarray(x, float).reshape(N, self.layout.width).T
        interval, energy, node = block_functions(self.system, self.scheme)
        blocks = np.asarray(interval.map(N - 1)(w[:, :-1], w[:, 1:], data.theta))
        nodes = np.asarray(node.map(N)(w, data.theta))
        result = {"interval": blocks[:2 * n].T, "g": nodes[:m].T, "hidden": nodes[m:].T,
                  "energy": np.zeros(0)}
        if energy is not None and N >= 3:
            result["energy"] = np.asarray(energy.map(N - 2)(w[:, :-2], w[:, 1:-1], w[:, 2:],
                                                            data.theta)).ravel()
        return result

    def action(self, x: np.ndarray, theta: np.ndarray) -> float:
        """The discrete action ``sum_k S_k`` of ``x`` (`action_function`)."""
        N = self.layout.nodes
        w = np.asarray(x, float).reshape(N, self.layout.width).T
        return float(np.sum(np.asarray(action_function(self.system, self.scheme).map(N - 1)(
            w[:, :-1], w[:, 1:], theta))))

    def pinned(self) -> np.ndarray:
        """Which values are pinned (end times and positions, every time of ``fixed``, the
        unused multipliers): IPOPT's ``lbx = ubx``."""
        n, N, M = self.layout.n, self.layout.nodes, self.layout.width
        mask = np.zeros((N, M), bool)
        mask[0, :n + 1] = mask[-1, :n + 1] = True
        mask[-1, 2 * n + 1:] = True
        if not self.scheme.variable_steps:
            mask[:, 0] = True
        return mask.ravel()

    def pinned_rows(self) -> np.ndarray:
        """The rows that only hold the pins (dropped from IPOPT's ``g``)."""
        s, n = self.slices, self.layout.n
        dropped = np.zeros(self.layout.size, bool)
        dropped[s["start"].start:s["start"].start + n + 1] = True
        dropped[s["end"]] = dropped[s["unused"]] = True
        if self.scheme.variable_steps:
            dropped[s["time"].stop - 1] = True
        else:
            dropped[s["time"]] = True
        return dropped


class ConstrainedIpopt:
    """IPOPT (``grid/ipopt.py``'s one build) on a `ConstrainedGrid`'s rows without the pinned
    ones, the pins as bounds, the steps bounded below by ``tau_floor`` (energy rules), on the
    unknowns and rows divided by their sizes (`sizes`): on the raw rows, with one absolute
    tolerance, the Cartesian pendulum's ``vddvp`` solve ended ``not_verified`` in lengths of
    ``1e-8`` or time units of ``1e5`` and ``solver_failed`` in lengths of ``1e6`` with time
    units of ``1e-3``, where it is solved in units of 1."""

    def __init__(self, grid: ConstrainedGrid, *, tol: float, max_iter: int, verbose: bool,
                 time_limit: float | None):
        self.grid = grid
        self.kept = np.flatnonzero(~grid.pinned_rows())
        rows = [grid.F[self.kept.tolist()]]
        N, M = grid.layout.nodes, grid.layout.width
        if grid.scheme.variable_steps:
            t = grid.x[::M]
            rows.append(t[1:] - t[:N - 1])
        settings = ipopt_settings(tol, max_iter, verbose, time_limit, dict(DEFAULT_OPTIONS))
        self.problem = FeasibilityNlp("constrained_bvp", grid.x, grid.P, ca.vertcat(*rows),
                                      settings, scaled=True)

    def sizes(self, x0: np.ndarray, data) -> tuple[np.ndarray, np.ndarray]:
        """``(d, r)`` (`grid.ipopt.node_grid_sizes`): each node's time by the span, its ``q``
        and ``p`` by their ranges over ``x0``, the multipliers by the rows; the step rows by
        the mean step. The energy rows (divided by the mean step, as Newton sees them) by the
        rate at which the motion trades energy (`grid.motion_size.energy_rate`, what their
        verification is relative to): equilibrated like the others they were sized by a
        position's whole range over one step, 7 times their rate on a rotating Cartesian
        pendulum, and IPOPT stalled on them (200 iterations) where it solves them like this in
        108 (measured)."""
        grid = self.grid
        N, M, n = grid.layout.nodes, grid.layout.width, grid.layout.n
        _, jacobian = grid.evaluate(x0, data, jacobian=True)
        steps = N - 1 if grid.scheme.variable_steps else 0
        z = np.asarray(x0, float).reshape(N, M)
        span = float(np.ptp(z[:, 0]))
        sizes = motion_sizes(grid.system, data.theta, z[:, 0], z[:, 1:1 + 2 * n],
                             span / (2 * np.pi))
        d, r = node_grid_sizes(grid.sparse(jacobian)[self.kept, :], x0, N, M, 1 + 2 * n, steps,
                               sizes)
        if grid.scheme.variable_steps:
            energy = np.zeros(grid.layout.size, bool)
            energy[grid.slices["time"]] = True
            energy[grid.slices["time"].stop - 1] = False  # the end time's pin
            rate = energy_rate(z[:, 0], z[:, 1:1 + 2 * n])
            if rate > 0:
                r[:self.kept.size][energy[self.kept]] = rate
        return d, r

    def solve(self, x0: np.ndarray, data: ConstrainedData, tau_floor: float) -> GridResult:
        grid = self.grid
        pinned = grid.pinned()
        P = data.vector(grid.layout.nodes)
        values, _ = grid.evaluate(x0, data, jacobian=False)
        target = np.array(x0, float)
        # the pinned values as the problem states them (ends, times, zero multipliers)
        target[pinned] = x0[pinned] - values[grid.pinned_rows()][_pin_order(grid)]
        lbx = np.where(pinned, target, -np.inf)
        ubx = np.where(pinned, target, np.inf)
        steps = grid.layout.nodes - 1 if grid.scheme.variable_steps else 0
        lbg = np.r_[np.zeros(self.kept.size), np.full(steps, tau_floor)]
        ubg = np.r_[np.zeros(self.kept.size), np.full(steps, np.inf)]
        x0 = np.clip(x0, lbx, ubx)
        return self.problem.solve(x0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, p=P,
                                  sizes=self.sizes(x0, data))


def _pin_order(grid: ConstrainedGrid) -> np.ndarray:
    """For each pinned value (in ``x``'s order), the position of its row among the pinned
    rows: each pinned row is ``value - given`` of one pinned value."""
    n, N, M = grid.layout.n, grid.layout.nodes, grid.layout.width
    s = grid.slices
    row_of = np.full(N * M, -1)
    start = s["start"].start
    row_of[:n + 1] = start + np.arange(n + 1)
    last = (N - 1) * M
    row_of[last + 1:last + n + 1] = s["end"].start + np.arange(n)
    row_of[last + 2 * n + 1:] = s["unused"].start + np.arange(2 * grid.layout.m)
    if grid.scheme.variable_steps:
        row_of[last] = s["time"].stop - 1
    else:
        row_of[M::M] = s["time"].start + np.arange(N - 1)
        row_of[0] = start
    pinned_rows = np.flatnonzero(grid.pinned_rows())
    position = np.full(N * M, -1)
    position[pinned_rows] = np.arange(pinned_rows.size)
    return position[row_of[grid.pinned()]]
