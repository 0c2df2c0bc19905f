"""The fixed-endpoint system of a higher-derivative Lagrangian, assembled window by window.

Unknowns, interleaved by node: ``x = (z_0, ..., z_{N-1})`` with ``z_k = (t_k, q_k)`` (``m = n + 1``
values per node). The ``l`` nodes at each end are unknowns too, pinned by their own rows
(``t_k - t_k(given)``, ``q_k - q_k(given)``), so that every step ``t_{k+1} - t_k`` is in ``x``
(Newton's ``tau_floor`` safeguard sees the steps next to the ends). Equations, node by node in
the same order, for a free node ``k``::

    t row:  dS_D/dt_k                    (energy rule: the action's stationarity in t_k)
            t_k - t_k(given)             (fixed steps)
    q rows: dS_D/dq_k * tau_mean^(2l-1)  (Euler-Lagrange, in the units of q)

The discrete action ``S_D = sum_k S_k`` (``discrete/higher_order_action.py``) is a sum of
window terms:
``S_k = tau_k L(q_k, v^(k), t_k)`` depends on the ``l + 1`` nodes ``k .. k + l`` only. One
CasADi function per window returns ``S_k``, its gradient and its dense Hessian in the window's
``W = (l + 1) m`` node values; it is mapped over the ``N - l`` windows (``ChunkedMap`` of
``grid/maps.py``: fixed windows of blocks through ``Function.buffer``), so that no expression
grows with ``N``. The gradient is the windows' gradients added at ``k m + a`` (one
``bincount``); the Jacobian of the equations is the action's Hessian, added the same way, its
rows scaled like the equations, with identity rows for the pins. Its entries lie within
``w = W - 1`` of the diagonal whatever ``N``: LAPACK band storage (``banded``) or a sparse
matrix (``sparse``) are filled by one ``bincount`` each on positions computed once.

The object is a ``grid.problem.GridProblem``, the interface the grid's Newton expects of an
assembly (``layout`` with ``bandwidth`` and ``time_index``, ``evaluate``, ``banded``,
``sparse``, ``release``), so the grid's Newton iteration runs on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ...cache import cached
from ...discrete.higher_order_action import action
from ..grid.maps import chunked
from ..grid.problem import parameter_blocks


@dataclass(frozen=True)
class HigherLayout:
    """Node ``k``'s ``(t_k, q_k)`` at ``x[k m:(k+1) m]``, ``m = n + 1``; ``order`` nodes pinned
    at each end."""

    n: int
    order: int
    nodes: int

    @property
    def m(self) -> int:
        return self.n + 1

    @property
    def size(self) -> int:
        return self.nodes * self.m

    @property
    def windows(self) -> int:
        return self.nodes - self.order

    @property
    def width(self) -> int:
        """Values of one window: its ``order + 1`` nodes."""
        return (self.order + 1) * self.m

    @property
    def bandwidth(self) -> int:
        """Lower and upper bandwidth of the Jacobian (module docstring)."""
        return self.width - 1

    def pack(self, t, q) -> np.ndarray:
        return np.column_stack([np.asarray(t, float), np.asarray(q, float)]).ravel()

    def unpack(self, x):
        """``(t, q)`` node arrays (copies) from ``x``."""
        z = np.asarray(x, float).reshape(self.nodes, self.m)
        return z[:, 0].copy(), z[:, 1:].copy()

    def time_index(self) -> np.ndarray:
        return np.arange(self.nodes) * self.m


@dataclass
class HigherEnds:
    """The data of one problem: ``given`` holds the pinned values at their places in ``x`` (the
    ``l`` end nodes; for fixed steps every node time), ``theta`` the parameters."""

    given: np.ndarray
    theta: np.ndarray


def window_functions(system):
    """``(value, full, gradient)``: ``value(z_0..z_l, theta) -> (S_k, dS_k/dw)``, ``full(...)
    -> (dS_k/dw, d2S_k/dw2)`` and ``gradient(...) -> dS_k/dw`` with ``w = (z_0, ..., z_l)``,
    ``z_j = (t, q)`` (dense outputs)."""
    def build():
        l, n = system.order, system.n  # noqa: E741 (l is the order, as in the paper)
        z = [ca.SX.sym(f"z{j}", n + 1) for j in range(l + 1)]
        S = action(system, [zj[1:] for zj in z], [zj[0] for zj in z], system.theta)
        w = ca.vertcat(*z)
        gradient = ca.gradient(S, w)
        inputs = [*z, system.theta]
        value = ca.Function("window_value", inputs, [S, ca.densify(gradient)])
        full = ca.Function("window_hessian", inputs,
                           [ca.densify(gradient), ca.densify(ca.jacobian(gradient, w))])
        return value, full, ca.Function("window_gradient", inputs, [ca.densify(gradient)])
    return cached(system, ("higher_windows",), build)


class HigherAssembly:
    """Residual ``F(x)`` and Jacobian ``F'(x)`` of one higher-order system, rule (``"fixed"``
    or an energy rule) and node count (module docstring)."""

    def __init__(self, system, rule: str, nodes: int, el_scale: float):
        self.layout = HigherLayout(system.n, system.order, nodes)
        self.variable = rule != "fixed"
        value, full, _ = window_functions(system)
        self._value = chunked(system, ("higher_value",), value)
        self._window_value = value
        self._full = chunked(system, ("higher_hessian",), full)
        for mapped in (self._value, self._full):
            mapped.prepare(self.layout.windows)
        self._rows(el_scale)
        self._pattern()

    # --- rows and patterns, built once ----------------------------------------------------

    def _rows(self, el_scale: float):
        """Which rows are the action's derivatives (``derived``) and their scale."""
        lay = self.layout
        l, m, N = lay.order, lay.m, lay.nodes  # noqa: E741 (l is the order, as in the paper)
        kind = np.zeros((N, m), bool)
        kind[l:N - l, 1:] = True
        if self.variable:
            kind[l:N - l, 0] = True
        self.derived = kind.ravel()
        scale = np.ones((N, m))
        scale[:, 1:] = el_scale
        self.row_scale = np.where(self.derived, scale.ravel(), 0.0)
        self.free_q = np.zeros((N, m), bool)
        self.free_q[l:N - l, 1:] = True
        self.free_q = self.free_q.ravel()
        self.free_t = np.zeros((N, m), bool)
        self.free_t[l:N - l, 0] = True
        self.free_t = self.free_t.ravel()
        base = np.arange(lay.windows)[:, None] * m
        self._gradient_index = (base + np.arange(lay.width)).ravel()

    def _pattern(self):
        """Rows and columns of every Jacobian entry (the kept Hessian entries, then the pins'
        ones) and their positions in CSC data and in LAPACK band storage."""
        lay = self.layout
        K, W, size, w = lay.windows, lay.width, lay.size, lay.bandwidth
        local = np.arange(W)
        base = np.arange(K)[:, None, None] * lay.m
        rows = np.broadcast_to(base + local[:, None], (K, W, W)).ravel()
        columns = np.broadcast_to(base + local[None, :], (K, W, W)).ravel()
        self._kept = np.flatnonzero(self.derived[rows])
        pins = np.flatnonzero(~self.derived)
        rows = np.concatenate([rows[self._kept], pins])
        columns = np.concatenate([columns[self._kept], pins])
        self._kept_scale = self.row_scale[rows[:self._kept.size]]
        self._pin_count = pins.size
        self.rows, self.columns = rows, columns
        key = columns.astype(np.int64) * size + rows
        ordered = np.sort(key)  # np.unique's hash path took 0.3 s on 1e6 keys
        unique = ordered[np.r_[True, np.diff(ordered) != 0]]
        self._csc_position = np.searchsorted(unique, key)
        self._csc_rows = (unique % size).astype(np.int32)
        self._csc_pointer = np.searchsorted(unique // size, np.arange(size + 1)).astype(np.int32)
        self._band_position = (2 * w + rows - columns) + columns.astype(np.int64) * (3 * w + 1)

    # --- evaluation -----------------------------------------------------------------------

    def _blocks(self, x, theta, hessian: bool):
        lay = self.layout
        z = np.ascontiguousarray(x, float).reshape(lay.nodes, lay.m)
        blocks = [z[j:j + lay.windows] for j in range(lay.order + 1)]
        mapped = self._full if hessian else self._value
        return mapped(blocks, np.ascontiguousarray(theta, float), lay.windows)

    def action(self, x, theta) -> float:
        """The discrete action ``S_D`` of the grid ``x``."""
        return float(np.sum(self._blocks(x, theta, False)[0]))

    def gradient(self, x, theta) -> np.ndarray:
        """``dS_D/dx`` (every node value, pinned ones included)."""
        g = self._blocks(x, theta, False)[1]
        return np.bincount(self._gradient_index, weights=g.ravel(), minlength=self.layout.size)

    def evaluate(self, x, ends: HigherEnds, jacobian: bool = True):
        """``F(x)`` and, if asked, the Jacobian's entry values (in the order of ``rows``,
        ``columns``)."""
        x = np.asarray(x, float)
        if jacobian:
            g, H = self._blocks(x, ends.theta, True)
        else:
            g, H = self._blocks(x, ends.theta, False)[1], None
        G = np.bincount(self._gradient_index, weights=g.ravel(), minlength=self.layout.size)
        with np.errstate(all="ignore"):  # a diverging iterate: inf and nan are the caller's
            F = np.where(self.derived, G * self.row_scale, x - ends.given)
        if H is None:
            return F, None
        values = np.concatenate([H.ravel()[self._kept] * self._kept_scale,
                                 np.ones(self._pin_count)])
        return F, values

    def release(self) -> None:
        """Nothing to drop: the Jacobian's values are the evaluation's own array."""

    def parameter_jacobian(self, x, ends: HigherEnds) -> sp.csc_matrix:
        """``dF/dtheta`` (``grid/problem.py``): the windows' gradients ``dS_k/dx`` differentiated
        in ``theta``, gathered and scaled as in `evaluate`; pinned rows do not depend on it."""
        lay, theta = self.layout, np.ascontiguousarray(ends.theta, float)
        if theta.size == 0:
            return sp.csc_matrix((lay.size, 0))
        inputs = self._window_value.sx_in()
        gradient = ca.Function("window_gradient", inputs,
                               [self._window_value.call(inputs)[1]])
        z = np.ascontiguousarray(x, float).reshape(lay.nodes, lay.m)
        blocks = parameter_blocks(gradient, lay.order + 1,
                                  [z[j:j + lay.windows] for j in range(lay.order + 1)], theta)
        dense = np.stack([np.bincount(self._gradient_index, weights=blocks[:, :, j].ravel(),
                                      minlength=lay.size) for j in range(theta.size)], axis=1)
        dense *= np.where(self.derived, self.row_scale, 0.0)[:, None]
        return sp.csc_matrix(dense)

    def sparse(self, values) -> sp.csc_matrix:
        data = np.bincount(self._csc_position, weights=values,
                           minlength=self._csc_rows.size)
        size = self.layout.size
        return sp.csc_matrix((data, self._csc_rows, self._csc_pointer), (size, size))

    def banded(self, values) -> np.ndarray:
        """The Jacobian in LAPACK ``gbsv`` storage, ``(3 w + 1, N m)`` in Fortran order,
        ``A[i, j]`` at row ``2 w + i - j``."""
        w, size = self.layout.bandwidth, self.layout.size
        store = np.bincount(self._band_position, weights=values, minlength=(3 * w + 1) * size)
        return store.reshape(size, 3 * w + 1).T

    def round_off(self, x, ends: HigherEnds, magnitudes: np.ndarray) -> np.ndarray:
        """Per row, the size of the rounding errors an evaluation of ``F`` carries: ``|F'(x)|
        magnitudes`` (every input rounded once, each of size ``magnitudes``) plus the sum of
        the terms added into the row (``|row scale| sum_k |dS_k/dx_i|``); pinned rows: their
        value's magnitude. Multiply by machine epsilon for an absolute error."""
        g, H = self._blocks(x, ends.theta, True)
        terms = np.bincount(self._gradient_index, weights=np.abs(g.ravel()),
                            minlength=self.layout.size) * np.abs(self.row_scale)
        return np.where(self.derived, terms + self._propagated(H, magnitudes), magnitudes)

    def response(self, x, ends: HigherEnds, sizes: np.ndarray) -> np.ndarray:
        """Per derived row, how far it moves when every unknown moves by its ``sizes``:
        ``|F'(x)| sizes`` (0 on the pinned rows), in the row's own units whatever the units
        of ``q``, of time or of the Lagrangian."""
        _, H = self._blocks(x, ends.theta, True)
        return np.where(self.derived, self._propagated(H, sizes), 0.0)

    def _propagated(self, H, sizes: np.ndarray) -> np.ndarray:
        values = np.abs(H.ravel()[self._kept] * self._kept_scale)
        kept_rows, kept_columns = self.rows[:self._kept.size], self.columns[:self._kept.size]
        return np.bincount(kept_rows, weights=values * sizes[kept_columns],
                           minlength=self.layout.size)
