"""The fixed-endpoint system of a grid, assembled node by node: residual and banded Jacobian.

Unknowns, interleaved by node: ``x = (z_0, z_1, ..., z_{N-1})`` with ``z_k = (t_k, q_k, p_k)``
(``m = 2n + 1`` values; the fixed values at the ends are unknowns too, pinned by their own
equations). Equations, in the same order, ``N m`` of them::

    t_0 - t_start,  q_0 - q_start                                   (n + 1 rows)
    for k = 0 .. N-2:  canonical equations of interval k           (2n rows)
                       time row of node k+1                        (1 row)
    q_{N-1} - q_end                                                 (n rows)

where the time row of an interior node is its energy equation divided by ``energy_scale`` (the mean
step, so that it is ``O(1)`` in the node times; docs/theory.md section 7), for the ``fixed`` rule
``t_k - t_k(given)``, and for node ``N-1`` ``t_{N-1} - t_end``. Row ``r`` depends only on node
values ``z_j`` with ``|r - j m| <= 3n + 1``: the Jacobian is banded with lower and upper bandwidth
``3n + 1`` (4 for ``n = 1``), whatever ``N``.

The equations are the ones written once in ``discrete/`` (``canonical_expression``,
``energy_expression``); here each becomes a per-interval (per-node) CasADi function returning
its residual and dense Jacobian, mapped over the grid and evaluated through ``Function.buffer``
on numpy memory: no expression grows with ``N``. The Jacobian blocks land in LAPACK's band
storage by one vectorised assignment per block entry (the band row of an entry does not depend
on ``k``: rows and columns both advance by ``m`` per interval).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..cache import cached
from ..discrete import equations
from ..discrete.scheme import Scheme

# Threads of each mapped evaluation: 1, since 2 threads were not faster on 2 cores (measured).
THREADS = 1
# Blocks per mapped evaluation (module docstring of ChunkedMap).
CHUNK = 4096


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


def node_expressions(system, scheme: Scheme):
    """``(z, r, e)``: three stacked node vectors ``z_j = (t, q, p)`` (SX symbols), the canonical
    equations ``r`` of the interval ``z_0 -> z_1`` and the energy equation ``e`` of the middle
    node (``None`` for ``fixed``), as written in ``discrete/``; the parameters are
    ``system.theta``. Every per-interval function of the fixed-endpoint solvers starts here."""
    n = system.n
    z = [ca.SX.sym(f"z{j}", 2 * n + 1) for j in range(3)]
    (t0, q0, p0), (t1, q1, p1), (t2, q2, p2) = [(zj[0], zj[1:n + 1], zj[n + 1:]) for zj in z]
    theta = system.theta
    r = equations.canonical_expression(system, scheme, t0, t1, q0, p0, q1, p1, theta)
    e = (equations.energy_expression(system, scheme, scheme.rule, t0, t1, t2, q0, p0, q1, p1,
                                     q2, p2, theta) if scheme.variable_steps else None)
    return z, r, e


def _block_functions(system, scheme: Scheme):
    """Per-interval ``(r, dr/d(z_a, z_b))`` of the canonical equations and per-node ``(e,
    de/d(z_prev, z_mid, z_next))`` of the energy equation (``None`` for ``fixed``)."""
    def build():
        z, r, e = node_expressions(system, scheme)
        theta = system.theta
        interval = ca.Function("interval", [z[0], z[1], theta],
                               [r, ca.densify(ca.jacobian(r, ca.vertcat(z[0], z[1])))])
        if e is None:
            return interval, None
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


def hessian_block_functions(system, scheme: Scheme):
    """The second derivatives IPOPT's Lagrangian needs, block by block: ``(interval, node)``,
    each ``(function, rows, columns)`` or ``None`` (``node`` for ``fixed``).

    ``interval(z_a, z_b, lam, theta)`` returns the structural nonzeros of the upper triangle of
    the Hessian of ``lam . r(z_a, z_b)`` (``lam`` one multiplier per canonical row, ``2n``) in
    the stacked ``(z_a, z_b)`` (``2m`` values), as a column; entry ``i`` sits at ``(rows[i],
    columns[i])`` of that ``2m x 2m`` block. ``node(z_prev, z_mid, z_next, mu, theta)`` does the
    same for ``mu e`` over ``3m`` values. Entries that vanish for every argument are left out,
    so that the output holds only what the grid's Hessian needs.
    """
    def triangle(name, expression, blocks, inputs):
        H = ca.triu(ca.hessian(expression, ca.vertcat(*blocks))[0])
        if H.nnz() == 0:
            return None
        rows, columns = H.sparsity().get_triplet()
        return (ca.Function(name, inputs, [ca.vertcat(*H.nonzeros())]), np.array(rows),
                np.array(columns))

    def build():
        z, r, e = node_expressions(system, scheme)
        theta = system.theta
        lam, mu = ca.SX.sym("lam", 2 * system.n), ca.SX.sym("mu")
        interval = triangle("interval_hessian", ca.dot(lam, r), z[:2], [z[0], z[1], lam, theta])
        if e is None:
            return interval, None
        return interval, triangle("node_hessian", mu * e, z, [*z, mu, theta])
    return cached(system, ("bvp_hessian_blocks", scheme), build)


class ChunkedMap:
    """A per-block function evaluated over ``count`` blocks in windows of ``CHUNK`` blocks, each
    by one mapped call through ``Function.buffer`` on numpy memory.

    A map over the whole grid cost 0.11 s to build at N = 1e5 (its sparsity patterns grow with
    N); a fixed window is built once per function and process. The last window is shifted back
    to end on the last block (it recomputes a few blocks: harmless). Block inputs are arrays of
    shape ``(count, size)``; ``theta`` is shared. Output ``j`` has shape ``(count, columns,
    rows)`` (CasADi's column-major blocks read as C arrays).
    """

    def __init__(self, function: ca.Function):
        self.function = function
        self._maps: dict[int, tuple] = {}

    def _window(self, size: int):
        if size not in self._maps:
            # Threads did not pay off on 2 cores (measured at N = 1e5 and 1e6); the form
            # map(name, "thread", n, reduce_in, ...) aborted on evaluation (CasADi 3.8.2).
            mapped = self.function.map(size, "thread", THREADS) if THREADS > 1 and size > 1 \
                else self.function.map(size)
            self._maps[size] = mapped.buffer()
        return self._maps[size]

    def prepare(self, count: int) -> None:
        self._window(min(CHUNK, count))

    def __call__(self, blocks: list[np.ndarray], theta: np.ndarray, count: int):
        f = self.function
        outputs = [np.empty((count, f.size2_out(j), f.size1_out(j))) for j in range(f.n_out())]
        size = min(CHUNK, count)
        buffer, evaluate = self._window(size)
        shared = np.ascontiguousarray(np.tile(np.asarray(theta, float), size))
        buffer.set_arg(len(blocks), memoryview(shared))
        for first in range(0, count, size):
            first = min(first, count - size)
            held = [np.ascontiguousarray(b[first:first + size]) for b in blocks]
            for j, part in enumerate(held):
                buffer.set_arg(j, memoryview(part))
            for j, out in enumerate(outputs):
                buffer.set_res(j, memoryview(out[first:first + size]))
            evaluate()
        return outputs


def chunked(system, key, function: ca.Function) -> ChunkedMap:
    """The :class:`ChunkedMap` of ``function``, one per system and ``key``."""
    return cached(system, ("chunked", key), lambda: ChunkedMap(function))


class GridAssembly:
    """Residual ``F(x)`` and Jacobian ``F'(x)`` of one system, scheme and node count (module
    docstring), in LAPACK band storage or as a sparse matrix."""

    def __init__(self, system, scheme: Scheme, nodes: int):
        self.layout = NodeLayout(system.n, nodes)
        self.scheme = scheme
        interval, node = _block_functions(system, scheme)
        self._interval = chunked(system, ("bvp_interval", scheme), interval)
        self._node = chunked(system, ("bvp_node", scheme), node) if node is not None else None
        self._action = chunked(system, ("bvp_action", scheme), _action_function(system, scheme))
        for mapped, count in ((self._interval, nodes - 1), (self._node, nodes - 2),
                              (self._action, nodes - 1)):
            if mapped is not None:
                mapped.prepare(count)  # build the window now: it is part of the build time

    def action(self, x: np.ndarray, theta: np.ndarray) -> float:
        """The discrete action ``S_D = sum_k S_k`` of the grid ``x``."""
        N = self.layout.nodes
        z = np.asarray(x, float).reshape(N, self.layout.m)
        return float(np.sum(self._action([z[:-1], z[1:]], theta, N - 1)[0]))

    def evaluate(self, x: np.ndarray, ends: Ends, jacobian: bool = True):
        """``F(x)`` (``N m``,) and, if asked, the Jacobian blocks ``(interval, node)``."""
        n, N, m = self.layout.n, self.layout.nodes, self.layout.m
        z = np.ascontiguousarray(x, float).reshape(N, m)
        theta = np.ascontiguousarray(ends.theta, float)
        r, J = self._interval([z[:-1], z[1:]], theta, N - 1)
        r = r[:, 0]
        F = np.empty(N * m)
        F[0] = z[0, 0] - ends.times[0]
        F[1:n + 1] = z[0, 1:n + 1] - ends.q_start
        body = F[n + 1:n + 1 + (N - 1) * m].reshape(N - 1, m)
        body[:, :2 * n] = r
        if self._node is not None:
            e, Je = self._node([z[:-2], z[1:-1], z[2:]], theta, N - 2)
            body[:-1, 2 * n] = e[:, 0, 0] / ends.energy_scale
            body[-1, 2 * n] = z[-1, 0] - ends.times[-1]
        else:
            body[:, 2 * n] = z[1:, 0] - ends.times[1:]
            Je = None
        F[-n:] = z[-1, 1:n + 1] - ends.q_end
        if not jacobian:
            return F, None
        return F, (J, None if Je is None else Je[:, :, 0] / ends.energy_scale)

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
