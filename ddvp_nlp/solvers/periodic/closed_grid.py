"""The periodic system of a closed grid, assembled node by node: residual and sparse Jacobian.

Unknowns, interleaved by node, then the unfolding parameters: ``x = (z_0, z_1, ..., z_N, u)``
with ``z_k = (t_k, q_k, p_k)`` (``m = 2n + 1`` values per node) and ``u = (lambda, mu_1, ..,
mu_r)``, one per first integral (``H``, then the ``r`` integrals of the symmetries given):
``(N+1) m + 1 + r`` in all. Equations, in the same order::

    t_0,  z_0[section] - value                                       (2 rows)
    g_i . (z_0 - z_0^ref) for each integral I_i, g_i = J grad I_i    (r rows)
    for k = 0 .. N-1:  canonical equations of interval k,            (2n rows)
                       unfolded by tau_k (lambda grad H + sum mu_i grad I_i)(Q_k, P_k)
                       H(Q_k, P_k) - E                               (1 row)
    q_N - q_0 - 2 pi w,  p_N - p_0   (w: turns of angle coordinates)  (2n rows)

``2 + r + N m + 2n = (N+1) m + 1 + r`` rows: square. Why these rows, and why the unfolding, is
the docstring of ``orbit.py``. The interval rows are ``equations.canonical_expression`` and
``equations.midpoint_energy_function``'s expression, written once in ``discrete/``; each interval
becomes one CasADi function returning its ``m`` rows and their dense Jacobian in
``(z_k, z_{k+1}, u)``, mapped over the grid by ``grid/maps.ChunkedMap``. The closure rows
put entries in the corner (columns of ``z_0``) and each unfolding parameter is a full column:
the matrix is factored by sparse LU (SuperLU), not in band storage. `PeriodicAssembly`
is a ``grid.problem.GridProblem`` (its data a `Closure`): the grid's Newton and its
IPOPT build take it as they take the fixed-endpoint assembly."""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ...cache import cached
from ...discrete import equations
from ...discrete.scheme import Scheme
from ...solution import Status
from ..grid.maps import chunked
from ..grid.motion_size import energy_rate
from ..grid.newton import newton
from ..grid.policy import Stage, failure_status
from ..grid.round_off import row_noise

EPS = float(np.finfo(float).eps)


def closed_newton(grid, x0, closure, request, target: np.ndarray):
    """The grid's sparse Newton on a closed grid (an orbit, constrained or not) from ``x0``,
    every row to its ``target`` (per row: `closed_targets`), within ``request``'s step floor,
    iterations and deadline; its outcome named ``newton: ...``."""
    result = newton(grid, x0, closure, target, tau_floor=request.tau_floor,
                    max_iter=request.max_iter, linear="sparse", deadline=request.deadline,
                    unknown_sizes="columns")
    result.outcome = f"newton: {result.outcome}"
    return result


# Newton's target on a row of a closed grid: this many times the row's change under a move of
# every unknown by one unit in its last place (`closed_targets`, as fixed ends'
# ``bvp/phases.NOISE_TARGET``); the verification allows BOUNDS_ALLOWED targets (the ratio of
# the allowance to the target when both were round-offs of max(1, |x|, |E|): 4096 and 64). The
# orbit solves, constrained or not, and their derivatives' solves share them.
NOISE_TARGET = 2.0
BOUNDS_ALLOWED = 64


def closed_targets(grid, x: np.ndarray, closure, sizes: np.ndarray) -> np.ndarray:
    """Per-row Newton targets of an orbit's closed grid (`PeriodicAssembly`) near ``x``, in
    each row's own units: ``NOISE_TARGET`` times the largest change of each kind of row (the
    canonical rows of each coordinate, the energy rows, the closure row of each coordinate)
    when every unknown moves by one unit in its last place (`grid.round_off.row_noise`), and
    never below the round-off of what the row measures (a row that is exactly 0 at ``x``, the
    ``t_0`` row at ``t_0 = 0`` or a section through the origin, changes by nothing): ``eps``
    times the size of the motion in its coordinate (``sizes``, ``(2n,)``:
    `grid.motion_size.motion_sizes`; the period for ``t_0``). No floor of 1: with targets of 64
    round-offs of ``max(1, |x|, |E|)`` a swing in lengths of ``1e-8`` stopped Newton at ``1e-6``
    of its size (its period ``1e-7`` off the one in lengths of 1)."""
    layout = grid.layout
    N, m, n, h = layout.intervals, layout.m, layout.n, grid.header
    noise = row_noise(grid, x, closure)
    z = np.asarray(x[:(N + 1) * m], float).reshape(N + 1, m)
    span = EPS * np.r_[np.ptp(z[:, 0]), sizes]  # (t, q, p)
    body = noise[h:h + N * m].reshape(N, m)
    target = np.empty_like(noise)
    target[0] = max(noise[0], span[0])
    target[1] = max(noise[1], span[closure.section_index])
    if h > 2:
        target[2:h] = np.maximum(noise[2:h], np.abs(closure.generators) @ span[1:])
    rows = target[h:h + N * m].reshape(N, m)
    rows[:, :2 * n] = np.maximum(np.max(body[:, :2 * n], axis=0), span[1:])
    rows[:, 2 * n] = max(float(np.max(body[:, 2 * n])), EPS * abs(closure.energy),
                         np.finfo(float).tiny)
    target[h + N * m:] = np.maximum(noise[h + N * m:], span[1:])
    # a degenerate start (all nodes one point) has rows with nothing to measure: never 0
    return NOISE_TARGET * np.maximum(target, np.finfo(float).tiny)


def closed_limits(grid, x: np.ndarray, closure, targets: np.ndarray, tol: float,
                  sizes: np.ndarray) -> dict:
    """The largest residual each row of an orbit may have and pass, by kind (the keys of the
    verification's residuals; arrays per coordinate for ``canonical`` and ``closure``): ``tol``
    relative to what the row measures, or ``BOUNDS_ALLOWED`` times its Newton target,
    whichever is larger:

    - a canonical or closure row of a coordinate: ``tol`` times the orbit's size in that
      coordinate (``sizes``: `grid.motion_size.motion_sizes`; the section's row: its
      coordinate's);
    - an energy row (the scheme's energy equations, and ``H_0 - E``): ``tol`` times the mean
      step times the rate at which the orbit trades energy, ``sum_i max |dq_i/dt| max
      |dp_i/dt|`` read off the nodes (as fixed ends', ``bvp/fixed_ends.verification_limits``).

    Every scale is the orbit's: the limits follow the rows under a change of units of length,
    momentum or time and a shift of the origin."""
    layout = grid.layout
    N, m, n, h = layout.intervals, layout.m, layout.n, grid.header
    z = np.asarray(x[:(N + 1) * m], float).reshape(N + 1, m)
    span = np.r_[np.ptp(z[:, 0]), sizes]
    body = targets[h:h + N * m].reshape(N, m)
    energy = max(tol * abs(z[-1, 0] - z[0, 0]) / N * energy_rate(z[:, 0], z[:, 1:]),
                 BOUNDS_ALLOWED * float(body[0, 2 * n]))
    return {"canonical": np.maximum(tol * span[1:], BOUNDS_ALLOWED * body[0, :2 * n]),
            "energy": energy, "prescribed_energy": energy,
            "closure": np.maximum(tol * span[1:], BOUNDS_ALLOWED * targets[h + N * m:]),
            "section": max(tol * span[closure.section_index], BOUNDS_ALLOWED * targets[1])}


def closed_verdict(result, worst: dict, limits: dict, tau: np.ndarray, note=None, *,
                   found: str = "periodic orbit"):
    """A closed grid's status and message from its largest residuals (``worst``, by row
    family) against their ``limits`` (one per family: `grid.policy.worst_against`) and its
    steps ``tau``; the solver's word is quoted, with ``note`` (the start's) after it."""
    listed = ", ".join(f"{name} {value:.3e} (limit {limits[name]:.1e})"
                       for name, value in worst.items())
    said = result.outcome + (f"; {note}" if note else "")
    if not all(np.isfinite(v) for v in worst.values()):
        return Status.NON_FINITE, f"the iteration produced non-finite values ({said})"
    if np.min(tau) <= 0:
        k = int(np.argmin(tau))
        return Status.NO_ADMISSIBLE_STEP, f"step {k} is not positive: tau = {tau[k]:.6g} ({said})"
    failed = [name for name, value in worst.items() if value > limits[name]]
    if not failed:
        return Status.SUCCESS, f"{found} found and verified: largest residuals {listed}; {said}"
    detail = f"largest residuals {listed}, above it: {', '.join(failed)}"
    status = failure_status(Stage("periodic orbit", "", result.converged, result.outcome), tau)
    if status is Status.SOLVER_FAILED:
        return status, f"no periodic orbit found: {detail} ({said})"
    return status, f"{status.value}: {detail} ({said})"


@dataclass(frozen=True)
class ClosedLayout:
    """Node ``k``'s ``(t, q, p)`` at ``x[k m:(k+1) m]`` for ``k = 0 .. N``; then the unfolding
    parameters ``u = (lambda, mu_1, ..., mu_r)``, one per first integral (``H`` first)."""

    n: int
    intervals: int
    integrals: int = 0

    @property
    def m(self) -> int:
        return 2 * self.n + 1

    @property
    def nodes(self) -> int:
        return self.intervals + 1

    @property
    def unfoldings(self) -> int:
        return 1 + self.integrals

    @property
    def size(self) -> int:
        return self.nodes * self.m + self.unfoldings

    @property
    def bandwidth(self) -> int:
        """Wider than any band: tells the grid's Newton to factor the sparse matrix."""
        return self.size

    def pack(self, t, q, p) -> np.ndarray:
        return np.concatenate([np.column_stack([np.asarray(t, float), q, p]).ravel(),
                               np.zeros(self.unfoldings)])

    def unpack(self, x):
        """``(t, q, p, u)`` (copies) from ``x``."""
        z = np.asarray(x[:self.nodes * self.m], float).reshape(self.nodes, self.m)
        return (z[:, 0].copy(), z[:, 1:self.n + 1].copy(), z[:, self.n + 1:].copy(),
                np.array(x[self.nodes * self.m:], float))

    def time_index(self) -> np.ndarray:
        return np.arange(self.nodes) * self.m


@dataclass(frozen=True)
class Closure:
    """The data of one periodic problem: the prescribed energy, the section (index into
    ``z = (t, q, p)`` of a node and value), the parameters, and for each first integral the
    reference node ``z_0^ref = (q, p)`` and symmetry generator ``g_i = J grad I_i(z_0^ref)`` of
    its phase condition ``g_i . (z_0 - z_0^ref) = 0``; ``shift`` (``2n``,) is ``z_N - z_0`` on
    the orbit: ``2 pi w_i`` for an angle coordinate that turns ``w_i`` times (a rotation), else
    0."""

    energy: float
    section_index: int
    section_value: float
    theta: np.ndarray
    reference: np.ndarray = field(default_factory=lambda: np.zeros(0))
    generators: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    shift: np.ndarray | float = 0.0
    # the unfolding's metric (`unfolding_metric`); None: ones
    metric: np.ndarray | None = None

    def unfolding_metric(self, n: int) -> np.ndarray:
        """``(2n,)``: the metric ``G`` of the unfolding terms ``tau G grad I u``, ones if none
        was given."""
        return np.ones(2 * n) if self.metric is None else np.asarray(self.metric, float)


def unfolding_metric(weights: np.ndarray, period: float) -> np.ndarray | None:
    """``G_i = (T / 2 pi) / W_i^2`` (`interval_rows`): ``W`` the symplectic weights of the
    orbit's start (`physics.hamiltonian.symplectic_weights`: in ``W z`` every coordinate has
    one unit, that of the square root of an action) and ``T`` the period; ``None`` (ones)
    where a weight or the period is not positive. A harmonic oscillator of unit frequency and
    mass gets ones, the plain unfolding."""
    weights = np.asarray(weights, float)
    if not (np.all(np.isfinite(weights)) and np.all(weights > 0) and period > 0):
        return None
    return period / (2 * np.pi) / weights ** 2


def integral_gradients(system, integrals) -> ca.Function:
    """``(q, p, theta) -> [grad H, grad I_1, ..., grad I_r]`` (``2n x (1 + r)``), gradients in
    ``z = (q, p)``; ``integrals`` are functions ``I(q, p)`` on CasADi symbols."""
    def build():
        z = ca.vertcat(system.q, system.p)
        columns = [ca.gradient(system.H, z)]
        for integral in integrals:
            columns.append(ca.gradient(integral(system.q, system.p), z))
        return ca.Function("integral_gradients", [system.q, system.p, system.theta],
                           [ca.horzcat(*columns)])
    return cached(system, ("periodic_gradients", tuple(integrals)), build)


def interval_rows(system, scheme: Scheme, integrals) -> ca.Function:
    """``(z_a, z_b, u, E, G, theta) -> rows (m,)`` of one interval, with ``u`` the unfolding
    parameters ``(lambda, mu_1, ..., mu_r)`` and ``G`` (``2n``) the metric of the unfolding
    terms: the Newton assembly differentiates it into blocks, the IPOPT problem
    (``orbit_nlp.py``) maps it over the grid. The unfolding terms are ``tau G grad I_i u_i``:
    a plain ``tau grad H lambda`` needs ``lambda`` in the units of ``q^2 / (E t)`` in a
    position's row and of ``p^2 / (E t)`` in a momentum's, so its column changed its shape
    with the time unit (IPOPT, scaled, then took another path); with ``G_i = (T / 2 pi) /
    W_i^2`` (`unfolding_metric`) every ``u_i`` has one unit. At an orbit ``u = 0``, whatever
    ``G``."""
    def build():
        n, r = system.n, len(integrals)
        z_a, z_b = ca.SX.sym("z_a", 2 * n + 1), ca.SX.sym("z_b", 2 * n + 1)
        unfolding, level = ca.SX.sym("u", 1 + r), ca.SX.sym("E")
        metric = ca.SX.sym("G", 2 * n)
        t_a, q_a, p_a = z_a[0], z_a[1:n + 1], z_a[n + 1:]
        t_b, q_b, p_b = z_b[0], z_b[1:n + 1], z_b[n + 1:]
        theta = system.theta
        canonical = equations.canonical_expression(system, scheme, t_a, t_b, q_a, p_a, q_b,
                                                   p_b, theta)
        energy = equations.midpoint_energy_function(system, scheme)(t_a, t_b, q_a, p_a, q_b,
                                                                    p_b, theta)
        Q = scheme.alpha * q_a + scheme.beta * q_b
        P = scheme.alpha * p_b + scheme.beta * p_a
        # The unfolding: increments z_b - z_a = tau (J grad H + lambda grad H + sum mu_i
        # grad I_i)(Q, P); the canonical rows are q_b - q_a - tau H_p and p_b - p_a + tau H_q.
        gradients = integral_gradients(system, integrals)(Q, P, theta)
        unfolded = metric * ca.mtimes(gradients, unfolding)
        rows = ca.vertcat(canonical - (t_b - t_a) * unfolded, energy - level)
        return ca.Function("periodic_rows", [z_a, z_b, unfolding, level, metric, theta],
                           [rows])
    return cached(system, ("periodic_rows", scheme, tuple(integrals)), build)


def _parameter_function(system, scheme: Scheme, integrals) -> ca.Function:
    """``(z_a, z_b, u, E, G, theta) -> d rows / d theta`` (``m x len(theta)``), from the same
    rows as `_interval_function`."""
    def build():
        rows = interval_rows(system, scheme, integrals)
        z_a, z_b, unfolding, level, metric, theta = rows.sx_in()
        expression = rows(z_a, z_b, unfolding, level, metric, theta)
        return ca.Function("periodic_theta", [z_a, z_b, unfolding, level, metric, theta],
                           [ca.densify(ca.jacobian(expression, theta))])
    return cached(system, ("periodic_theta", scheme, tuple(integrals)), build)


def _interval_function(system, scheme: Scheme, integrals) -> ca.Function:
    """``(z_a, z_b, u, E, G, theta) -> (rows (m,), d rows / d(z_a, z_b, u))``."""
    def build():
        rows = interval_rows(system, scheme, integrals)
        z_a, z_b, unfolding, level, metric, theta = rows.sx_in()
        expression = rows(z_a, z_b, unfolding, level, metric, theta)
        unknowns = ca.vertcat(z_a, z_b, unfolding)
        return ca.Function("periodic_interval", [z_a, z_b, unfolding, level, metric, theta],
                           [expression, ca.densify(ca.jacobian(expression, unknowns))])
    return cached(system, ("periodic_interval", scheme, tuple(integrals)), build)


class PeriodicAssembly:
    """``F(x)`` and ``F'(x)`` of one system, scheme, interval count and set of integrals
    (module docstring); the problem's data (a `Closure`) comes with each evaluation."""

    def __init__(self, system, scheme: Scheme, intervals: int, integrals=()):
        self.layout = ClosedLayout(system.n, intervals, len(integrals))
        self.scheme = scheme
        self._interval = chunked(system, ("periodic_interval", scheme, tuple(integrals)),
                                 _interval_function(system, scheme, tuple(integrals)))
        self._pattern = self._sparsity()
        self._theta_rows = _parameter_function(system, scheme, tuple(integrals))

    @property
    def header(self) -> int:
        """Rows before the intervals': ``t_0``, the section, one phase row per integral."""
        return 2 + self.layout.integrals

    def evaluate(self, x: np.ndarray, closure: Closure, jacobian: bool = True):
        """``F(x)`` and, if asked, the Jacobian: the interval blocks ``(N, 2m + 1 + r, m)``
        with the problem data its constant rows need (``(blocks, closure)``)."""
        N, m, h = self.layout.intervals, self.layout.m, self.header
        z = np.ascontiguousarray(x[:(N + 1) * m], float).reshape(N + 1, m)
        unfolding = np.tile(x[(N + 1) * m:], (N, 1))
        level = np.full((N, 1), closure.energy)
        metric = np.tile(closure.unfolding_metric(self.layout.n), (N, 1))
        rows, J = self._interval([z[:-1], z[1:], unfolding, level, metric], closure.theta, N)
        F = np.empty(self.layout.size)
        F[0] = z[0, 0]
        F[1] = z[0, closure.section_index] - closure.section_value
        F[2:h] = closure.generators @ (z[0, 1:] - closure.reference) if h > 2 else 0.0
        F[h:h + N * m] = rows[:, 0, :].ravel()
        F[h + N * m:] = z[N, 1:] - z[0, 1:] - closure.shift
        return F, ((J, closure) if jacobian else None)

    def release(self) -> None:
        """Nothing to drop: the blocks are the evaluation's own arrays."""

    def parameter_jacobian(self, x: np.ndarray, closure: Closure) -> sp.csc_matrix:
        """``dF/dtheta`` at ``x`` (``(size, len(theta))``, sparse), differentiated from the same
        interval rows as `evaluate`'s ``F``; the constant rows (``t_0``, section, phase,
        closure) do not depend on ``theta``."""
        N, m, h = self.layout.intervals, self.layout.m, self.header
        z = np.ascontiguousarray(x[:(N + 1) * m], float).reshape(N + 1, m)
        unfolding = np.tile(x[(N + 1) * m:], (N, 1))
        level = np.full((N, 1), closure.energy)
        theta = np.asarray(closure.theta, float).ravel()
        if theta.size == 0:
            return sp.csc_matrix((self.layout.size, 0))
        mapped = self._theta_rows.map(N)
        metric = np.tile(closure.unfolding_metric(self.layout.n)[:, None], (1, N))
        values = np.asarray(mapped(z[:-1].T, z[1:].T, unfolding.T, level.T, metric, theta))
        blocks = values.reshape(m, N, theta.size).transpose(1, 0, 2)
        dense = np.zeros((self.layout.size, theta.size))
        dense[h:h + N * m] = blocks.reshape(N * m, theta.size)
        return sp.csc_matrix(dense)

    def residuals(self, F: np.ndarray):
        """``(canonical (N, 2n), energy (N,), closure (2n,))`` in ``F`` (unscaled)."""
        N, m, n, h = self.layout.intervals, self.layout.m, self.layout.n, self.header
        body = F[h:h + N * m].reshape(N, m)
        return body[:, :2 * n].copy(), body[:, 2 * n].copy(), F[h + N * m:].copy()

    def _sparsity(self):
        """Rows and columns of the interval blocks' entries, in the order of their values
        (``N (2m + u) m``, ``u`` unfolding parameters)."""
        N, m, h = self.layout.intervals, self.layout.m, self.header
        u = self.layout.unfoldings
        k = np.arange(N)[:, None, None]
        column = np.arange(2 * m + u)[None, :, None]
        row = np.arange(m)[None, None, :]
        first_unfolding = (N + 1) * m
        rows = np.broadcast_to(h + k * m + row, (N, 2 * m + u, m))
        cols = np.broadcast_to(np.where(column < 2 * m, k * m + column,
                                        first_unfolding + column - 2 * m), (N, 2 * m + u, m))
        return rows.ravel(), cols.ravel()

    def sparse(self, jacobian) -> sp.csc_matrix:
        """The Jacobian as a sparse matrix: the interval blocks, then the constant rows
        (``t_0``, section, phase conditions, closure) of the problem the evaluation was of."""
        blocks, closure = jacobian
        N, m, h = self.layout.intervals, self.layout.m, self.header
        rows, cols = self._pattern
        closing = h + N * m + np.arange(m - 1)
        r = self.layout.integrals
        phase_rows = np.repeat(2 + np.arange(r), m - 1)
        phase_cols = np.tile(1 + np.arange(m - 1), r)
        fixed_rows = np.concatenate([[0, 1], phase_rows, closing, closing])
        fixed_cols = np.concatenate([[0, closure.section_index], phase_cols,
                                     N * m + 1 + np.arange(m - 1), 1 + np.arange(m - 1)])
        fixed_values = np.concatenate([[1.0, 1.0], np.ravel(closure.generators),
                                       np.ones(m - 1), -np.ones(m - 1)])
        size = self.layout.size
        return sp.csc_matrix((np.concatenate([np.asarray(blocks).ravel(), fixed_values]),
                              (np.concatenate([rows, fixed_rows]),
                               np.concatenate([cols, fixed_cols]))), (size, size))
