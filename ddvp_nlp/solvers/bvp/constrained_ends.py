"""Fixed ends of a constrained system: ``solve_bvp`` hands a system with ``constraints=`` here.

The whole discrete action as one square system (``constrained_grid.py``: the interval equations
of ``discrete/constrained.py``, ``g = 0`` and the hidden constraint at the nodes, the node
multipliers as unknowns), solved by the grid's Newton (sparse LU) and by IPOPT on the same rows,
through the grid's one policy (``"auto"``: Newton, then IPOPT from the same start if Newton's
point fails its verification).

**The ends.** ``q_start`` and ``q_end`` must lie on ``g = 0``: an end off it by at most
``END_TOLERANCE`` of its size (rounding of printed values) is projected onto it by the least
change, as the march's start is (``marching/constrained_start.py``), and a ``RuntimeWarning``
says what moved; one farther off is refused by name (a fixed-end problem asks for those
positions: projecting far would answer another problem).

**The start.** The straight line between the ends, each node projected onto ``g = 0``, its
velocity as momentum projected onto the hidden constraint, and the multipliers of the exact
motion through those states (``exact/constrained_flow.multipliers_function``); or the user's
nodes (a `Solution`, a mapping with ``t``, ``q``, ``p``), projected the same way. An energy
rule first solves ``fixed`` steps on the uniform times, then releases the times.

**The verdict.** Every returned point is checked by its own unscaled residuals, each kind of
row in its own units (`_limits`): ``tol`` relative to what the row measures (the motion's size
for the interval rows, how far ``g`` and its time derivative move with the positions for the
constraint and the hidden constraint, ``tol h W`` for the energy rows) or 64 of Newton's
targets, which are each row's own round-off (`_targets`); every step positive. No scale is a
floor of 1 and none is an absolute number, so the same motion in other units of length,
momentum or time is the same solution with the same verdict. Then it is
judged against the constrained exact flow (index-reduced, projected inside its error control)
through the continuous solution near it found by multiple shooting (``exact/shooting.py``), as
an unconstrained fixed-end solution is.
"""

from __future__ import annotations

import sys
import time
import warnings
from dataclasses import dataclass, replace

import numpy as np

from ...discrete.scheme import Scheme
from ...errors import InputError
from ...physics.constraints import check_start_constraints, constraint_function
from ...solution import EndsRecord, Solution, Status
from ...validation import check_integer, check_span, check_state
from ..accuracy.judgement import judge
from ..columns import row_max_abs
from ..dense import attach
from ..exact.constrained_flow import multipliers_function, projection_function
from ..grid.motion_size import energy_rate
from ..grid.newton import newton
from ..grid.policy import (
    Attempt,
    Stage,
    failure_status,
    solve_in_order,
    solver_order,
    worst_against,
)
from ..grid.problem import GridRequest, GridResult
from ..grid.round_off import row_noise
from .constrained_grid import (
    ConstrainedData,
    ConstrainedGrid,
    ConstrainedIpopt,
    ConstrainedLayout,
)
from .continuous_check import judged_against_shooting
from .phases import BOUNDS_ALLOWED, NOISE_TARGET, canonical_sizes

EPS = np.finfo(float).eps
DEFAULT_MAX_ITER = 200
# An end off g = 0 by at most this fraction of its size is projected onto it (with a warning);
# farther, refused.
END_TOLERANCE = 1e-6
PROJECTION_ROUNDS = 20
# The homotopy of an energy rule's Newton: iterations per stage, smallest stage.
HOMOTOPY_ITER = 30
SMALLEST_HOMOTOPY_STEP = 2.0 ** -12
# An energy rule's start on more nodes than this comes from its solution on about half as many.
COARSEST = 41


@dataclass
class ConstrainedBoundary:
    """The data of a constrained fixed-end problem: the (projected) ends, the times of the
    ``fixed`` rule, and what projecting the ends moved."""

    q_start: np.ndarray
    q_end: np.ndarray
    t0: float
    t1: float
    grid_times: np.ndarray
    moved: dict


@dataclass
class ConstrainedEndsRecord:
    """What a constrained fixed-end solve found besides its nodes (``Solution.constraints``):
    ``|g|`` and the hidden constraint's residual per node, the multipliers of every interval,
    what projecting the ends moved (max norm), and the limits the residuals were held to."""

    constraint_residual: np.ndarray
    hidden_residual: np.ndarray
    multipliers: np.ndarray
    ends_moved: dict
    constraint_limit: float
    hidden_limit: float


def solve_constrained_bvp(system, q_start, q_end, t_span, *, nodes, scheme, params, guess, times,
                          options, compilation, output, derivatives) -> Solution:
    """`solve_bvp` of a constrained system (module docstring); ``options``, ``compilation``
    and ``output`` are already objects."""
    request, start = _checked(system, q_start, q_end, t_span, nodes=nodes, scheme=scheme,
                              params=params, guess=guess, times=times, options=options,
                              compilation=compilation, output=output, derivatives=derivatives)
    started = request.start_clock()
    x0 = _released_start(request, start) if request.scheme.variable_steps else \
        _start_point(request, start)
    chosen = _solve(request, request.scheme, x0, f"{request.scheme.rule} equations")
    solution = _solution(request, chosen, started)
    return attach(solution, system, request.theta, solution.t[-1] if solution.t.size else None)


def _checked(system, q_start, q_end, t_span, *, nodes, scheme, params, guess, times, options,
             compilation, output, derivatives):
    """The `GridRequest` (data a `ConstrainedBoundary`) and the start's nodes (``None``: the
    straight line); named errors before anything is built."""
    from .at_energy import AtEnergy
    from .first_guess import Shooting, check_guess, check_tau_floor, check_times

    name = system.name
    if output.checkpoint is not None or output.stop is not None:
        raise InputError("solve_bvp reports progress only (Output(progress=...)); checkpoint "
                         "and stop belong to a march")
    if isinstance(t_span, AtEnergy):
        raise InputError(f"system {name!r} has constraints: solve_bvp does not take a transfer "
                         "at a prescribed energy (AtEnergy) of a constrained system yet")
    if derivatives:
        raise InputError(f"system {name!r} has constraints: solve_bvp does not give "
                         f"derivatives={derivatives!r} of a constrained system yet")
    if isinstance(guess, Shooting) or guess == "march":
        raise InputError(f"system {name!r} has constraints: guess={guess!r} (shooting) is not "
                         "supported for a constrained system yet; give 'straight' or nodes")
    if isinstance(guess, str) and guess != "straight":
        raise InputError(f"unknown guess {guess!r} for a constrained system (give 'straight', "
                         "a Solution or a mapping with t, q and p)")
    if options.linear == "banded":
        raise InputError("options.linear='banded' does not apply to a constrained system "
                         "(its rows are grouped: the sparse LU)")
    scheme = Scheme.coerce(scheme)
    n = system.n
    q_start, q_end = check_state("q_start", q_start, n), check_state("q_end", q_end, n)
    t0, t1 = check_span(t_span)
    nodes = check_integer("nodes", nodes, minimum=3)
    options = options.resolved(max_iter=DEFAULT_MAX_ITER)
    tau_floor = check_tau_floor(options.tau_floor, t0, t1, nodes)
    grid_times = check_times(times, nodes, t0, t1)
    start = None if guess is None or isinstance(guess, str) else \
        check_guess(guess, nodes, n, t0, t1)
    theta = system.parameter_vector(params)
    moved = {}
    q_start, moved["q_start"] = on_constraint(system, q_start, t0, theta, "q_start")
    q_end, moved["q_end"] = on_constraint(system, q_end, t1, theta, "q_end")
    boundary = ConstrainedBoundary(q_start, q_end, t0, t1, grid_times, moved)
    request = GridRequest(system, scheme, nodes, theta, boundary, options, compilation,
                          tau_floor=tau_floor, progress=output.progress)
    return request, start


def on_constraint(system, q, t: float, theta, what: str):
    """``(q, moved)``: ``q`` on ``g(q, t) = 0`` (module docstring: projected with a warning
    when it is off by at most ``END_TOLERANCE`` of its size, refused when farther)."""
    check_start_constraints(system, q, t, theta, what=what)
    constraints = constraint_function(system)
    m, n = system.n_constraints, system.n
    size = max(float(np.abs(q).max()), np.finfo(float).tiny)
    projected = np.array(q, float)
    for _ in range(PROJECTION_ROUNDS):
        g, G, _ = (np.asarray(v, float) for v in constraints(projected, t, theta))
        step = G.reshape(m, n).T @ np.linalg.solve(G.reshape(m, n) @ G.reshape(m, n).T,
                                                   g.ravel())
        projected = projected - step
        if np.abs(step).max() <= 4 * EPS * size:
            break
    moved = float(np.abs(projected - q).max())
    if not np.all(np.isfinite(projected)) or moved > END_TOLERANCE * size:
        g = np.asarray(constraints(q, t, theta)[0], float).ravel()
        raise InputError(f"{what} = {np.asarray(q).tolist()} is not on the constraints of "
                         f"{system.name!r}: g = {g.tolist()} (the nearest point on g = 0 is "
                         f"{moved:.3g} away, more than {END_TOLERANCE:g} of its size); give "
                         "an end on g = 0")
    if moved > 64 * EPS * size:
        warnings.warn(f"{what} was projected onto the constraints of {system.name!r}: it "
                      f"moved by {moved:.3g} (max norm)", RuntimeWarning, stacklevel=5)
        return projected, moved
    return np.array(q, float), 0.0


def _start_point(request: GridRequest, start) -> np.ndarray:
    """The packed start (module docstring): the straight line or the user's nodes, projected
    onto ``g = 0`` and the hidden constraint, with the exact motion's multipliers."""
    data, system = request.data, request.system
    N = request.nodes
    t = np.asarray(start["t"], float) if start is not None else data.grid_times \
        if data.grid_times.size == N else np.linspace(data.t0, data.t1, N)
    if start is None:
        s = (t - t[0]) / (t[-1] - t[0])
        q = data.q_start[None, :] + s[:, None] * (data.q_end - data.q_start)[None, :]
        p = np.repeat(((data.q_end - data.q_start) / (t[-1] - t[0]))[None, :], N, 0)
    else:
        q, p = np.asarray(start["q"], float), np.asarray(start["p"], float)
    z = np.hstack([q, p]).T
    project = projection_function(system).map(N)
    theta = np.tile(request.theta[:, None], (1, N))
    for _ in range(PROJECTION_ROUNDS):
        moved = np.asarray(project(z, t[None, :], theta))
        # each coordinate against its own magnitude (no floor of 1: in lengths of 1e-8 the
        # first round passed for converged)
        done = bool(np.all(np.abs(moved - z) <= 8 * EPS * np.max(np.abs(moved), axis=1,
                                                                  keepdims=True)))
        z = moved
        if done or not np.all(np.isfinite(z)):
            break
    if not np.all(np.isfinite(z)):
        raise InputError("the start cannot be put on the constraints: projecting the "
                         f"{'straight line between the ends' if start is None else 'guess'} "
                         "onto g = 0 gave non-finite values (it passes where the constraint's "
                         "Jacobian is singular); give a guess with t, q and p on g = 0")
    z[:system.n, 0], z[:system.n, -1] = data.q_start, data.q_end
    nu = np.asarray(multipliers_function(system).map(N)(z, t[None, :], theta)).T
    multipliers = np.hstack([nu[:-1], nu[1:]])
    layout = ConstrainedLayout(system.n, system.n_constraints, N)
    return layout.pack(t, z[:system.n].T, z[system.n:].T, multipliers)


def _released_start(request: GridRequest, start) -> np.ndarray:
    """The start of an energy rule's solve (module docstring): the user's nodes as given; else,
    up to ``COARSEST`` nodes, ``fixed`` steps on uniform times solved from the straight line;
    above, the energy rule's own solution on about half the nodes, resampled by node index
    (its step distribution kept). Released from uniform times, Newton took 16, 48, 86 and then
    more than 200 iterations at N = 21, 41, 81, 161 on a rotation of the Cartesian pendulum
    (measured): the energy rule's steps are far from uniform there."""
    if start is not None:
        return _start_point(request, start)
    rule = request.scheme.rule
    if request.nodes > COARSEST:
        coarse = replace(request, nodes=(request.nodes - 1) // 2 + 1)  # the same phases list
        solved = _solve(coarse, request.scheme, _released_start(coarse, None),
                        f"{rule} equations on {coarse.nodes} nodes")
        request.build_s += coarse.build_s
        if solved.status is Status.SUCCESS:
            t, q, p, _ = grid_of(coarse, request.scheme).layout.unpack(solved.x)
            index, old = np.linspace(0, coarse.nodes - 1, request.nodes), np.arange(coarse.nodes)
            t = np.interp(index, old, t)
            return _start_point(request, {"t": t, **{
                key: np.column_stack([np.interp(index, old, c) for c in value.T])
                for key, value in (("q", q), ("p", p))}})
    x0 = _start_point(request, None)
    fixed = Scheme("fixed", alpha=request.scheme.alpha, clock=request.scheme.clock)
    first = _solve(request, fixed, x0, "fixed steps, uniform times")
    return first.x if first.status is Status.SUCCESS else x0


def grid_of(request: GridRequest, scheme: Scheme) -> ConstrainedGrid:
    return request.built(("constrained_bvp_grid", scheme, request.nodes),
                         lambda: ConstrainedGrid(request.system, scheme, request.nodes))


def data_of(request: GridRequest, scheme: Scheme) -> ConstrainedData:
    """The data of the system of ``scheme``: ``fixed`` steps on the request's times (uniform
    for the start phase of an energy rule), an energy rule between its two end times."""
    d = request.data
    if scheme.variable_steps:
        times = np.array([d.t0, d.t1])
    elif request.scheme.variable_steps:
        times = np.linspace(d.t0, d.t1, request.nodes)
    else:
        times = d.grid_times
    return ConstrainedData(d.q_start, d.q_end, times, request.theta,
                           (d.t1 - d.t0) / (request.nodes - 1))


def _solve(request: GridRequest, scheme: Scheme, x0: np.ndarray, name: str) -> Attempt:
    """The system of ``scheme`` from ``x0`` by the request's solvers in the policy's order,
    each point verified."""
    def attempt(solver: str) -> Attempt:
        started = time.perf_counter()
        grid, data = grid_of(request, scheme), data_of(request, scheme)
        if solver == "newton" and scheme.variable_steps:
            result = _homotopy(request, grid, x0, data)
        elif solver == "newton":
            result = newton(grid, x0, data, _targets(request, grid, x0, data),
                            tau_floor=-np.inf, max_iter=request.max_iter, linear="sparse",
                            deadline=request.deadline,
                            progress=_reporter(name) if request.progress else None)
        else:
            problem = request.built(
                ("constrained_bvp_ipopt", scheme, request.nodes, request.tol,
                 request.max_iter, request.verbose),
                lambda: ConstrainedIpopt(grid, tol=request.tol, max_iter=request.max_iter,
                                         verbose=request.verbose or request.progress,
                                         time_limit=request.remaining()))
            result = problem.solve(x0, data, request.tau_floor)
        stage = Stage(name, solver, result.converged, result.outcome, result.iterations,
                      time.perf_counter() - started)
        request.phases.append(stage)
        return Attempt(result.x, stage, verify(request, scheme, result.x, stage))

    chosen, _, _ = solve_in_order(solver_order(request.solver), attempt)
    return chosen


def _homotopy(request: GridRequest, grid: ConstrainedGrid, x0: np.ndarray,
              data: ConstrainedData) -> GridResult:
    """Newton on an energy rule's rows through the homotopy ``F(x) = (1 - s) F(x_0)``, ``s``
    from 0 (``x_0`` solves it) to 1: the whole step first, a quarter of it after a stage that
    fails, twice the last after one that converges; ``request.max_iter`` iterations in all.
    From fixed steps on uniform times Newton alone stalled at N = 32 on a rotation of the
    Cartesian pendulum, and took two stages with it (measured)."""
    F0, _ = grid.evaluate(x0, data, jacobian=False)
    x, reached, step, iterations, stages = np.array(x0, float), 0.0, 1.0, 0, 0
    said = ""
    while reached < 1.0 and step >= SMALLEST_HOMOTOPY_STEP and iterations < request.max_iter:
        s = min(1.0, reached + step)
        result = newton(grid, x, data, _targets(request, grid, x, data),
                        tau_floor=request.tau_floor, max_iter=min(HOMOTOPY_ITER, max(
                            1, request.max_iter - iterations)), linear="sparse",
                        deadline=request.deadline, offset=None if s == 1.0 else (1 - s) * F0,
                        progress=_reporter(f"s = {s:.4g}") if request.progress else None)
        iterations, stages, said = iterations + result.iterations, stages + 1, result.outcome
        if result.converged:
            x, reached, step = result.x, s, 2 * step
        elif "time limit" in said:
            break
        else:
            step /= 4
    if reached == 1.0:
        return GridResult(x, True, f"{said} (homotopy in the rows' start residual: {stages} "
                          f"stages)", iterations)
    return GridResult(x, False, f"the homotopy in the rows' start residual stopped at s = "
                      f"{reached:.4g} after {stages} stages, {iterations} iterations; last "
                      f"stage: {said}", iterations)


def _reporter(name: str):
    def report(iteration, norm, alpha):
        print(f"constrained bvp [{name}]: iteration {iteration}, |F| = {norm:.3e}, step "
              f"{alpha:.3g}", file=sys.stderr, flush=True)
    return report


def _targets(request, grid: ConstrainedGrid, x, data: ConstrainedData) -> np.ndarray:
    """Newton's per-row ``|F_i|`` targets near ``x``, in each row's own units (as the
    unconstrained grid's, ``phases.newton_targets``): ``NOISE_TARGET`` times the largest change
    of each kind of row (every column of the interval block: the canonical rows and the hidden
    constraint; the constraint rows; the scaled energy rows) when every unknown moves by one
    unit in its last place (`grid.round_off.row_noise`); a pin's row (an end time or position,
    an unused multiplier) its own. No floor of 1 and no mix of units: with ``64 eps max(1,
    |q_ends|, |t_ends|)`` a pendulum in lengths of ``1e-8`` or in time units of ``1e5`` took
    its start for a solution, 0 iterations, its energy rows ``1e-5`` of its energy off."""
    layout, s = grid.layout, grid.slices
    n, m, N, M = layout.n, layout.m, layout.nodes, layout.width
    noise = row_noise(grid, x, data)
    # a pin's round-off where its row is exactly 0 (t_0 = 0, an unused multiplier): eps times
    # its column's magnitude; a tiny target there failed Newton's monotonicity test on the
    # round-off of a linear row
    size = EPS * np.max(np.abs(np.asarray(x, float).reshape(N, M)), axis=0)
    q_size, t_size = size[1:n + 1], size[0]
    target = noise.copy()
    B = 2 * n + m
    body = noise[s["intervals"]].reshape(N - 1, B).max(axis=0)
    body[:2 * n] = np.maximum(body[:2 * n], EPS * _sizes(request, grid, x))
    target[s["intervals"]] = np.tile(body, N - 1)
    first = s["start"].start
    target[first] = max(noise[first], t_size)
    target[first + 1:first + n + 1] = np.maximum(noise[first + 1:first + n + 1], q_size)
    target[first + n + 1:s["start"].stop] = np.maximum(noise[first + n + 1:s["start"].stop],
                                                       body[2 * n:])
    if N > 2:
        target[s["constraint"]] = np.tile(noise[s["constraint"]].reshape(N - 2, m).max(axis=0),
                                          N - 2)
    times = np.maximum(noise[s["time"]], t_size)
    if grid.scheme.variable_steps and N > 2:
        times[:-1] = np.max(noise[s["time"]][:-1])
    target[s["time"]] = times
    target[s["end"]] = np.maximum(noise[s["end"]], q_size)
    target[s["unused"]] = np.maximum(noise[s["unused"]], size[2 * n + 1:])
    return NOISE_TARGET * np.maximum(target, np.finfo(float).tiny)


def _sizes(request: GridRequest, grid: ConstrainedGrid, x) -> np.ndarray:
    """`phases.canonical_sizes` of the point ``x``."""
    _, q, p, _ = grid.layout.unpack(x)
    return canonical_sizes(request.system, grid.scheme, q, p)


def _limits(request: GridRequest, grid: ConstrainedGrid, x, data: ConstrainedData) -> dict:
    """The largest residual of each kind the point may have, per column: ``tol`` relative to
    what the row measures, or ``BOUNDS_ALLOWED`` of its Newton target (`_targets`), whichever
    is larger. A canonical row measures the motion's size in its units (`_sizes`);
    a constraint row ``|dg/dq| s_q``, how far ``g`` moves when the positions move by their
    ranges; the hidden constraint ``|dg/dq| v_q``, ``v_q`` the largest speed of each position
    read off the nodes; an energy row (unscaled) ``tol`` times the mean step times the rate at
    which the motion trades energy (`grid.motion_size.energy_rate`), as the unconstrained
    grid's. Every scale follows the units of lengths, momenta and time, and none moves with a
    shift of the origin or a constant added to ``H``: ``tol`` as an absolute number had passed
    in lengths of ``1e-8`` energy rows that were not solved."""
    layout, s = grid.layout, grid.slices
    n, m, N = layout.n, layout.m, layout.nodes
    targets = _targets(request, grid, x, data)
    body = targets[s["intervals"]].reshape(N - 1, 2 * n + m)[0]
    g_target = targets[s["constraint"]][:m] if N > 2 else body[2 * n:]
    t, q, p, _ = layout.unpack(x)
    theta = np.tile(request.theta[:, None], (1, N))
    G = np.abs(np.asarray(constraint_function(request.system).map(N)(
        q.T, t[None, :], theta)[1], float).reshape(m, N, n)).max(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        speeds = np.abs(np.diff(q, axis=0)) / np.abs(np.diff(t))[:, None]
    speed = np.nanmax(np.where(np.isfinite(speeds), speeds, np.nan), axis=0) \
        if N > 1 else np.zeros(n)
    tol = request.tol
    energy = BOUNDS_ALLOWED * float(targets[s["time"].start]) * data.energy_scale \
        if grid.scheme.variable_steps and N > 2 else 0.0
    return {"canonical": np.maximum(tol * _sizes(request, grid, x),
                                    BOUNDS_ALLOWED * body[:2 * n]),
            "g": np.maximum(tol * G @ np.ptp(q, axis=0), BOUNDS_ALLOWED * g_target),
            "hidden": np.maximum(tol * G @ np.nan_to_num(speed), BOUNDS_ALLOWED * body[2 * n:]),
            "energy": max(tol * data.energy_scale * energy_rate(t, np.hstack([q, p])), energy)}


def verify(request: GridRequest, scheme: Scheme, x: np.ndarray, stage: Stage):
    """``(status, message, details)`` of ``x`` from its own unscaled residuals against
    `_limits` (per column of each kind), the solver's words quoted."""
    grid, data = grid_of(request, scheme), data_of(request, scheme)
    if not np.all(np.isfinite(x)):
        return Status.NON_FINITE, f"the solver returned non-finite values ({stage.quoted})", {}
    parts = grid.parts(x, data)
    # the row of each kind furthest over (or nearest) its column's limit; a fixed-step grid
    # has no energy rows: 0 against their limit
    energy = parts["energy"] if parts["energy"].size else np.zeros(1)
    worst, limits = worst_against({"canonical": parts["interval"], "g": parts["g"],
                                   "hidden": parts["hidden"], "energy": energy},
                                  _limits(request, grid, x, data))
    t = grid.layout.unpack(x)[0]
    tau = np.diff(t)
    problems = [f"step {int(np.argmin(tau))} is not positive: tau = {tau.min():.6g}"] \
        if tau.min() <= 0 else []
    words = {"canonical": "interval residual", "g": "constraint |g|",
             "hidden": "hidden constraint", "energy": "energy residual"}
    for key, said in words.items():
        if worst[key] > limits[key] and (key != "energy" or scheme.variable_steps):
            problems.append(f"{said} {worst[key]:.3e} above its limit {limits[key]:.3e}")
    details = {"parts": parts, "limits": limits, "worst": worst}
    if not problems:
        return Status.SUCCESS, (
            f"solved and verified: largest residuals interval {worst['canonical']:.3e}, "
            f"|g| {worst['g']:.3e}, hidden {worst['hidden']:.3e}, energy {worst['energy']:.3e}; "
            f"{stage.iterations} iterations ({stage.quoted})"), details
    status = failure_status(stage, tau)
    return status, f"{status.value}: {'; '.join(problems)} ({stage.quoted})", details


def _solution(request: GridRequest, chosen: Attempt, started: float) -> Solution:
    status, message, details = chosen.outcome
    grid = grid_of(request, request.scheme)
    t, q, p, multipliers = grid.layout.unpack(chosen.x)
    parts = details.get("parts")
    N, n = request.nodes, request.system.n
    if parts is None:
        nan = np.full(N, np.nan)
        parts = {"interval": np.full((N - 1, 2 * n), np.nan), "g": nan[:, None],
                 "hidden": nan[:, None], "energy": np.full(N - 2, np.nan)}
    limits, worst = details.get("limits", {}), details.get("worst", {})
    stats = {"solver": chosen.stage.solver, "return_status": chosen.stage.said,
             "iterations": chosen.stage.iterations,
             "iterations_total": sum(s.iterations for s in request.phases),
             "energy_scale": (request.data.t1 - request.data.t0) / (N - 1),
             "tau_floor": request.tau_floor}
    sign_changes = tuple(int(np.count_nonzero(np.diff(np.sign(p[:, i])) != 0))
                         for i in range(n))
    finite = bool(np.all(np.isfinite(chosen.x)))
    record = EndsRecord(stages=tuple(replace(s) for s in request.phases),
                        action=grid.action(chosen.x, request.theta) if finite else float("nan"),
                        p_sign_changes=sign_changes,
                        canonical_limit=limits.get("canonical", np.nan),
                        energy_limit=limits.get("energy", np.nan),
                        canonical_residual_max=worst.get("canonical"),
                        energy_residual_max=worst.get("energy"),
                        tau_min=float(np.min(np.diff(t))) if np.all(np.isfinite(t)) else None)
    report, local = None, np.zeros(0)
    judged, judged_cpu = time.perf_counter(), time.process_time()
    if np.all(np.isfinite(chosen.x)):
        report, local = _accuracy(request, t, q, p)
    total = time.perf_counter() - started
    solution = Solution(
        t=t, q=q, p=p, status=status, message=message, scheme=request.scheme.rule,
        energy_residual=parts["energy"] if request.scheme.variable_steps else np.zeros(0),
        canonical_residual=row_max_abs(parts["interval"]),
        newton_iterations=stats["iterations_total"],
        timing={"build_s": request.build_s, "solve_s": total - request.build_s,
                "accuracy_s": total - (judged - started),
                "accuracy_cpu_s": time.process_time() - judged_cpu},
        stats=stats, ends=record)
    solution.constraints = ConstrainedEndsRecord(
        np.abs(parts["g"]).max(axis=1), np.abs(parts["hidden"]).max(axis=1), multipliers,
        dict(request.data.moved), limits.get("g", np.nan), limits.get("hidden", np.nan))
    judge(solution, report, request.options.accuracy, local_error=local,
          advice="try more nodes")
    return solution


def _accuracy(request: GridRequest, t, q, p):
    """The accuracy check against the constrained exact flow: the continuous solution near the
    grid's by multiple shooting (``exact/shooting.py``, the flow index-reduced and projected),
    each interval against the exact flow, the nodal energy; no level test (the constraint
    forces do not change the interval energies the energy rows hold, as for the march)."""
    return judged_against_shooting(request, t, q, p, flow="constrained exact flow")


__all__ = ["ConstrainedEndsRecord", "on_constraint", "solve_constrained_bvp", "verify"]
