"""IPOPT on the fixed-endpoint system, fed by the banded assembly of ``interleaved.py``: no NLP
expression over the grid.

The NLP (``grid/ipopt.py``'s feasibility problem): unknowns interleaved by node,
``z_k = (t_k, q_k, p_k)``; the fixed end values (``t_0, q_0, t_{N-1}, q_{N-1}``, and for
``fixed`` every ``t_k``) pinned by ``lbx = ubx`` (IPOPT removes them,
``fixed_variable_treatment = make_parameter``); objective ``0``; the canonical and energy rows
as equalities, ``t_{k+1} - t_k >= tau_floor`` as linear rows. IPOPT's functions are
`casadi.Callback` objects whose ``eval_buffer`` runs numpy code on CasADi's own memory:

- ``g``: the rows of `GridAssembly`'s ``F(x)`` that are not pins (the pinned rows
  ``t_0 - t_start`` etc. are dropped), then the step differences;
- ``jac_g``: the same Jacobian blocks that Newton factorises, gathered from the assembly's band
  storage into a sparsity pattern built once (CSC nonzeros in the order of the band storage's
  memory, merged with the constant step rows by one precomputed permutation);
- ``hess_lag``: the upper triangle of ``sum_i lam_i Hess g_i`` (the objective is ``0``), from
  per-interval Hessian blocks of ``lam . r_k`` and per-node ones of ``mu e_k``
  (``hessian_block_functions``: only their structural nonzeros), evaluated in windows like the
  residual (``grid/maps.ChunkedMap``) and summed into a band store by one vectorised addition
  per block entry, then gathered into the fixed pattern.

Build cost is the sparsity patterns (``O(N)`` numpy, then CasADi ``Sparsity`` from lists) and
IPOPT's own set-up; each evaluation is ``O(N)``. IPOPT receives ``g`` and ``jac_g``
separately; the assembly is evaluated once per point (the last point's ``F`` and blocks are
kept). This build was 4-6 times faster than an MX NLP of mapped per-interval functions on the
pendulum at N = 1e3..1e5 (docs/benchmarks/bench_bvp.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

import casadi as ca
import numpy as np

from ...cache import cached
from ...discrete.scheme import Scheme
from ..grid.ipopt import DEFAULT_OPTIONS, FeasibilityNlp, ipopt_settings
from ..grid.maps import chunked
from ..grid.problem import GridResult
from ..options import Compilation
from .interleaved import Ends, GridAssembly, NodeLayout, hessian_block_functions, node_expressions

# Changes to grid/ipopt.DEFAULT_OPTIONS for this build, measured on the pendulum's released solve
# at N = 1e5 from the same start (one process each, loaded machine, CPU time):
# - AMD ordering (pivot_order 0): MUMPS's analysis 0.26 s against 5.1 s with METIS, the
#   whole phase 9.1 s against 11.2 s; AMF and QAMD were slower (14.5 s, 10.3 s);
# - mu_init 1e-13 (and mu_min below it): with 1e-9 the complementarity alone stayed above
#   IPOPT's tol (1e-11), and lowering the barrier took 8 iterations and ended at
#   "acceptable"; with 1e-13 the phase took 1-2 iterations and ended "Solve_Succeeded".
# MUMPS scaling 77 or 8 and a pivot tolerance of 1e-4 took more factorizations (32, 22, 8
# against 5): the inertia MUMPS reports for this saddle-point matrix (its (1,1) block is
# ~1e-13) is off by a few eigenvalues, which costs IPOPT a perturbed refactorization.
ASSEMBLY_OPTIONS = MappingProxyType({"ipopt.mumps_pivot_order": 0, "ipopt.mu_init": 1e-13,
                                     "ipopt.mu_min": 1e-15})


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


@dataclass(frozen=True)
class EndScales:
    """What IPOPT's unknowns and rows are divided by (`end_scales`): ``unknowns`` ``(m,)``,
    each kind of a node's values ``(t, q_1.., p_1..)``; ``rows`` ``(m,)``, each kind of row of
    node ``k + 1`` (interval ``k``'s ``2n`` canonical rows, then its energy row); ``steps``,
    the rows ``(t_{k+1} - t_k) / h``."""

    unknowns: np.ndarray
    rows: np.ndarray
    steps: float


def end_scales(layout: NodeLayout, band: np.ndarray, sizes: np.ndarray,
               energy_scale: float) -> EndScales:
    """IPOPT's scales from the Jacobian at the start (``band``: LAPACK ``gbsv`` storage,
    ``(3 w + 1, N m)``) and each kind of unknown's size (``sizes``, ``(m,)``: the span, each
    coordinate's range; ``nan`` where the start has none, a momentum constant along a straight
    line): a kind of row's size is the most its rows change when the sized unknowns move by
    their sizes, ``max |J_ij| d_j``; an unsized kind of unknown's is the move that changes some
    row by its size (`grid.ipopt.equilibrated_sizes`, by kind: one number per kind keeps the
    scaling a table of ``m x (3 w + 1)`` factors on the band, no index per nonzero). The step
    rows are divided by ``d_t / h``. Read off the motion alone, the scaled problem is the same
    to round-off in any units of length, momentum and time: IPOPT on the raw rows, with one
    absolute tolerance, ended ``not_verified`` on a swing in lengths of ``1e-8``, or in time
    units of ``1e5``, and stopped at its straight-line start in lengths of ``1e-8`` with time
    units of ``1e4`` (0 iterations)."""
    n, N, m, w = layout.n, layout.nodes, layout.m, layout.bandwidth
    B = 3 * w + 1
    table = band.T.reshape(N, m, B)
    kinds = row_kinds(layout)
    first, last = n + 1, n + 1 + (N - 1) * m  # the body rows; the last energy row is a pin
    reach = np.zeros((m, B))
    inner = slice(min(N, -(-(2 * w + n + 1) // m) + 1), max(0, N - w // m - 3))
    for begin in range(inner.start, inner.stop, CHUNK_NODES):  # no copy of the whole band
        chunk = table[begin:min(begin + CHUNK_NODES, inner.stop)]
        reach = np.maximum(reach, np.max(np.abs(chunk), axis=0))
    offsets = np.arange(m)[:, None] + np.arange(B)[None, :] - 2 * w
    for node in [*range(0, min(N, inner.start)), *range(max(inner.stop, inner.start), N)]:
        row = node * m + offsets
        body = (row >= first) & (row < last) & (row != last - 1)
        reach = np.maximum(reach, np.where(body, np.abs(table[node]), 0.0))
    d = np.asarray(sizes, float).copy()
    known = np.isfinite(d) & (d > 0)
    rows = np.zeros(m)
    np.maximum.at(rows, kinds.ravel(), (reach * np.where(known, d, 0.0)[:, None]).ravel())
    rows = np.where(rows > 0, rows, np.finfo(float).tiny)
    with np.errstate(divide="ignore"):
        moved = np.max(reach / rows[kinds], axis=1)
        d = np.where(known, d, np.where(moved > 0, 1.0 / moved, np.nan))
    d = np.where(np.isfinite(d) & (d > 0), d, np.nanmax(np.where(known, d, np.nan)))
    return EndScales(d, rows, float(d[0] / energy_scale))


# Nodes of the band read at a time for the scales (`end_scales`): the band of 1e6 nodes is
# 0.4 GB, and its absolute value at once was another.
CHUNK_NODES = 65536


def row_kinds(layout: NodeLayout) -> np.ndarray:
    """``(m, 3 w + 1)``: the kind (`EndScales.rows`) of the row of each entry of the band's
    table ``(node, kind of unknown, offset)``."""
    n, m, w = layout.n, layout.m, layout.bandwidth
    offsets = np.arange(m)[:, None] + np.arange(3 * w + 1)[None, :] - 2 * w
    return (offsets - n - 1) % m


def _sparsity(rows: np.ndarray, columns: np.ndarray, shape):
    """CasADi sparsity and the CSC order of the entries ``(rows, columns)`` (no duplicates).

    CasADi takes Python lists here: from numpy arrays its constructor converted element by
    element (73 s against 3 s for 2.4e7 entries, measured)."""
    order = np.lexsort((rows, columns))
    colind = np.zeros(shape[1] + 1, dtype=np.int64)
    np.cumsum(np.bincount(columns, minlength=shape[1]), out=colind[1:])
    return ca.Sparsity(shape[0], shape[1], colind.tolist(), rows[order].tolist()), order


def _narrow(index: np.ndarray) -> np.ndarray:
    """``index`` as 32-bit integers where they fit (half the memory of the patterns)."""
    return index.astype(np.int32) if index.size and index.max() < 2 ** 31 else index


class GridNlp:
    """``g``, its Jacobian and the Lagrangian's Hessian of one system, scheme and node count,
    on numpy arrays (module docstring); the callbacks below call it."""

    def __init__(self, system, scheme: Scheme, nodes: int, compilation: Compilation):
        self.grid = GridAssembly(system, scheme, nodes, compilation)
        self.layout, self.scheme = self.grid.layout, scheme
        self.steps = scheme.variable_steps
        self.n_theta = system.theta.numel()
        n, N, m = system.n, nodes, self.layout.m
        pinned = np.zeros(N * m, bool)
        pinned[:n + 1] = pinned[N * m - n:] = True
        time_rows = n + 1 + np.arange(N - 1) * m + 2 * n  # time row of node k + 1
        pinned[time_rows[-1:] if self.steps else time_rows] = True
        self.kept = np.flatnonzero(~pinned)
        self.ng = self.kept.size + (N - 1 if self.steps else 0)
        residuals = residual_functions(system, scheme)
        self._residuals = [None if f is None else chunked(system, ("bvp_residual", j, scheme), f,
                                                          compilation.threads)
                           for j, f in enumerate(residuals)]
        for f, count in zip(self._residuals, (N - 1, N - 2), strict=True):
            if f is not None:
                f.prepare(count)
        hessians = hessian_block_functions(system, scheme)
        self._hessians = [None if h is None else (chunked(system, ("bvp_hessian", j, scheme),
                                                          h[0], compilation.threads), h[1], h[2])
                          for j, h in enumerate(hessians)]
        for h, count in zip(self._hessians, (N - 1, N - 2), strict=True):
            if h is not None:
                h[0].prepare(count)
        # Columns of values pinned for the whole build (every node time of ``fixed``): IPOPT
        # drops them (fixed_variable_treatment make_parameter), so their Jacobian and Hessian
        # entries are left out of the patterns. At N = 1e6 they were a third of the Jacobian's
        # 1.2e7 entries and most of the Hessian's, copied by CasADi, IPOPT and MUMPS (peak
        # 4.3 GB; measured).
        self.fixed_columns = np.zeros(N * m, bool)
        if not self.steps:
            self.fixed_columns[::m] = True
        self._jacobian_pattern(pinned)
        self._hessian_pattern()
        self._last = None
        self.scales: EndScales | None = None  # set for each solve (`scale`)
        self._scaled_band = None  # the evaluation whose band is scaled in place

    def scale(self, scales: EndScales) -> None:
        """IPOPT sees ``x / d`` and each row divided by its size (`end_scales`) from now on:
        the unknowns' vector ``d`` over the grid, the rows', and the factors of the band's
        and the Hessian store's entries."""
        n, N, m = self.layout.n, self.layout.nodes, self.layout.m
        d, rows = scales.unknowns, scales.rows
        self.scales = scales
        self.x_sizes = np.tile(d, N)
        self.row_sizes = np.concatenate([rows[(self.kept - n - 1) % m],
                                         np.full(self.ng - self.kept.size, scales.steps)])
        # the factors of the band's table (node, kind of unknown, offset) and of the Hessian
        # store's (node, kind, offset): applied in place, by broadcasting, before the gather
        self._band_factors = d[:, None] / rows[row_kinds(self.layout)]
        dd = np.arange(3 * m)
        self._hessian_factors = d[:, None] * d[(np.arange(m)[:, None] + dd) % m]

    # --- patterns, built once -------------------------------------------------------------

    def _jacobian_pattern(self, pinned):
        N, m, w = self.layout.nodes, self.layout.m, self.layout.bandwidth
        n = self.layout.n
        ones = (np.ones((N - 1, 2 * m, 2 * n)), np.ones((N - 2, 3 * m)) if self.steps else None)
        band = self.grid.banded(ones).T  # (N m, 3 w + 1), C order: column j's band contiguous
        flat = np.flatnonzero(band.ravel())
        columns = flat // band.shape[1]
        rows = flat % band.shape[1] - 2 * w + columns
        row_of = np.cumsum(~pinned) - 1  # F row -> g row
        keep = ~pinned[rows] & ~self.fixed_columns[columns]
        rows, columns, self._band_source = row_of[rows[keep]], columns[keep], flat[keep]
        if self.steps:  # t_{k+1} - t_k: -1 at t_k, +1 at t_{k+1}
            k = np.arange(N - 1)
            rows = np.concatenate([rows, self.kept.size + k, self.kept.size + k])
            columns = np.concatenate([columns, k * m, (k + 1) * m])
            constants = np.r_[-np.ones(N - 1), np.ones(N - 1)]
        else:
            constants = np.zeros(0)
        self.jac_sparsity, order = _sparsity(rows, columns, (self.ng, N * m))
        position = np.empty(order.size, np.int32 if order.size < 2 ** 31 else np.int64)
        position[order] = np.arange(order.size)
        self._band_source = _narrow(self._band_source)
        self._band_target = position[:self._band_source.size]
        self._constant_target = position[self._band_source.size:]
        self._constants = constants

    def _hessian_pattern(self):
        N, m = self.layout.nodes, self.layout.m
        ones = [None if h is None else np.ones((count, 1, h[1].size))
                for h, count in zip(self._hessians, (N - 1, N - 2), strict=True)]
        band = self._hessian_band(ones)
        flat = np.flatnonzero(band.ravel())
        rows = flat // band.shape[1]
        columns = rows + flat % band.shape[1]
        keep = ~self.fixed_columns[rows] & ~self.fixed_columns[columns]
        flat, rows, columns = flat[keep], rows[keep], columns[keep]
        self.hess_sparsity, order = _sparsity(rows, columns, (N * m, N * m))
        self._hessian_source = _narrow(flat[order])

    def _hessian_band(self, values) -> np.ndarray:
        """Upper band of the Hessian, ``H[i, i + d]`` at ``[i, d]``, from the blocks'
        nonzeros ``values`` (``(count, 1, entries)`` for each kind of block)."""
        N, m = self.layout.nodes, self.layout.m
        store = np.zeros((N, m, 3 * m))
        for h, v in zip(self._hessians, values, strict=True):
            if h is None or v is None:
                continue
            _, rows, columns = h
            count = v.shape[0]
            for e, (a, b) in enumerate(zip(rows, columns, strict=True)):
                node = a // m
                store[node:node + count, a % m, b - a] += v[:, 0, e]
        return store.reshape(N * m, 3 * m)

    # --- evaluations ----------------------------------------------------------------------

    def _evaluate(self, x: np.ndarray, parameters: np.ndarray):
        if self._last is None or not np.array_equal(self._last[0], x) \
                or not np.array_equal(self._last[1], parameters):
            ends = self._ends(parameters)
            F, blocks = self.grid.evaluate(x, ends)
            self._last = (x.copy(), parameters.copy(), F, blocks)
        return self._last[2], self._last[3]

    def forget(self) -> None:
        """Drop the last evaluation (its point, rows and Jacobian blocks)."""
        self._last = None

    def _ends(self, parameters) -> Ends:
        """The ends are pinned by bounds: the rows that hold them are not in ``g``."""
        n = self.layout.n
        times = np.zeros(2 if self.steps else self.layout.nodes)
        return Ends(np.zeros(n), np.zeros(n), times, parameters[:self.n_theta],
                    float(parameters[self.n_theta]))

    def _rows(self, x, parameters) -> np.ndarray:
        """The kept rows of ``F(x)`` without the Jacobian blocks (IPOPT's line search asks for
        ``g`` alone), or from the last evaluation if it was at ``x``."""
        if self._last is not None and np.array_equal(self._last[0], x) \
                and np.array_equal(self._last[1], parameters):
            return self._last[2][self.kept]
        n, N, m = self.layout.n, self.layout.nodes, self.layout.m
        z = np.ascontiguousarray(x).reshape(N, m)
        theta = np.ascontiguousarray(parameters[:self.n_theta])
        F = np.zeros(N * m)
        body = F[n + 1:n + 1 + (N - 1) * m].reshape(N - 1, m)
        interval, node = self._residuals
        body[:, :2 * n] = interval([z[:-1], z[1:]], theta, N - 1)[0][:, 0]
        if node is not None:
            body[:-1, 2 * n] = node([z[:-2], z[1:-1], z[2:]], theta, N - 2)[0][:, 0, 0] \
                / parameters[self.n_theta]
        return F[self.kept]

    def g(self, x, parameters, out):
        x = self._unscaled(x)
        out[:self.kept.size] = self._rows(x, parameters)
        if self.steps:
            out[self.kept.size:] = np.diff(x[::self.layout.m]) / parameters[self.n_theta]
        if self.scales is not None:
            out /= self.row_sizes

    def jacobian(self, x, parameters, out):
        x = self._unscaled(x)
        _, blocks = self._evaluate(x, parameters)
        band = self.grid.banded(blocks).T
        constants = self._constants / parameters[self.n_theta]
        if self.scales is not None:  # diag(1 / r) J diag(d), by the kinds of row and unknown
            if self._scaled_band is not self._last:  # once per evaluation: in its own store
                N, m = self.layout.nodes, self.layout.m
                band.reshape(N, m, -1)[...] *= self._band_factors
                self._scaled_band = self._last
            constants = constants * (self.scales.unknowns[0] / self.scales.steps)
        out[self._band_target] = band.ravel()[self._band_source]
        out[self._constant_target] = constants

    def _unscaled(self, x):
        return x if self.scales is None else x * self.x_sizes

    def hessian(self, x, parameters, lam_g, out):
        x = self._unscaled(x)
        n, N, m = self.layout.n, self.layout.nodes, self.layout.m
        z = np.ascontiguousarray(x).reshape(N, m)
        theta = np.ascontiguousarray(parameters[:self.n_theta])
        lam = np.zeros(N * m)
        lam[self.kept] = lam_g[:self.kept.size]
        if self.scales is not None:  # the scaled rows' multipliers on the raw rows
            lam[self.kept] /= self.row_sizes[:self.kept.size]
        body = lam[n + 1:n + 1 + (N - 1) * m].reshape(N - 1, m)
        interval, node = self._hessians
        values = [None, None]
        if interval is not None:
            values[0] = interval[0]([z[:-1], z[1:], np.ascontiguousarray(body[:, :2 * n])],
                                    theta, N - 1)[0]
        if node is not None:
            mu = np.ascontiguousarray(body[:-1, 2 * n:]) / parameters[self.n_theta]
            values[1] = node[0]([z[:-2], z[1:-1], z[2:], mu], theta, N - 2)[0]
        store = self._hessian_band(values)
        if self.scales is not None:  # diag(d) H diag(d)
            store.reshape(N, m, 3 * m)[...] *= self._hessian_factors
        out[:] = store.ravel()[self._hessian_source]


class _Callback(ca.Callback):
    """One of IPOPT's functions, evaluated by `GridNlp` on CasADi's buffers."""

    def __init__(self, name: str, nlp: GridNlp, inputs, outputs, evaluate):
        ca.Callback.__init__(self)
        self._inputs, self._outputs, self._evaluate = inputs, outputs, evaluate
        self.nlp = nlp
        self.construct(name, {})

    def get_n_in(self):
        return len(self._inputs)

    def get_n_out(self):
        return len(self._outputs)

    def get_sparsity_in(self, i):
        return self._inputs[i]

    def get_sparsity_out(self, i):
        return self._outputs[i]

    def has_eval_buffer(self):
        return True

    def eval_buffer(self, arg, res):
        self._evaluate([np.frombuffer(a, dtype=float) for a in arg],
                       [None if r is None else np.frombuffer(r, dtype=float) for r in res])
        return 0


def _callbacks(nlp: GridNlp):
    """``(g, jac_g, hess_lag)`` callbacks with CasADi's signatures for IPOPT."""
    nx, ng = nlp.layout.size, nlp.ng
    x, p = ca.Sparsity.dense(nx, 1), ca.Sparsity.dense(nlp.n_theta + 1, 1)
    g_out = ca.Sparsity.dense(ng, 1)

    def g(arg, res):
        nlp.g(arg[0], arg[1], res[0])

    def jac_g(arg, res):
        if res[0] is not None:
            nlp.g(arg[0], arg[1], res[0])
        nlp.jacobian(arg[0], arg[1], res[1])

    def hess_lag(arg, res):
        nlp.hessian(arg[0], arg[1], arg[3], res[0])

    return (_Callback("grid_g", nlp, [x, p], [g_out], g),
            _Callback("grid_jac_g", nlp, [x, p], [g_out, nlp.jac_sparsity], jac_g),
            _Callback("grid_hess_lag", nlp, [x, p, ca.Sparsity.dense(1, 1), g_out],
                      [nlp.hess_sparsity], hess_lag))


class BvpIpopt:
    """IPOPT on `GridNlp` (``grid/ipopt.py``'s one build) for one system, scheme and
    node count; `solve` takes the data of one problem."""

    def __init__(self, system, scheme: Scheme, nodes: int, *, tol: float, max_iter: int,
                 verbose: bool = False, time_limit: float | None = None,
                 compilation: Compilation | None = None, floor: float = 0.0):
        self.nlp = GridNlp(system, scheme, nodes, compilation or Compilation())
        self.layout, self.scheme = self.nlp.layout, scheme
        self._callbacks = _callbacks(self.nlp)  # IPOPT holds them by reference: keep them
        g, jac_g, hess_lag = self._callbacks
        x = ca.MX.sym("x", self.layout.size)
        p = ca.MX.sym("p", self.nlp.n_theta + 1)
        settings = ipopt_settings(tol, max_iter, verbose, time_limit,
                                  {**DEFAULT_OPTIONS, **ASSEMBLY_OPTIONS}, floor)
        settings.update({"jac_g": jac_g, "hess_lag": hess_lag, "no_nlp_grad": True,
                         "calc_lam_p": False})
        self.problem = FeasibilityNlp("bvp_grid", x, p, g(x, p), settings)

    def solve(self, x0: np.ndarray, ends: Ends, tau_floor: float,
              scales: EndScales) -> GridResult:
        """IPOPT from ``x0`` on the unknowns and rows divided by ``scales`` (`end_scales`), in
        the fields of a `GridResult` (its point in the raw unknowns)."""
        nlp = self.nlp
        nlp.scale(scales)
        lbx, ubx = pinned_bounds(self.layout, self.scheme, ends)
        steps = nlp.ng - nlp.kept.size
        lbg = np.r_[np.zeros(nlp.kept.size), np.full(steps, tau_floor / ends.energy_scale)]
        ubg = np.r_[np.zeros(nlp.kept.size), np.full(steps, np.inf)]
        for bound, size in ((lbx, nlp.x_sizes), (ubx, nlp.x_sizes), (lbg, nlp.row_sizes),
                            (ubg, nlp.row_sizes)):
            bound /= size  # in place: at N = 1e6 each copy is 24 MB held through the solve
        result = self.problem.solve(x0 / nlp.x_sizes, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg,
                                    p=np.concatenate([ends.theta, [ends.energy_scale]]))
        result.x = result.x * nlp.x_sizes
        nlp.forget()  # the last point's blocks: O(N) memory the cached problem need not hold
        return result
