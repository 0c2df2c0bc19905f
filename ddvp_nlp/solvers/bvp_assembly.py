"""The fixed-endpoint system of a grid, assembled node by node: residual and banded Jacobian.

Unknowns, interleaved by node: ``x = (z_0, z_1, ..., z_{N-1})`` with ``z_k = (t_k, q_k, p_k)``
(``m = 2n + 1`` values; the fixed values at the ends are unknowns too, pinned by their own
equations). Equations, in the same order, ``N m`` of them::

    t_0 - t_start,  q_0 - q_start                                   (n + 1 rows)
    for k = 0 .. N-2:  canonical equations of interval k           (2n rows)
                       time row of node k+1                        (1 row)
    q_{N-1} - q_end                                                 (n rows)

where the time row of an interior node is its energy equation divided by ``energy_scale`` (the
mean step, so that it is ``O(1)`` in the node times; THEORY.md section 5), for the ``fixed`` rule
``t_k - t_k(given)``, and for node ``N-1`` ``t_{N-1} - t_end``. Row ``r`` depends only on node
values ``z_j`` with ``|r - j m| <= 3n + 1``: the Jacobian is banded with lower and upper
bandwidth ``3n + 1`` (4 for ``n = 1``), whatever ``N``.

The equations are the ones written once in ``discrete/`` (``canonical_expression``,
``energy_expression``); here each becomes a per-interval (per-node) CasADi function returning
its residual and dense Jacobian, mapped over the grid and evaluated through ``Function.buffer``
on numpy memory: no expression grows with ``N``. The Jacobian blocks land in LAPACK's band
storage by one vectorised assignment per block entry (the band row of an entry does not depend
on ``k``: rows and columns both advance by ``m`` per interval).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..cache import cached
from ..discrete import equations
from ..discrete.scheme import Scheme

# Map over the grid with this many threads: the per-interval functions are independent.
THREADS = max(1, min(4, os.cpu_count() or 1))


@dataclass(frozen=True)
class NodeLayout:
    """Where node values and equations sit: node ``k``'s ``(t, q, p)`` at ``x[k m:(k+1) m]``."""

    n: int
    nodes: int

    @property
    def m(self) -> int:
        return 2 * self.n + 1

    @property
    def size(self) -> int:
        return self.nodes * self.m

    @property
    def bandwidth(self) -> int:
        """Lower and upper bandwidth of the Jacobian (module docstring)."""
        return 3 * self.n + 1

    def pack(self, t, q, p) -> np.ndarray:
        """``x`` from node arrays ``t`` (N,), ``q``, ``p`` (N, n)."""
        return np.column_stack([np.asarray(t, float), q, p]).ravel()

    def unpack(self, x):
        """``(t, q, p)`` node arrays (copies) from ``x``."""
        z = np.asarray(x, float).reshape(self.nodes, self.m)
        return z[:, 0].copy(), z[:, 1:self.n + 1].copy(), z[:, self.n + 1:].copy()

    def time_index(self) -> np.ndarray:
        """Positions of ``t_0 .. t_{N-1}`` in ``x``."""
        return np.arange(self.nodes) * self.m


@dataclass
class Ends:
    """The data of one problem: fixed positions, node times (``t_0, t_end`` for an energy rule,
    all ``N`` for ``fixed``), parameters and the energy rows' scale."""

    q_start: np.ndarray
    q_end: np.ndarray
    times: np.ndarray
    theta: np.ndarray
    energy_scale: float


def _block_functions(system, scheme: Scheme):
    """Per-interval ``(r, dr/d(z_a, z_b))`` of the canonical equations and per-node ``(e,
    de/d(z_prev, z_mid, z_next))`` of the energy equation (``None`` for ``fixed``)."""
    def build():
        n = system.n
        z = [ca.SX.sym(f"z{j}", 2 * n + 1) for j in range(3)]
        parts = [(zj[0], zj[1:n + 1], zj[n + 1:]) for zj in z]
        (t0, q0, p0), (t1, q1, p1), (t2, q2, p2) = parts
        theta = system.theta
        r = equations.canonical_expression(system, scheme, t0, t1, q0, p0, q1, p1, theta)
        interval = ca.Function("interval", [z[0], z[1], theta],
                               [r, ca.densify(ca.jacobian(r, ca.vertcat(z[0], z[1])))])
        if not scheme.variable_steps:
            return interval, None
        e = equations.energy_expression(system, scheme, scheme.rule, t0, t1, t2, q0, p0, q1, p1,
                                        q2, p2, theta)
        node = ca.Function("node", [z[0], z[1], z[2], theta],
                           [e, ca.densify(ca.jacobian(e, ca.vertcat(*z)))])
        return interval, node
    return cached(system, ("bvp_blocks", scheme), build)


def _action_function(system, scheme: Scheme) -> ca.Function:
    """``S_k(z_a, z_b, theta)``: the interval action of ``discrete/``."""
    def build():
        n = system.n
        z_a, z_b = ca.SX.sym("z_a", 2 * n + 1), ca.SX.sym("z_b", 2 * n + 1)
        S = equations.interval_action_expression(system, scheme, z_a[0], z_b[0], z_a[1:n + 1],
                                                 z_a[n + 1:], z_b[1:n + 1], z_b[n + 1:],
                                                 system.theta)
        return ca.Function("interval_action", [z_a, z_b, system.theta], [S])
    return cached(system, ("bvp_action", scheme), build)


class _Mapped:
    """A per-block function mapped over ``count`` blocks, evaluated through ``Function.buffer``
    on numpy arrays: its inputs are ``shifts`` node slices of the grid (nodes ``k``, ``k+1``,
    ...) and ``theta`` (shared); output ``j`` is written to ``outputs[j]`` of shape
    ``(count, columns, rows)`` (CasADi's column-major blocks read as C arrays)."""

    def __init__(self, function: ca.Function, count: int, shifts: int):
        # Threads pay off only on long grids (measured: 2x at N = 1e6 on 2 cores).
        parallel = "thread" if THREADS > 1 and count > 10_000 else "serial"
        options = {"max_num_threads": THREADS} if parallel == "thread" else {}
        mapped = function.map(function.name(), parallel, count, [shifts], [], options)
        self.count, self.shifts = count, shifts
        self.buffer, self.evaluate = mapped.buffer()
        self.outputs = [np.zeros((count, function.size2_out(j), function.size1_out(j)))
                        for j in range(function.n_out())]
        for j, out in enumerate(self.outputs):
            self.buffer.set_res(j, memoryview(out))
        self._held = ()

    def __call__(self, z: np.ndarray, theta: np.ndarray) -> list[np.ndarray]:
        """The outputs at the grid ``z`` (``N`` rows of node values); overwritten by the next
        call."""
        # The buffer reads the arrays' memory at evaluation time: hold them until then.
        slices = [np.ascontiguousarray(z[s:s + self.count]) if s else z[:self.count]
                  for s in range(self.shifts)]
        self._held = (*slices, theta)
        for j, part in enumerate(slices):
            self.buffer.set_arg(j, memoryview(part))
        self.buffer.set_arg(self.shifts, memoryview(theta))
        self.evaluate()
        return self.outputs


class GridAssembly:
    """Residual ``F(x)`` and Jacobian ``F'(x)`` of one system, scheme and node count (module
    docstring), in LAPACK band storage or as a sparse matrix."""

    def __init__(self, system, scheme: Scheme, nodes: int):
        self.layout = NodeLayout(system.n, nodes)
        self.scheme = scheme
        interval, node = _block_functions(system, scheme)
        self._interval = _Mapped(interval, nodes - 1, 2)
        self._node = _Mapped(node, nodes - 2, 3) if node is not None else None
        self._system = system
        self._action = None

    def action(self, x: np.ndarray, theta: np.ndarray) -> float:
        """The discrete action ``S_D = sum_k S_k`` of the grid ``x``."""
        if self._action is None:
            self._action = _Mapped(_action_function(self._system, self.scheme),
                                   self.layout.nodes - 1, 2)
        z = np.ascontiguousarray(x, float).reshape(self.layout.nodes, self.layout.m)
        return float(np.sum(self._action(z, np.ascontiguousarray(theta, float))[0]))

    def evaluate(self, x: np.ndarray, ends: Ends, jacobian: bool = True):
        """``F(x)`` (``N m``,) and, if asked, the Jacobian blocks ``(interval, node)``."""
        n, N, m = self.layout.n, self.layout.nodes, self.layout.m
        z = np.ascontiguousarray(x, float).reshape(N, m)
        theta = np.ascontiguousarray(ends.theta, float)
        r, J = (a[:, 0] if a.shape[1] == 1 else a for a in self._interval(z, theta))
        F = np.empty(N * m)
        F[0] = z[0, 0] - ends.times[0]
        F[1:n + 1] = z[0, 1:n + 1] - ends.q_start
        body = F[n + 1:n + 1 + (N - 1) * m].reshape(N - 1, m)
        body[:, :2 * n] = r
        if self._node is not None:
            e, Je = self._node(z, theta)
            body[:-1, 2 * n] = e[:, 0, 0] / ends.energy_scale
            body[-1, 2 * n] = z[-1, 0] - ends.times[-1]
        else:
            body[:, 2 * n] = z[1:, 0] - ends.times[1:]
            Je = None
        F[-n:] = z[-1, 1:n + 1] - ends.q_end
        if not jacobian:
            return F, None
        return F, (J.copy(), None if Je is None else Je[:, :, 0] / ends.energy_scale)

    def residuals(self, F: np.ndarray, ends: Ends):
        """The unscaled equations in ``F``: canonical ``(N-1, 2n)``, energy ``(N-2,)`` (empty
        for ``fixed``)."""
        n, N, m = self.layout.n, self.layout.nodes, self.layout.m
        body = F[n + 1:n + 1 + (N - 1) * m].reshape(N - 1, m)
        energy = body[:-1, 2 * n] * ends.energy_scale if self._node is not None else np.zeros(0)
        return body[:, :2 * n].copy(), energy

    def banded(self, blocks) -> np.ndarray:
        """The Jacobian in LAPACK ``gbsv`` storage: shape ``(3 w + 1, N m)``, Fortran order, with
        ``A[i, j]`` at row ``2 w + i - j`` (``w`` the bandwidth; the top ``w`` rows are LAPACK's
        workspace for the fill-in of pivoting)."""
        N, m = self.layout.nodes, self.layout.m
        w = self.layout.bandwidth
        store = np.zeros((N, m, 3 * w + 1))
        for row, col, value in self._entries(blocks):
            # row, col: offsets within the block's window; value: (count,) over the grid
            node, comp = divmod(col, m)
            store[node + row[1]:node + row[1] + value.size, comp, 2 * w + row[0] - col] = value
        return store.reshape(N * m, 3 * w + 1).T

    def sparse(self, blocks) -> sp.csc_matrix:
        """The same Jacobian as a sparse matrix (for wide bands)."""
        m = self.layout.m
        rows, cols, values = [], [], []
        for row, col, value in self._entries(blocks):
            k = np.arange(value.size)
            rows.append(row[0] + (k + row[1]) * m)
            cols.append(col + (k + row[1]) * m)
            values.append(value)
        size = self.layout.size
        return sp.csc_matrix((np.concatenate(values), (np.concatenate(rows),
                                                       np.concatenate(cols))), (size, size))

    def _entries(self, blocks):
        """Every Jacobian entry as ``((row offset, first node), column offset, values)``: the
        entry is at row ``row offset + k m`` and column ``column offset + k m`` for ``k`` =
        first node, first node + 1, ... (one per value). Offsets are relative to node
        ``first node``'s first row/column, so that ``row offset - column offset`` is the
        entry's diagonal."""
        n, N, m = self.layout.n, self.layout.nodes, self.layout.m
        J, Je = blocks
        one = np.ones(1)
        for i in range(n + 1):  # t_0, q_0 pinned
            yield (i, 0), i, one
        for a in range(2 * n):  # canonical rows of interval k: row (n+1) + k m + a
            for c in range(2 * m):
                yield (n + 1 + a, 0), c, J[:, c, a]
        time_row = n + 1 + 2 * n
        if Je is not None:
            for c in range(3 * m):
                yield (time_row, 0), c, Je[:, c]
            yield (time_row, N - 2), m, one  # t_{N-1} pinned
        else:
            yield (time_row, 0), m, np.ones(N - 1)
        for i in range(n):  # q_{N-1} pinned: row N m - n + i, column (N-1) m + 1 + i
            yield (m - n + i, N - 1), 1 + i, one
