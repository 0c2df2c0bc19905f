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
``energy_expression``). `GridAssembly` evaluates them by blocks: block ``k`` is the ``m``
rows of interval ``k`` (canonical rows, time row of node ``k + 1``), one CasADi function of
``z_k, z_{k+1}`` (and ``z_{k+2}`` for an energy rule) returning the block's residual and its
Jacobian already laid out as band rows (`_band_rows`). The function is mapped over windows
of ``WINDOW`` blocks, compiled once by ``compiler.py`` (the march's build and cache; CasADi's
virtual machine without a compiler), and evaluated through ``Function.buffer`` on numpy memory:
the residual lands in ``F`` itself, the band rows in a band store kept by the assembly, by one
strided assignment per window (the band row of an entry does not depend on ``k``: rows and
columns both advance by ``m`` per block). No expression grows with ``N``.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ...cache import cached
from ...discrete import equations
from ...discrete.scheme import Scheme
from ..grid.maps import window_map
from ..grid.problem import parameter_blocks
from ..options import Compilation


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
    all ``N`` for ``fixed``), parameters and the energy rows' scale; ``energy``: the prescribed
    energy of a transfer whose end time is free (``at_energy.py``), the value the last block of
    a `GridAssembly` built with ``last=`` takes instead of ``t_end``."""

    q_start: np.ndarray
    q_end: np.ndarray
    times: np.ndarray
    theta: np.ndarray
    energy_scale: float
    energy: float | None = None


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


def _band_rows(J, n: int) -> ca.SX:
    """The ``m`` rows of ``J`` (their Jacobian in the block's columns ``0 .. J.size2()-1``) as
    band rows: a dense ``(2w + 1) x m`` matrix whose column ``a`` holds row ``a``'s entries at
    block columns ``c = n + 1 + a - w + e``, ``e = 0 .. 2w`` (zero outside the block), so that
    each band row is one diagonal-centred window of the grid's row (``GridAssembly._band_view``).
    """
    m, w = 2 * n + 1, 3 * n + 1
    out = ca.SX(2 * w + 1, m)
    for a in range(m):
        for e in range(2 * w + 1):
            c = n + 1 + a - w + e
            if 0 <= c < J.size2():
                out[e, a] = J[a, c]
    return ca.densify(out)


def _block_functions(system, scheme: Scheme):
    """The per-block functions of the grid: block ``k`` is the ``m`` rows after the pins of
    ``t_0, q_0``, shifted by ``k m``: the canonical equations of interval ``k`` and the time row
    of node ``k + 1``. Two kinds, each as ``(residual and band rows, residual only)``:

    - ``pinned(z_a, z_b, t_given, theta)``: time row ``t_b - t_given`` (every block of ``fixed``;
      the last block, ``t_{N-1} - t_end``, of an energy rule);
    - ``energy(z_prev, z_mid, z_next, (theta, energy_scale))``: time row the energy equation of
      node ``mid`` over ``energy_scale`` (``None`` for ``fixed``).

    The expressions and derivatives are the ones of ``node_expressions`` (``dr/d(z_a, z_b)`` and
    ``de/d(z_prev, z_mid, z_next)``, the energy row's divided by the scale), so that every path
    computes the same numbers; the band rows are `_band_rows`."""
    def build():
        n = system.n
        z, r, e = node_expressions(system, scheme)
        theta = system.theta
        J_r = ca.jacobian(r, ca.vertcat(z[0], z[1]))
        t_given = ca.SX.sym("t_given")
        F = ca.vertcat(r, z[1][0] - t_given)
        J = ca.vertcat(J_r, ca.jacobian(F[2 * n], ca.vertcat(z[0], z[1])))
        inputs = [z[0], z[1], t_given, theta]
        pinned = (ca.Function("bvp_pinned_block", inputs, [F, _band_rows(J, n)]),
                  ca.Function("bvp_pinned_rows", inputs, [F]))
        if e is None:
            return pinned, None
        scale = ca.SX.sym("energy_scale")
        F = ca.vertcat(r, e / scale)
        J = ca.vertcat(ca.horzcat(J_r, ca.SX(2 * n, 2 * n + 1)),
                       ca.jacobian(e, ca.vertcat(*z)) / scale)
        inputs = [z[0], z[1], z[2], ca.vertcat(theta, scale)]
        energy = (ca.Function("bvp_energy_block", inputs, [F, _band_rows(J, n)]),
                  ca.Function("bvp_energy_rows", inputs, [F]))
        return pinned, energy
    return cached(system, ("bvp_blocks", scheme), build)


def prescribed_energy_block(system, scheme: Scheme):
    """The last block of a transfer at a prescribed energy (``at_energy.py``), as the ``last`` of
    `GridAssembly`: ``(block, rows)`` of ``(z_a, z_b, E, theta)``, the canonical
    equations of interval ``N - 2`` and, in the time row of node ``N - 1``, ``H(Q, P) - E`` of
    that interval (``discrete/``'s interval energy; with the energy equations ``H_k =
    H_{k-1}`` of the interior nodes it prescribes every interval's energy), in place of
    ``t_{N-1} - t_end``: ``t_{N-1}`` is an unknown."""
    def build():
        n = system.n
        z, r, _ = node_expressions(system, scheme)
        theta, level = system.theta, ca.SX.sym("E")
        energy = equations.midpoint_energy_function(system, scheme)(
            z[0][0], z[1][0], z[0][1:n + 1], z[0][n + 1:], z[1][1:n + 1], z[1][n + 1:], theta)
        F = ca.vertcat(r, energy - level)
        J = ca.jacobian(F, ca.vertcat(z[0], z[1]))
        inputs = [z[0], z[1], level, theta]
        return (ca.Function("bvp_prescribed_block", inputs, [F, _band_rows(J, n)]),
                ca.Function("bvp_prescribed_rows", inputs, [F]))
    return cached(system, ("bvp_prescribed_block", scheme), build)


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


class BandJacobian:
    """The Jacobian of one evaluation, held in its `GridAssembly`'s band store (LAPACK
    ``gbsv`` storage, overwritten by the next evaluation with ``jacobian=True`` and by an LU
    factorisation in place)."""

    def __init__(self, ab: np.ndarray):
        self.ab = ab


class GridAssembly:
    """Residual ``F(x)`` and Jacobian ``F'(x)`` of one system, scheme and node count (module
    docstring), in LAPACK band storage or as a sparse matrix.

    The Jacobian is written into one band store allocated at the first evaluation and reused:
    each block's band rows (`_band_rows`) go to their places by one strided assignment per
    window (the store has ``w + 1`` spare columns on each side, where the entries of columns
    outside the grid land, always zeros), and the pinned rows' entries by one indexed
    assignment. Every entry of the band (rows ``w .. 3w`` of the storage) is written at each
    evaluation; the ``w`` rows above are LAPACK's fill-in, which ``gbtrf`` clears itself."""

    def __init__(self, system, scheme: Scheme, nodes: int,
                 compilation: Compilation | None = None, last=None):
        """``last``: the last block's functions ``(block, rows)`` of inputs ``(z_a, z_b, value,
        theta)`` in place of the pin ``t_{N-1} - t_end`` (an energy rule's; ``value`` is
        ``Ends.energy``)."""
        compilation = compilation or Compilation()
        self.layout = NodeLayout(system.n, nodes)
        self.scheme = scheme
        pinned, energy = _block_functions(system, scheme)
        self._energy_rule = energy is not None
        self._rows = (pinned[1], energy[1] if energy is not None else None)
        if energy is None:
            self._maps = [window_map(system, ("pinned", j, scheme), f, compilation)
                          for j, f in enumerate(pinned)]
        else:  # blocks 0 .. N-3; block N-2 (pinned to t_end) alone, on the virtual machine
            self._maps = [window_map(system, ("energy", j, scheme), f, compilation)
                          for j, f in enumerate(energy)]
            self._last = last or pinned
            self._last_buffers = [f.buffer() for f in self._last]
        self._action = window_map(system, ("action", scheme), _action_function(system, scheme),
                                  compilation)
        blocks = nodes - 2 if self._energy_rule else nodes - 1
        for mapped in self._maps:
            mapped.prepare(blocks)  # build (or load) the windows now: part of the build time
        self._action.prepare(nodes - 1)
        self._flat = None

    @property
    def path(self) -> str:
        """``"compiled"`` or ``"vm"``: how the Jacobian blocks are evaluated."""
        return self._maps[0].path

    def action(self, x: np.ndarray, theta: np.ndarray) -> float:
        """The discrete action ``S_D = sum_k S_k`` of the grid ``x``."""
        N, m = self.layout.nodes, self.layout.m
        z = np.ascontiguousarray(x, float).reshape(N, m)
        S = np.empty((N - 1, 1))
        self._action([z[:-1], z[1:]], np.ascontiguousarray(theta, float), [S], N - 1)
        return float(np.sum(S))

    def evaluate(self, x: np.ndarray, ends: Ends, jacobian: bool = True):
        """``F(x)`` (``N m``,) and, if asked, the Jacobian (a `BandJacobian`, for
        `banded` and `sparse`; valid until the next evaluation of the Jacobian)."""
        n, N, m = self.layout.n, self.layout.nodes, self.layout.m
        z = np.ascontiguousarray(x, float).reshape(N, m)
        theta = np.ascontiguousarray(ends.theta, float)
        F = np.empty(N * m)
        F[0] = z[0, 0] - ends.times[0]
        F[1:n + 1] = z[0, 1:n + 1] - ends.q_start
        body = F[n + 1:n + 1 + (N - 1) * m].reshape(N - 1, m)
        kind = 0 if jacobian else 1
        sink = self._sink() if jacobian else None
        outputs = [body] if not jacobian else [body, None]
        if not self._energy_rule:
            times = np.ascontiguousarray(ends.times, float)[1:, None]
            self._maps[kind]([z[:-1], z[1:], times], theta, outputs, N - 1, sink)
        else:
            outputs[0] = body[:-1]
            self._maps[kind]([z[:-2], z[1:-1], z[2:]], np.r_[theta, ends.energy_scale],
                               outputs, N - 2, sink)
            self._last_block(z, ends, theta, body, sink)
        F[-n:] = z[-1, 1:n + 1] - ends.q_end
        if not jacobian:
            return F, None
        self._flat[self._pin_index] = self._pin_values
        return F, BandJacobian(self._ab)

    def parameter_jacobian(self, x: np.ndarray, ends: Ends) -> sp.csc_matrix:
        """``dF/dtheta`` (``grid/problem.py``): the blocks' rows differentiated in ``theta``
        (the pins of ``t_0``, ``q_0``, ``q_end`` do not depend on it)."""
        n, N, m = self.layout.n, self.layout.nodes, self.layout.m
        z = np.ascontiguousarray(x, float).reshape(N, m)
        theta = np.ascontiguousarray(ends.theta, float)
        dense = np.zeros((N * m, theta.size))
        if theta.size == 0:
            return sp.csc_matrix(dense)
        body = dense[n + 1:n + 1 + (N - 1) * m].reshape(N - 1, m, theta.size)
        if not self._energy_rule:
            times = np.ascontiguousarray(ends.times, float)[1:, None]
            body[:] = parameter_blocks(self._rows[0], 3, [z[:-1], z[1:], times], theta)
            return sp.csc_matrix(dense)
        body[:-1] = parameter_blocks(self._rows[1], 3, [z[:-2], z[1:-1], z[2:]],
                                     np.r_[theta, ends.energy_scale], theta.size)
        given = ends.times[-1] if ends.energy is None else ends.energy
        body[-1] = parameter_blocks(self._last[1], 3, [z[-2:-1], z[-1:], np.array([[given]])],
                                    theta)[0]
        return sp.csc_matrix(dense)

    def release(self) -> None:
        """Drop the band store (allocated again by the next evaluation of the Jacobian): the
        assembly stays cached between solves (``phases.py``), its store need not."""
        self._flat = self._ab = self._band_view = None

    def _last_block(self, z, ends, theta, body, sink):
        """Block ``N - 2`` of an energy rule: canonical rows and ``t_{N-1} - t_end``."""
        kind = 0 if sink is not None else 1
        buffer, trigger = self._last_buffers[kind]
        given = ends.times[-1] if ends.energy is None else ends.energy
        held = [np.ascontiguousarray(z[-2]), np.ascontiguousarray(z[-1]),
                np.array([float(given)]), theta]
        for j, value in enumerate(held):
            buffer.set_arg(j, memoryview(value))
        row = np.empty(self.layout.m)
        buffer.set_res(0, memoryview(row))
        band = None
        if sink is not None:
            band = np.empty((1, self._last[0].nnz_out(1)))
            buffer.set_res(1, memoryview(band))
        trigger()
        body[-1] = row
        if sink is not None:
            sink(self.layout.nodes - 2, band)

    def _sink(self):
        """The band store (allocated once) and the assignment of a window's band rows."""
        m, w = self.layout.m, self.layout.bandwidth
        if self._flat is None:
            self._allocate()
        view = self._band_view

        def sink(first, values):
            view[first:first + values.shape[0]] = values.reshape(-1, m, 2 * w + 1)
        return sink

    def _allocate(self):
        """The band store ``(3w + 1, N m)`` (Fortran order) inside a flat buffer with ``w + 1``
        spare columns on each side; the strided view of the blocks' band rows; the pinned
        rows' positions."""
        n, N, m, w = self.layout.n, self.layout.nodes, self.layout.m, self.layout.bandwidth
        L, size, spare = 3 * w + 1, N * m, w + 1
        self._flat = np.zeros(L * (size + 2 * spare))
        self._ab = self._flat[spare * L:(spare + size) * L].reshape(size, L).T
        # entry (i, j) of the matrix is at flat position spare L + 2w + i + j (L - 1); block k's
        # band row a, entry e: i = k m + n + 1 + a, j = i - w + e
        first = spare * L + 2 * w + (n + 1) * L - w * (L - 1)
        last = first + (N - 2) * m * L + (m - 1) * L + 2 * w * (L - 1)
        assert 0 <= first and last < self._flat.size, "band store margins too small"
        step = self._flat.itemsize
        self._band_view = np.lib.stride_tricks.as_strided(
            self._flat[first:], shape=(N - 1, m, 2 * w + 1),
            strides=(m * L * step, L * step, (L - 1) * step), writeable=True)
        # t_0, q_0: A[i, i] = 1 (i = 0 .. n); q_{N-1}: A[N m - n + i, (N-1) m + 1 + i] = 1, n
        # columns left of the diagonal
        rows = np.r_[np.arange(n + 1), size - n + np.arange(n)]
        diagonal = np.r_[np.zeros(n + 1, int), np.full(n, -n)]
        i, e = np.meshgrid(rows, np.arange(2 * w + 1), indexing="ij")
        self._pin_index = (spare * L + 2 * w + i * L + (e - w) * (L - 1)).ravel()
        self._pin_values = (e - w == diagonal[:, None]).astype(float).ravel()

    def residuals(self, F: np.ndarray, ends: Ends):
        """The unscaled equations in ``F``: canonical ``(N-1, 2n)``, energy ``(N-2,)`` (empty
        for ``fixed``)."""
        n, N, m = self.layout.n, self.layout.nodes, self.layout.m
        body = F[n + 1:n + 1 + (N - 1) * m].reshape(N - 1, m)
        energy = body[:-1, 2 * n] * ends.energy_scale if self._energy_rule \
            else np.zeros(0)
        return body[:, :2 * n].copy(), energy

    def banded(self, blocks) -> np.ndarray:
        """The Jacobian in LAPACK ``gbsv`` storage: shape ``(3 w + 1, N m)``, Fortran order, with
        ``A[i, j]`` at row ``2 w + i - j`` (``w`` the bandwidth; the top ``w`` rows are LAPACK's
        workspace for the fill-in of pivoting).

        ``blocks`` is what `evaluate` returned (its store itself, no copy), or dense
        blocks ``(interval (N-1, 2m, 2n), node (N-2, 3m) or None)`` in the layout of
        `block_entries` (a new array; ``ends_nlp.py`` builds its pattern from ones)."""
        if isinstance(blocks, BandJacobian):
            return blocks.ab
        N, m = self.layout.nodes, self.layout.m
        w = self.layout.bandwidth
        store = np.zeros((N, m, 3 * w + 1))
        for row, col, value in block_entries(self.layout, blocks):
            # row, col: offsets within the block's window; value: (count,) over the grid
            node, comp = divmod(col, m)
            store[node + row[1]:node + row[1] + value.size, comp, 2 * w + row[0] - col] = value
        return store.reshape(N * m, 3 * w + 1).T

    def sparse(self, blocks) -> sp.csc_matrix:
        """The same Jacobian as a sparse matrix (for wide bands); from a `BandJacobian`,
        its nonzero entries."""
        size = self.layout.size
        if isinstance(blocks, BandJacobian):
            w = self.layout.bandwidth
            band = blocks.ab[w:3 * w + 1]
            j = np.broadcast_to(np.arange(size), band.shape)
            i = j + np.arange(-w, w + 1)[:, None]
            keep = (i >= 0) & (i < size) & (band != 0)
            return sp.csc_matrix((band[keep], (i[keep], j[keep])), (size, size))
        m = self.layout.m
        rows, cols, values = [], [], []
        for row, col, value in block_entries(self.layout, blocks):
            k = np.arange(value.size)
            rows.append(row[0] + (k + row[1]) * m)
            cols.append(col + (k + row[1]) * m)
            values.append(value)
        return sp.csc_matrix((np.concatenate(values), (np.concatenate(rows),
                                                       np.concatenate(cols))), (size, size))


def block_entries(layout: NodeLayout, blocks):
    """Every Jacobian entry as ``((row offset, first node), column offset, values)``: the
    entry is at row ``row offset + k m`` and column ``column offset + k m`` for ``k`` =
    first node, first node + 1, ... (one per value). Offsets are relative to node
    ``first node``'s first row/column, so that ``row offset - column offset`` is the
    entry's diagonal."""
    n, N, m = layout.n, layout.nodes, layout.m
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
