"""The closed grid of a constrained system (``g(q) = 0``, ``m`` rows): the periodic rows of
``closed_grid.py`` with the node multipliers and node rows of ``bvp/constrained_grid.py``.

Unknowns, by node, then the unfolding parameters: ``w_k = (t_k, q_k, p_k, lambda_k, mu_k)`` for
``k = 0 .. N`` (``M = 1 + 2n + 2m`` values; node ``k``'s multipliers are those of interval ``k``
of ``discrete/constrained.py``, the last node's are unused and pinned to zero), then
``u = (lambda, mu_1 .. mu_r)``: ``(N+1) M + 1 + r`` in all. Rows, in this order::

    t_0,  z_0[section] - value                                       (2)
    g_i . (z_0 - z_0^ref), g_i = J grad I_i at the start's node 0    (r)
    for k = 0 .. N-1:  the 2n interval equations (RATTLE's form),    (2n)
                       unfolded by tau_k (lambda grad H + sum mu_i grad I_i)(Q_k, P_k)
                       the hidden constraint G H_p + g_t at node k+1 (m)
                       g(q_{k+1}) at node k+1                        (m)
                       E_k - E (the interval's energy, own momenta)  (1)
    q_N - q_0,  p_N - p_0                                            (2n)
    the unused multipliers of node N                                 (2m)

``2 + r + N M + 2n + 2m = (N+1) M + 1 + r``: square. Node 0's constraint rows are those of node
``N`` through the closure. Why the unfolding parameters: ``orbit.py``'s docstring (the time shift
and each symmetry make one direction of solutions and one dependent closure row); here the
constraint forces take up the unfolding term's component normal to the manifold (the
multipliers adjust), so the term may be any vector field with a component along the level
set's normal. ``(Q_k, P_k)`` are the midpoints of the interval's node positions and momenta.

One MX graph of per-interval SX functions mapped over the grid (as ``constrained_grid.py``):
CasADi's own sparsity, the sparse LU in the grid's Newton.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ...cache import cached
from ...discrete.constrained import (
    energy_expression,
    interval_energy_expression,
    interval_expression,
    node_expression,
)
from ...discrete.scheme import Scheme
from .closed_grid import integral_gradients


@dataclass(frozen=True)
class ConstrainedClosedLayout:
    """Node ``k``'s ``(t, q, p, lambda, mu)`` at ``x[k M:(k+1) M]``, ``k = 0 .. N``; then
    ``u = (lambda, mu_1, ..., mu_r)``."""

    n: int
    m: int
    intervals: int
    integrals: int = 0

    @property
    def width(self) -> int:
        return 1 + 2 * self.n + 2 * self.m

    @property
    def nodes(self) -> int:
        return self.intervals + 1

    @property
    def unfoldings(self) -> int:
        return 1 + self.integrals

    @property
    def size(self) -> int:
        return self.nodes * self.width + self.unfoldings

    @property
    def bandwidth(self) -> int:
        return self.size  # corner and column entries: the sparse LU

    def time_index(self) -> np.ndarray:
        return np.arange(self.nodes) * self.width

    def pack(self, t, q, p, multipliers) -> np.ndarray:
        """``x`` from ``t`` (N+1,), ``q``, ``p`` (N+1, n), the multipliers (N, 2m); the
        unfolding parameters zero."""
        last = np.zeros((1, 2 * self.m))
        nodes = np.column_stack([np.asarray(t, float), q, p,
                                 np.vstack([np.asarray(multipliers, float), last])])
        return np.concatenate([nodes.ravel(), np.zeros(self.unfoldings)])

    def unpack(self, x):
        """``(t, q, p, multipliers (N, 2m), u)``, copies."""
        n, size = self.n, self.nodes * self.width
        w = np.asarray(x[:size], float).reshape(self.nodes, self.width)
        return (w[:, 0].copy(), w[:, 1:n + 1].copy(), w[:, n + 1:2 * n + 1].copy(),
                w[:-1, 2 * n + 1:].copy(), np.array(x[size:], float))


@dataclass(frozen=True)
class ConstrainedClosure:
    """The data of one orbit: energy, section (index into ``(t, q, p)`` and value), parameters,
    the integrals' reference node and generators (``r x 2n``)."""

    energy: float
    section_index: int
    section_value: float
    theta: np.ndarray
    reference: np.ndarray
    generators: np.ndarray

    def vector(self) -> np.ndarray:
        return np.concatenate([self.theta, [self.energy, self.section_value], self.reference,
                               np.ravel(self.generators, "F")])


def interval_function(system, scheme: Scheme, integrals) -> ca.Function:
    """``(w_a, w_b, u, E, theta) -> rows (2n + 2m + 1)`` of one interval (module docstring)."""
    def build():
        n, m, r = system.n, system.n_constraints, len(integrals)
        w_a, w_b = ca.SX.sym("w_a", 1 + 2 * n + 2 * m), ca.SX.sym("w_b", 1 + 2 * n + 2 * m)
        u, level, theta = ca.SX.sym("u", 1 + r), ca.SX.sym("E"), system.theta
        t_a, q_a, p_a = w_a[0], w_a[1:n + 1], w_a[n + 1:2 * n + 1]
        t_b, q_b, p_b = w_b[0], w_b[1:n + 1], w_b[n + 1:2 * n + 1]
        lam, mu = w_a[2 * n + 1:2 * n + 1 + m], w_a[2 * n + 1 + m:]
        rows = interval_expression(system, scheme, t_a, t_b, q_a, p_a, q_b, p_b, lam, mu,
                                   theta)
        gradients = integral_gradients(system, integrals)((q_a + q_b) / 2, (p_a + p_b) / 2,
                                                          theta)
        unfolded = rows - (t_b - t_a) * ca.mtimes(gradients, u)
        at_b = node_expression(system, q_b, p_b, t_b, theta)
        energy = interval_energy_expression(system, scheme, t_a, t_b, q_a, p_a, q_b, p_b, lam,
                                            mu, theta)
        return ca.Function("constrained_closed_interval", [w_a, w_b, u, level, theta],
                           [ca.vertcat(unfolded, at_b[m:], at_b[:m], energy - level)])
    return cached(system, ("constrained_closed_interval", scheme, tuple(integrals)), build)


def scheme_energy_function(system, scheme: Scheme) -> ca.Function:
    """``(w_prev, w_mid, w_next, theta) -> `` the scheme's own energy equation at the middle
    node (``discrete/constrained.energy_expression``), for the verification."""
    def build():
        n, m = system.n, system.n_constraints
        w = [ca.SX.sym(f"w{j}", 1 + 2 * n + 2 * m) for j in range(3)]
        t = [wj[0] for wj in w]
        q = [wj[1:n + 1] for wj in w]
        p = [wj[n + 1:2 * n + 1] for wj in w]
        e = energy_expression(system, scheme, scheme.rule,
                              (*t, q[0], p[0], q[1], p[1], q[2], p[2]),
                              (w[0][2 * n + 1:2 * n + 1 + m], w[0][2 * n + 1 + m:],
                               w[1][2 * n + 1:2 * n + 1 + m], w[1][2 * n + 1 + m:]),
                              system.theta)
        return ca.Function("constrained_closed_energy", [*w, system.theta], [e])
    return cached(system, ("constrained_closed_energy", scheme), build)


class ConstrainedClosedGrid:
    """``F(x)`` and its sparse Jacobian for one system, scheme, interval count and set of
    integrals (module docstring); a ``grid.GridProblem`` whose data is a
    `ConstrainedClosure`."""

    def __init__(self, system, scheme: Scheme, intervals: int, integrals=()):
        integrals = tuple(integrals)
        n, m, r = system.n, system.n_constraints, len(integrals)
        self.system, self.scheme, self.integrals = system, scheme, integrals
        self.layout = layout = ConstrainedClosedLayout(n, m, intervals, r)
        N, M = intervals, layout.width
        x = ca.MX.sym("x", layout.size)
        k = system.theta.numel()
        P = ca.MX.sym("P", k + 2 + 2 * n + 2 * n * r)
        theta, level, value = P[:k], P[k], P[k + 1]
        reference = P[k + 2:k + 2 + 2 * n]
        generators = ca.reshape(P[k + 2 + 2 * n:], r, 2 * n)
        W = ca.reshape(x[:(N + 1) * M], M, N + 1)
        u = x[(N + 1) * M:]
        blocks = interval_function(system, scheme, integrals).map(N)(
            W[:, :-1], W[:, 1:], ca.repmat(u, 1, N), level, theta)
        self.x, self.P = x, P
        self._W, self._rows = W, [
            W[0, 0], ca.mtimes(generators, W[1:2 * n + 1, 0] - reference), ca.vec(blocks),
            W[1:2 * n + 1, N] - W[1:2 * n + 1, 0], W[2 * n + 1:, N]]
        self._value = value
        self._built = {}

    def _functions(self, section_index: int):
        """``(F, (F, J))`` with the section row on coordinate ``section_index``."""
        if section_index not in self._built:
            first, phase, body, closure, unused = self._rows
            F = ca.vertcat(first, self._W[section_index, 0] - self._value, phase, body,
                           closure, unused)
            J = ca.jacobian(F, self.x)
            colind, row = J.sparsity().get_ccs()
            self._built[section_index] = (
                ca.Function("constrained_closed_rows", [self.x, self.P], [F]),
                ca.Function("constrained_closed_jacobian", [self.x, self.P], [J]),
                (np.asarray(row), np.asarray(colind), J.shape), F)
        return self._built[section_index]

    def rows_expression(self, section_index: int):
        """The rows as an MX expression of ``(self.x, self.P)`` (IPOPT's constraints)."""
        return self._functions(section_index)[3]

    def evaluate(self, x: np.ndarray, data: ConstrainedClosure, jacobian: bool = True):
        rows, jac, pattern, _ = self._functions(data.section_index)
        P = data.vector()
        F = np.asarray(rows(x, P), float).ravel()
        if not jacobian:
            return F, None
        row, colind, shape = pattern
        values = np.asarray(jac(x, P).nonzeros(), float)
        return F, sp.csc_matrix((values, row, colind), shape=shape)

    def sparse(self, jacobian):
        return jacobian

    def parameter_jacobian(self, x: np.ndarray, data: ConstrainedClosure) -> sp.csc_matrix:
        """``dF/dtheta`` at ``x`` (``(size, len(theta))``, sparse), from the same rows."""
        k = self.system.theta.numel()
        key = ("theta", data.section_index)
        if key not in self._built:
            F = self.rows_expression(data.section_index)
            self._built[key] = ca.Function("constrained_closed_theta", [self.x, self.P],
                                           [ca.jacobian(F, self.P)[:, :k]])
        D = self._built[key](x, data.vector())
        return sp.csc_matrix(D.sparse()) if hasattr(D, "sparse") else sp.csc_matrix(
            np.asarray(D, float))

    def release(self) -> None:
        pass

    def parts(self, x: np.ndarray, data: ConstrainedClosure) -> dict:
        """The unscaled rows of ``x`` with the unfolding parameters set to zero (a point is
        verified without them): ``interval`` (N, 2n), ``hidden``, ``g`` (N, m) at nodes
        ``1 .. N``, ``prescribed`` (N,) ``E_k - E``, ``energy`` (N,) the scheme's own energy
        equation at nodes ``1 .. N-1`` and at the wrap-around node, ``closure`` (2n,),
        ``section``, ``unused`` (2m,)."""
        layout = self.layout
        n, m, N, M = layout.n, layout.m, layout.intervals, layout.width
        W = np.asarray(x[:(N + 1) * M], float).reshape(N + 1, M).T
        zero = np.zeros((layout.unfoldings, N))
        blocks = np.asarray(interval_function(self.system, self.scheme, self.integrals).map(N)(
            W[:, :-1], W[:, 1:], zero, data.energy, data.theta))
        # the wrap-around node: node N with interval 0's multipliers, node N+1 node 1 a period on
        wrapped = np.column_stack([W, W[:, 1:2]])
        wrapped[:, N] = np.concatenate([W[:2 * n + 1, N], W[2 * n + 1:, 0]])
        wrapped[0, N + 1] = W[0, N] + W[0, 1] - W[0, 0]
        energy = np.asarray(scheme_energy_function(self.system, self.scheme).map(N)(
            wrapped[:, :-2], wrapped[:, 1:-1], wrapped[:, 2:], data.theta)).ravel()
        return {"interval": blocks[:2 * n].T, "hidden": blocks[2 * n:2 * n + m].T,
                "g": blocks[2 * n + m:2 * n + 2 * m].T, "prescribed": blocks[-1],
                "energy": energy, "closure": W[1:2 * n + 1, N] - W[1:2 * n + 1, 0],
                "section": float(W[data.section_index, 0] - data.section_value),
                "unused": W[2 * n + 1:, N]}


__all__ = ["ConstrainedClosedGrid", "ConstrainedClosedLayout", "ConstrainedClosure",
           "interval_function", "scheme_energy_function"]
