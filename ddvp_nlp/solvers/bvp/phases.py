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
from ..grid.motion_size import motion_sizes
from ..grid.newton import newton
from ..grid.policy import Stage
from ..grid.problem import GridRequest
from ..grid.round_off import row_noise
from .ends_nlp import BvpIpopt, end_scales
from .interleaved import Ends, GridAssembly

EPS = np.finfo(float).eps
# Newton's target on each row was TARGET_ULPS round-offs of its magnitude, and the verification
# allowed ROUND_OFF_ALLOWANCE of them (module docstring of grid/newton.py; fixed_ends.py): the
# ratio of the two is kept (BOUNDS_ALLOWED, below).
TARGET_ULPS = 16
ROUND_OFF_ALLOWANCE = 1024


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


# Newton's target on a row: this many times that change (the residual Newton's last step leaves
# was 0.4-0.75 of it on Kepler's vddvp rows); the verification allows ROUND_OFF_ALLOWANCE /
# TARGET_ULPS of the target, as before.
NOISE_TARGET = 2.0
BOUNDS_ALLOWED = ROUND_OFF_ALLOWANCE // TARGET_ULPS


@dataclass(frozen=True)
class RowRoundOff:
    """Newton's target on each kind of row, unscaled (`row_round_offs`): ``canonical`` per
    canonical row ``(2n,)``, ``energy`` the energy row (0 for ``fixed``), ``pins`` the rows that
    pin a node to the data (an end position, an end time)."""

    canonical: np.ndarray
    energy: float
    pins: float
    pin_rows: np.ndarray | None = None  # (rows, targets) of each pin in its own units


def row_round_offs(request: GridRequest, x: np.ndarray, scheme: Scheme, grid=None,
                   data: Ends | None = None, base: np.ndarray | None = None) -> RowRoundOff:
    """Each kind of row's round-off near ``x``, in the row's own units: ``NOISE_TARGET`` times
    the largest change of the row over the grid when every unknown is moved by one unit in
    its last place (`grid.round_off.row_noise`), which is how far the rows' values are known at
    ``x``. It scales with the rows under any change of units and
    grows where a coordinate is offset or a constant is added to ``H``, as the round-off does,
    and it needs no floor of 1: with ``max(1, |q|, |p|, |t|)`` a pendulum in lengths of ``1e-8``
    had its canonical targets at ``eps`` times the end time, ``1e-6`` of its motion, and Newton
    stopped there (its solution ``1e-5`` off the one in lengths of 1). ``grid``, ``data``: the
    assembly of ``scheme`` and its data (default the request's); ``base``: its rows at ``x``,
    where already evaluated."""
    grid = assembly(request, scheme) if grid is None else grid
    data = ends(request, scheme) if data is None else data
    n, N, m = request.system.n, request.nodes, 2 * request.system.n + 1
    spread = row_noise(grid, x, data, base)
    body = spread[n + 1:n + 1 + (N - 1) * m].reshape(N - 1, m)
    pins = np.concatenate([spread[:n + 1], spread[n + 1 + (N - 1) * m:], body[-1:, 2 * n]])
    energy = 0.0
    if scheme.variable_steps and N > 2:
        energy = float(np.max(body[:-1, 2 * n])) * data.energy_scale
    else:
        pins = np.concatenate([pins, body[:, 2 * n]])
    return RowRoundOff(NOISE_TARGET * np.max(body[:, :2 * n], axis=0), NOISE_TARGET * energy,
                       NOISE_TARGET * float(np.max(pins, initial=0.0)),
                       _pin_rows(spread, x, n, N, scheme.variable_steps and N > 2))


def _pin_rows(spread: np.ndarray, x: np.ndarray, n: int, N: int, released: bool):
    """``(rows, targets)``: the pins' targets by kind, ``NOISE_TARGET`` times the largest
    change of the time pins' rows and of each coordinate's two end pins (never below eps times
    that column's largest magnitude): the pins of a time and of a position are in different
    units, and one target for all (their largest) held the end positions in lengths of
    ``1e-7`` to the round-off of times of ``1e4``, so a derivative check's move of an end was
    taken for converged before Newton's first step (its quotient 0: "disagrees")."""
    m = 2 * n + 1
    z = np.asarray(x, float).reshape(N, m)
    # a pin is known to the round-off of its column (a time, coordinate i) over the grid:
    # Newton's solve leaves it there, whatever row it pins
    column = np.finfo(float).eps * np.max(np.abs(z), axis=0)
    times = [N - 2] if released else list(range(N - 1))
    time_rows = np.array([0, *(n + 1 + k * m + 2 * n for k in times)])
    rows, targets = [time_rows], [np.full(time_rows.size, max(float(np.max(spread[time_rows])),
                                                              column[0]))]
    for i in range(n):
        pair = np.array([1 + i, N * m - n + i])  # q_0,i and q_end,i
        rows.append(pair)
        targets.append(np.full(2, max(float(np.max(spread[pair])), column[1 + i])))
    own = np.concatenate(targets)
    return np.concatenate(rows), NOISE_TARGET * np.maximum(own, np.finfo(float).tiny)


def canonical_sizes(system, scheme: Scheme, q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``(2n,)``: the motion's size in each canonical row's units (``Scheme``'s ``row_units``:
    the increment form has one block of positions and one of momenta, the discrete Legendre
    transform two of momenta), the largest range of a position, or of a momentum, over the
    nodes ``q``, ``p`` (``(N, n)``): what ``tol`` is relative to on every grid family's
    canonical rows."""
    ranges = {"q": float(np.max(np.ptp(q, axis=0))), "p": float(np.max(np.ptp(p, axis=0)))}
    units = equations.action_for(system, scheme).row_units
    return np.repeat([ranges[units[0]], ranges[units[1]]], np.shape(q)[1])


def newton_targets(request: GridRequest, grid: GridAssembly, x, data: Ends) -> np.ndarray:
    """Per-row ``|F_i|`` targets: each kind of row's round-off (`row_round_offs`; the energy
    rows in their scaled units)."""
    n, N, m = request.system.n, request.nodes, 2 * request.system.n + 1
    rows = row_round_offs(request, x, grid.scheme, grid, data)
    target = np.full(N * m, rows.pins)
    body = target[n + 1:n + 1 + (N - 1) * m].reshape(N - 1, m)
    body[:, :2 * n] = rows.canonical
    if grid.scheme.variable_steps:
        body[:-1, 2 * n] = rows.energy / data.energy_scale
    pinned, own = rows.pin_rows
    target[pinned] = own
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


def ipopt_scales(request: GridRequest, x: np.ndarray, scheme: Scheme, data: Ends):
    """``(scales, floor)``: what IPOPT's unknowns and rows are divided by
    (`ends_nlp.end_scales`: the span and each coordinate's range over the nodes ``x``, the
    rows' sizes read off the Jacobian there) and the round-off of the scaled rows near ``x``,
    the largest of Newton's targets over its row's size (`row_round_offs`), rounded up to two
    digits so that nearby starts share a built problem: IPOPT's tolerance is one number for
    every row, so it is only the same in any units on rows of one scale."""
    grid = assembly(request, scheme)
    n, N, m = request.system.n, request.nodes, 2 * request.system.n + 1
    z = np.asarray(x, float).reshape(N, m)
    span = float(np.ptp(z[:, 0]))
    sizes = np.r_[span, motion_sizes(request.system, request.theta, z[:, 0], z[:, 1:],
                                     span / (2 * np.pi))]
    sizes = np.where(sizes > 0, sizes, np.nan)
    _, blocks = grid.evaluate(x, data, jacobian=True)
    scales = end_scales(grid.layout, grid.banded(blocks), sizes, data.energy_scale)
    grid.release()
    rows = row_round_offs(request, x, scheme, grid, data)
    scaled = np.asarray(rows.canonical, float) / scales.rows[:2 * n]
    floor = float(np.max(scaled, initial=0.0))
    if scheme.variable_steps:
        floor = max(floor, rows.energy / data.energy_scale / scales.rows[2 * n])
    floor = max(floor, np.finfo(float).tiny)
    digits = 10.0 ** (np.floor(np.log10(floor)) - 1)
    return scales, float(np.ceil(floor / digits) * digits)


def _ipopt(request: GridRequest, scheme: Scheme, x0: np.ndarray, data: Ends):
    """IPOPT's solve of the system of ``scheme`` from ``x0``, on unknowns and rows scaled by
    their sizes (`ipopt_scales`): the request's own system to ``tol`` (but not below the rows'
    round-off), a start phase to that round-off. Before a released problem is built the
    fixed-step ones are dropped from the cache: at N = 1e6 the fixed-step one held about 3 GB
    while the released one was built (measured)."""
    remaining = request.remaining()
    compilation = request.compilation
    scales, floor = ipopt_scales(request, x0, scheme, data)
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
    return problem.solve(x0, data, request.tau_floor, scales)


def _reporter(name: str):
    def report(iteration, norm, alpha):
        print(f"bvp [{name}]: iteration {iteration}, |F| = {norm:.3e}, step {alpha:.3g}",
              file=sys.stderr, flush=True)
    return report
