"""One solve of the fixed-endpoint system by one solver: the unit the starts and the final
solve are made of (``fixed_ends.py``, ``first_guess.py``).

The inputs of a ``solve_bvp`` call are a `GridRequest`
whose ``data`` is a `Boundary`; `run_phase` solves the system of a scheme (the
user's, or ``fixed`` on given times for the start) from a point, by the grid's Newton
(``grid/newton.py``) or IPOPT (``ends_nlp.py`` on ``grid/ipopt.py``), and records what the solver
said. The built problems are cached per system (``GridRequest.built``), their build time
counted apart.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numpy as np

from ...discrete import equations
from ...discrete.scheme import Scheme
from ..grid.linear import band_kernel
from ..grid.newton import newton
from ..grid.policy import Stage
from ..grid.problem import GridRequest
from .ends_nlp import BvpIpopt
from .interleaved import Ends, GridAssembly

EPS = np.finfo(float).eps
# Newton's target on a row whose round-off is known by its magnitude (a pin, a row whose
# expression cannot be walked): this many units of it (module docstring of grid/newton.py);
# verification allows ROUND_OFF_ALLOWANCE of them (fixed_ends.py). A row whose running error
# bound is known (`row_round_offs`) has that bound, already a sum over its every operation, as
# its target, and BOUNDS_ALLOWED of it in the verification: the same ratio.
TARGET_ULPS = 16
ROUND_OFF_ALLOWANCE = 1024
BOUNDS_ALLOWED = ROUND_OFF_ALLOWANCE // TARGET_ULPS


@dataclass
class Boundary:
    """The data of a fixed-endpoint problem: the end positions and times, the node times of
    the ``fixed`` rule, and the momentum shooting starts from (``guess="march"``)."""

    q_start: np.ndarray
    q_end: np.ndarray
    t0: float
    t1: float
    grid_times: np.ndarray
    p_start: np.ndarray | None = None


def mean_step(request: GridRequest[Boundary]) -> float:
    return (request.data.t1 - request.data.t0) / (request.nodes - 1)


def ends(request: GridRequest[Boundary], scheme: Scheme, times=None) -> Ends:
    """The data of the system of ``scheme``: for ``fixed``, on ``times`` (default the
    request's grid)."""
    data = request.data
    if scheme.variable_steps:
        return Ends(data.q_start, data.q_end, np.array([data.t0, data.t1]), request.theta,
                    mean_step(request))
    return Ends(data.q_start, data.q_end,
                data.grid_times if times is None else np.asarray(times, float),
                request.theta, 1.0)


def assembly(request: GridRequest, scheme: Scheme) -> GridAssembly:
    compilation = request.compilation
    return request.built(("bvp_assembly", scheme, request.nodes, compilation.compiler,
                          str(compilation.cache_dir)),
                         lambda: GridAssembly(request.system, scheme, request.nodes,
                                              compilation))


# Intervals at which each row's round-off is read (`row_round_offs`): this many evenly spaced,
# and those of the largest state, the fastest motion and the shortest step.
ROUND_OFF_SAMPLES = 32


@dataclass(frozen=True)
class RowRoundOff:
    """Each row's round-off bound in units of ``eps`` (`row_round_offs`): ``canonical`` per
    canonical row ``(2n,)``, ``energy`` the unscaled energy row, ``pins`` the rows that pin a
    node to the data (an end position, an end time: ``TARGET_ULPS`` of their magnitude)."""

    canonical: np.ndarray
    energy: float
    pins: float


def row_round_offs(request: GridRequest, x: np.ndarray, scheme: Scheme) -> RowRoundOff:
    """Each row's round-off near ``x``, in units of ``eps`` and in the row's own units: the
    running error bound of the row's expression (`physics.roundoff.roundoff_bound`) at sampled
    intervals (`ROUND_OFF_SAMPLES`, with those of the largest state, the fastest motion and the
    shortest step), the largest per row. It scales with the rows under any change of units and
    grows where a coordinate is offset or a constant is added to ``H``, as the round-off does;
    no floor of 1 (a pendulum in lengths of ``1e-8`` had its rows' targets at ``eps`` times the
    end time, ``1e-6`` of its motion, and its energy rows' at ``eps``, ``1e17`` times its
    energy). Where a row's expression has an operation without a scalar rule, the magnitudes of
    its terms instead (`_row_magnitudes`)."""
    n, N = request.system.n, request.nodes
    z = x.reshape(N, 2 * n + 1)
    pins = TARGET_ULPS * float(np.max(np.abs(z[[0, -1]]), initial=0.0))
    bounds = _row_bounds(request.system, scheme)
    if bounds is None or not np.all(np.isfinite(z)):
        return _row_magnitudes(request, z, scheme, pins)
    canonical_rows, energy_row = bounds
    theta = np.asarray(request.theta, float).ravel()
    k = _sampled_intervals(z)
    canonical = np.array([max(row(z[j], z[j + 1], theta) for j in k) if row is not None
                          else 0.0 for row in canonical_rows])
    energy = 0.0
    if energy_row is not None and N > 2:
        energy = max(energy_row(z[j], z[j + 1], z[j + 2], theta)
                     for j in np.minimum(k, N - 3))
    return RowRoundOff(canonical, float(energy), pins)


def _sampled_intervals(z: np.ndarray) -> np.ndarray:
    """Evenly spaced intervals and those of the largest ``|z|``, the largest ``|dz| / tau``
    and the shortest step."""
    N = z.shape[0]
    tau = np.diff(z[:, 0])
    speed = np.max(np.abs(np.diff(z[:, 1:], axis=0)), axis=1) / np.where(tau != 0, np.abs(tau),
                                                                         np.inf)
    extremes = [min(int(np.argmax(np.max(np.abs(z), axis=1))), N - 2), int(np.argmax(speed)),
                int(np.argmin(np.abs(tau)))]
    spread = np.linspace(0, N - 2, min(N - 1, ROUND_OFF_SAMPLES)).astype(int)
    return np.unique(np.concatenate([spread, extremes]))


def _row_bounds(system, scheme: Scheme):
    """``(canonical, energy)``: the running error bound of each canonical row as a callable of
    ``(z_a, z_b, theta)`` (``None`` for a row that is structurally zero) and of the energy row
    of ``(z_prev, z_mid, z_next, theta)`` (``None`` for ``fixed``), built once per system and
    scheme; ``None`` where an operation has no scalar rule."""
    import casadi as ca

    from ...cache import cached
    from ...physics.roundoff import roundoff_bound
    from .interleaved import node_expressions

    def build():
        z, r, e = node_expressions(system, scheme)
        theta = system.theta
        try:
            canonical = [roundoff_bound(ca.Function(f"row_{i}", [z[0], z[1], theta], [r[i]]),
                                        (0, 1)) if r[i].nnz() else None
                         for i in range(r.numel())]
            energy = None if e is None else roundoff_bound(
                ca.Function("energy_row", [z[0], z[1], z[2], theta], [e]), (0, 1, 2))
        except ValueError:
            return None
        return canonical, energy
    return cached(system, ("bvp_row_round_off", scheme), build)


def _row_magnitudes(request: GridRequest, z: np.ndarray, scheme: Scheme,
                    pins: float) -> RowRoundOff:
    """``TARGET_ULPS`` of the rows' magnitudes where their expressions cannot be walked: a
    canonical row's ``|z|`` at its nodes plus the end time's magnitude times its rate of change
    (a step's round-off carried by the field), an energy row's ``|E_k|`` plus
    ``|q| |H_q| + |p| |H_p|`` (the march's energy magnitude, `acceptance.start_values`), from
    the nodes."""
    n = request.system.n
    finite = z[np.all(np.isfinite(z), axis=1)]
    if finite.shape[0] < 2:
        return RowRoundOff(np.zeros(2 * n), 0.0, pins)
    tau = np.diff(finite[:, 0])
    rate = np.abs(np.diff(finite[:, 1:], axis=0)) / np.where(tau != 0, np.abs(tau),
                                                             np.inf)[:, None]
    size = np.max(np.abs(finite[:, 1:]), axis=0)
    times = float(np.max(np.abs(finite[:, 0])))
    canonical = 2 * size + 2 * times * np.max(rate, axis=0)
    energy = 0.0
    if scheme.variable_steps:
        E = equations.interval_energies(request.system, scheme, finite[:, 0],
                                        finite[:, 1:n + 1], finite[:, n + 1:], request.theta)
        flow = np.max(rate, axis=0)
        energy = float(np.max(np.abs(E), initial=0.0)
                       + np.sum(size[:n] * flow[n:] + size[n:] * flow[:n]))
    return RowRoundOff(TARGET_ULPS * canonical, TARGET_ULPS * energy, pins)


def newton_targets(request: GridRequest, grid: GridAssembly, x, data: Ends) -> np.ndarray:
    """Per-row ``|F_i|`` targets: each row's round-off bound (`row_round_offs`; the energy
    rows in their scaled units)."""
    n, N, m = request.system.n, request.nodes, 2 * request.system.n + 1
    rows = row_round_offs(request, x, grid.scheme)
    target = np.full(N * m, EPS * rows.pins)
    body = target[n + 1:n + 1 + (N - 1) * m].reshape(N - 1, m)
    body[:, :2 * n] = EPS * rows.canonical
    if grid.scheme.variable_steps:
        body[:-1, 2 * n] = EPS * rows.energy / data.energy_scale
    return target


def run_phase(request: GridRequest, scheme: Scheme, x0: np.ndarray, name: str, solver: str,
              times=None):
    """``(x, stage)``: the system of ``scheme`` solved from ``x0`` by ``solver``; the `Stage`
    records the solver's own verdict (``converged``, what it said, ``iterations``)."""
    data = ends(request, scheme, times)
    started = time.perf_counter()
    if solver == "newton":
        grid = assembly(request, scheme)
        result = newton(grid, x0, data, newton_targets(request, grid, x0, data),
                        tau_floor=request.tau_floor if scheme.variable_steps else -np.inf,
                        max_iter=request.max_iter, linear=request.linear,
                        kernel=band_kernel(request.compilation), deadline=request.deadline,
                        progress=_reporter(name) if request.progress else None)
    else:
        result = _ipopt(request, scheme, x0, data)
    x, converged, said, iterations = (result.x, result.converged, result.outcome,
                                      result.iterations)
    stage = Stage(name, solver, converged, said, iterations, time.perf_counter() - started)
    request.phases.append(stage)
    return x, stage


def ipopt_floor(request: GridRequest, x: np.ndarray, scheme: Scheme, data: Ends) -> float:
    """The round-off of the rows IPOPT sees near ``x``, the largest bound
    (`row_round_offs`: the canonical rows' and, for energy rules, the energy rows' divided by
    the energy scale, the mean step; 1e-11 at N = 1e6 on the pendulum), rounded up to two
    digits so that nearby starts share a built problem."""
    rows = row_round_offs(request, x, scheme)
    floor = EPS * max(float(np.max(rows.canonical, initial=0.0)), rows.pins,
                                    rows.energy / data.energy_scale, np.finfo(float).tiny)
    digits = 10.0 ** (np.floor(np.log10(floor)) - 1)
    return float(np.ceil(floor / digits) * digits)


def _ipopt(request: GridRequest, scheme: Scheme, x0: np.ndarray, data: Ends):
    """IPOPT's solve of the system of ``scheme`` from ``x0``: the request's own system to
    ``tol`` (but not below the rows' round-off, `ipopt_floor`), a start phase to that
    round-off. Before a released problem is built the fixed-step ones are
    dropped from the cache: at N = 1e6 the fixed-step one held about 3 GB while the released
    one was built (measured)."""
    remaining = request.remaining()
    compilation = request.compilation
    floor = ipopt_floor(request, x0, scheme, data)
    # A start phase (another scheme than the request's: fixed steps) ends where Newton's does,
    # at its rows' round-off: at 1e-2 tol = 1e-11 IPOPT took the predicted times' start as it
    # came at N = 1e6 (0 iterations), the released rows were then 2.5e-12 off, above the
    # verification, and one IPOPT iteration on them cost 38 s and 7.9 GB (measured).
    tol = request.tol if scheme == request.scheme else floor
    if scheme.variable_steps:
        request.forget(lambda key: key[0] == "bvp_ipopt" and key[1] != scheme)
    problem = request.built(("bvp_ipopt", scheme, request.nodes, request.max_iter,
                             tol, floor, request.verbose, remaining, compilation),
                            lambda: BvpIpopt(request.system, scheme, request.nodes,
                                             tol=tol, max_iter=request.max_iter,
                                             verbose=request.verbose or request.progress,
                                             time_limit=remaining, compilation=compilation,
                                             floor=floor))
    return problem.solve(x0, data, request.tau_floor)


def _reporter(name: str):
    def report(iteration, norm, alpha):
        print(f"bvp [{name}]: iteration {iteration}, |F| = {norm:.3e}, step {alpha:.3g}",
              file=sys.stderr, flush=True)
    return report
