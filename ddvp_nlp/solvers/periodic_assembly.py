"""The periodic system of a closed grid, assembled node by node: residual and sparse Jacobian.

Unknowns, interleaved by node, then one number: ``x = (z_0, z_1, ..., z_N, lambda)`` with
``z_k = (t_k, q_k, p_k)`` (``m = 2n + 1`` values per node, ``(N+1) m + 1`` in all). Equations,
in the same order::

    t_0,  z_0[section] - value                                       (2 rows)
    for k = 0 .. N-1:  canonical equations of interval k,            (2n rows)
                       unfolded by lambda tau_k grad H(Q_k, P_k)
                       H(Q_k, P_k) - E                               (1 row)
    q_N - q_0,  p_N - p_0                                            (2n rows)

``2 + N m + 2n = (N+1) m + 1`` rows: square. Why these rows, and why ``lambda``, is the
docstring of ``periodic.py``. The interval rows are ``equations.canonical_expression`` and
``equations.midpoint_energy_function``'s expression, written once in ``discrete/``; each interval
becomes one CasADi function returning its ``m`` rows and their dense Jacobian in
``(z_k, z_{k+1}, lambda)``, mapped over the grid by ``bvp_assembly.ChunkedMap``. The closure rows
put entries in the corner (columns of ``z_0``) and ``lambda`` is a full column: the matrix is
factored by sparse LU (SuperLU), not in band storage. The object has the interface
``bvp_newton.newton`` expects (``layout.time_index``, ``layout.bandwidth``, ``evaluate``,
``sparse``), so the fixed-endpoint solver's Newton iteration and line search run unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..cache import cached
from ..discrete import equations
from ..discrete.scheme import Scheme
from ..physics.hamiltonian import derivatives_function
from .bvp_assembly import chunked


@dataclass(frozen=True)
class ClosedLayout:
    """Node ``k``'s ``(t, q, p)`` at ``x[k m:(k+1) m]`` for ``k = 0 .. N``; ``lambda`` last."""

    n: int
    intervals: int

    @property
    def m(self) -> int:
        return 2 * self.n + 1

    @property
    def nodes(self) -> int:
        return self.intervals + 1

    @property
    def size(self) -> int:
        return self.nodes * self.m + 1

    @property
    def bandwidth(self) -> int:
        """Wider than any band: tells ``bvp_newton`` to factor the sparse matrix."""
        return self.size

    def pack(self, t, q, p, unfolding: float = 0.0) -> np.ndarray:
        return np.concatenate([np.column_stack([np.asarray(t, float), q, p]).ravel(),
                               [float(unfolding)]])

    def unpack(self, x):
        """``(t, q, p, lambda)`` (copies) from ``x``."""
        z = np.asarray(x[:-1], float).reshape(self.nodes, self.m)
        return (z[:, 0].copy(), z[:, 1:self.n + 1].copy(), z[:, self.n + 1:].copy(),
                float(x[-1]))

    def time_index(self) -> np.ndarray:
        return np.arange(self.nodes) * self.m


@dataclass(frozen=True)
class Closure:
    """The data of one periodic problem: the prescribed energy, the section (index into
    ``z = (t, q, p)`` of a node and value), the parameters."""

    energy: float
    section_index: int
    section_value: float
    theta: np.ndarray


def _interval_function(system, scheme: Scheme) -> ca.Function:
    """``(z_a, z_b, lambda, E, theta) -> (rows (m,), d rows / d(z_a, z_b, lambda))``."""
    def build():
        n = system.n
        z_a, z_b = ca.SX.sym("z_a", 2 * n + 1), ca.SX.sym("z_b", 2 * n + 1)
        unfolding, level = ca.SX.sym("lambda"), ca.SX.sym("E")
        t_a, q_a, p_a = z_a[0], z_a[1:n + 1], z_a[n + 1:]
        t_b, q_b, p_b = z_b[0], z_b[1:n + 1], z_b[n + 1:]
        theta = system.theta
        canonical = equations.canonical_expression(system, scheme, t_a, t_b, q_a, p_a, q_b,
                                                   p_b, theta)
        energy = equations.midpoint_energy_function(system, scheme)(t_a, t_b, q_a, p_a, q_b,
                                                                    p_b, theta)
        Q = scheme.alpha * q_a + scheme.beta * q_b
        P = scheme.alpha * p_b + scheme.beta * p_a
        _, H_q, H_p, _ = derivatives_function(system)(Q, P, t_a, theta)
        # The unfolding: canonical rows q_b - q_a - tau H_p - lambda tau H_q and
        # p_b - p_a + tau H_q - lambda tau H_p (z' = (J + lambda I) grad H, continuous form).
        gradient = ca.vertcat(H_q, H_p)
        rows = ca.vertcat(canonical - unfolding * (t_b - t_a) * gradient, energy - level)
        unknowns = ca.vertcat(z_a, z_b, unfolding)
        return ca.Function("periodic_interval", [z_a, z_b, unfolding, level, theta],
                           [rows, ca.densify(ca.jacobian(rows, unknowns))])
    return cached(system, ("periodic_interval", scheme), build)


class PeriodicAssembly:
    """``F(x)`` and ``F'(x)`` of one system, scheme and interval count (module docstring)."""

    def __init__(self, system, scheme: Scheme, intervals: int, section_index: int):
        self.layout = ClosedLayout(system.n, intervals)
        self.scheme = scheme
        self.section_index = section_index
        self._interval = chunked(system, ("periodic_interval", scheme),
                                 _interval_function(system, scheme))
        self._pattern = self._sparsity()

    def evaluate(self, x: np.ndarray, closure: Closure, jacobian: bool = True):
        """``F(x)`` and, if asked, the interval blocks ``(N, 2m + 1, m)``."""
        N, m = self.layout.intervals, self.layout.m
        z = np.ascontiguousarray(x[:-1], float).reshape(N + 1, m)
        unfolding = np.full((N, 1), x[-1])
        level = np.full((N, 1), closure.energy)
        rows, J = self._interval([z[:-1], z[1:], unfolding, level], closure.theta, N)
        F = np.empty(self.layout.size)
        F[0] = z[0, 0]
        F[1] = z[0, closure.section_index] - closure.section_value
        F[2:2 + N * m] = rows[:, 0, :].ravel()
        F[2 + N * m:] = z[N, 1:] - z[0, 1:]
        return F, (J if jacobian else None)

    def residuals(self, F: np.ndarray):
        """``(canonical (N, 2n), energy (N,), closure (2n,))`` in ``F`` (unscaled)."""
        N, m, n = self.layout.intervals, self.layout.m, self.layout.n
        body = F[2:2 + N * m].reshape(N, m)
        return body[:, :2 * n].copy(), body[:, 2 * n].copy(), F[2 + N * m:].copy()

    def _sparsity(self):
        """Rows and columns of every Jacobian entry, in the order :meth:`sparse` fills them:
        the interval blocks (``N (2m + 1) m``); the constant entries (pinned time, section,
        closure) are appended by :meth:`sparse`."""
        N, m = self.layout.intervals, self.layout.m
        k = np.arange(N)[:, None, None]
        column = np.arange(2 * m + 1)[None, :, None]
        row = np.arange(m)[None, None, :]
        rows = np.broadcast_to(2 + k * m + row, (N, 2 * m + 1, m))
        cols = np.broadcast_to(np.where(column < 2 * m, k * m + column, self.layout.size - 1),
                               (N, 2 * m + 1, m))
        return rows.ravel(), cols.ravel()

    def sparse(self, blocks) -> sp.csc_matrix:
        """The Jacobian as a sparse matrix."""
        N, m = self.layout.intervals, self.layout.m
        rows, cols = self._pattern
        closing = 2 + N * m + np.arange(m - 1)
        fixed_rows = np.concatenate([[0, 1], closing, closing])
        fixed_cols = np.concatenate([[0, self.section_index], N * m + 1 + np.arange(m - 1),
                                     1 + np.arange(m - 1)])
        fixed_values = np.concatenate([[1.0, 1.0], np.ones(m - 1), -np.ones(m - 1)])
        size = self.layout.size
        return sp.csc_matrix((np.concatenate([np.asarray(blocks).ravel(), fixed_values]),
                              (np.concatenate([rows, fixed_rows]),
                               np.concatenate([cols, fixed_cols]))), (size, size))
