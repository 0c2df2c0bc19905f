"""Periodic orbits at a prescribed energy of a constrained system (``g(q) = 0``):
`solve_periodic` hands a system with ``constraints=`` here (docs/periodic/constrained.md).

**The rows** are those of ``constrained_closed.py``: the closed grid of ``orbit.py`` with the
node multipliers, the position and hidden constraints at every node, the interval energy with
the interval's own momenta held at ``E``, and the unfolding parameter ``lambda`` of ``H`` (the
time shift's dependent closure row), solved by the grid's Newton (sparse LU) and IPOPT on the
same rows through the grid's one policy.

**Further symmetries.** A first integral ``I`` whose flow is a symmetry (the spherical
pendulum's angular momentum about the vertical) is handled as in ``orbit.py``: a phase
condition ``(J grad I) . (z_0 - z_0^ref) = 0`` and an unfolding ``mu`` along ``grad I``. Where
the symmetry's flow is the orbit's own motion at node 0 (a relative equilibrium: the conical
orbit of the spherical pendulum, which *is* a rotation about the vertical), that phase condition
repeats the section and the rows are singular: such an integral is refused by name, and none
is needed (the rotation and the time shift are then one direction of solutions and one
dependent closure row, which the section and ``lambda`` take; measured in the docs).

**The start.** ``start = (q, p)`` is required: a point near the constraints, projected onto
``g = 0`` and its hidden constraint (``marching/constrained_start.py``), its momentum scaled so
that ``H = E`` (``H`` quadratic in ``p``; an energy at or below the potential there has no
motion at that point and is refused by name). The exact constrained flow from it is traced to
the section twice in the same direction: one period, sampled at ``N + 1`` uniform times, the
multipliers those of the exact motion. Or ``guess`` nodes of one period (a `Solution` or a
mapping with ``t``, ``q``, ``p``; a neighbour in a family), resampled to ``N + 1`` nodes,
projected onto the constraints, with the exact motion's multipliers. Angle coordinates and
derivatives are refused by name (not handled for constrained systems).

**The verdict.** The point is verified by its own unscaled residuals with the unfolding
parameters set to zero (interval equations, ``g`` and the hidden constraint at every node, the
scheme's own energy equations at every node with the wrap-around, ``E_k = E``, closure,
section, every step positive), then judged against the constrained exact flow (index-reduced,
projected): every interval, the level, and the flow from node 0 over the period staying on the
orbit (else ``inaccurate``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.optimize import brentq

from ...discrete.scheme import Scheme
from ...errors import InputError
from ...physics.constraints import constraint_function
from ...physics.hamiltonian import derivatives_function
from ...solution import OrbitRecord, Solution, Status
from ...validation import check_integer, check_real, check_state
from ..accuracy.judgement import Judgement, Level, judge
from ..compiler import find_compiler
from ..exact.constrained_flow import (
    constrained_field,
    multipliers_function,
    projection_function,
)
from ..exact.flow import exact_flow
from ..grid.ipopt import DEFAULT_OPTIONS, FeasibilityNlp, ipopt_settings, node_grid_sizes
from ..grid.motion_size import energy_rate, orbit_sizes
from ..grid.policy import Attempt, Stage, solve_in_order, solver_order, worst_against
from ..grid.problem import GridRequest, GridResult, check_energy_problem
from ..grid.round_off import row_noise
from ..marching.constrained_start import consistent_start
from ..options import GridOptions
from .closed_grid import (
    BOUNDS_ALLOWED,
    EPS,
    NOISE_TARGET,
    closed_newton,
    closed_verdict,
    integral_gradients,
)
from .constrained_closed import ConstrainedClosedGrid, ConstrainedClosure
from .first_orbit import guess_nodes

DEFAULT_MAX_ITER = 100
TRACE_RTOL = 1e-11
TRACE_DOUBLINGS = 8  # the trace's span doubled at most this often looking for the return
# the traced state must return to within this fraction of its size (the trace's rtol is 1e-11)
RETURN = 1e-6
# a symmetry generator within this angle (sine) of the flow at node 0 repeats the section
PARALLEL = 1e-6


@dataclass
class ConstrainedOrbit:
    """The data of one constrained periodic problem: energy, section, the consistent start at
    ``E`` (``z``) and what projecting it moved, or the user's ``guess`` nodes ``(t, z)``."""

    energy: float
    index: int
    value: float
    label: str
    z: np.ndarray | None
    moved: tuple
    guess: tuple | None = None


@dataclass
class ConstrainedOrbitRecord:
    """``Solution.constraints`` of a constrained orbit: ``|g|`` and the hidden constraint per
    node, the multipliers of every interval, what projecting the start moved, the limits (by
    kind of residual, as ``OrbitRecord.residual_limit``)."""

    constraint_residual: np.ndarray
    hidden_residual: np.ndarray
    multipliers: np.ndarray
    start_moved: tuple
    limit: dict


def solve_constrained_periodic(system, *, energy, nodes, section, guess, scheme, params, start,
                               integrals, angles, options: GridOptions, derivatives) -> Solution:
    """`solve_periodic` of a constrained system (module docstring)."""
    request = checked_request(system, energy, nodes, section, guess, scheme, params, start,
                              integrals, angles, options, derivatives)
    started = request.start_clock()
    t, z = _traced_nodes(request) if request.data.guess is None else request.data.guess
    grid = request.built(("constrained_closed", request.scheme, request.intervals, integrals),
                         lambda: ConstrainedClosedGrid(system, request.scheme,
                                                       request.intervals, integrals))
    closure = _closure(request, z[0], integrals)
    x0 = _packed(request, grid, t, z)
    sizes = _sizes(request, grid, x0)
    scale = _targets(request, grid, x0, closure, sizes)
    request.tau_floor = 1e-3 * (t[-1] - t[0]) / request.intervals

    def attempt(solver: str) -> Attempt:
        began = time.perf_counter()
        result = _run(solver, request, grid, x0, closure, scale)
        stage = Stage("constrained periodic orbit", solver, result.converged, result.outcome,
                      result.iterations, time.perf_counter() - began)
        request.phases.append(stage)
        solution = _solution(request, grid, result, closure, scale, started)
        solution.stats["solver"] = solver
        return Attempt(result.x, stage, (solution.status, solution.message, solution))

    chosen, tried, _ = solve_in_order(solver_order(request.solver), attempt,
                                      enough=(Status.SUCCESS, Status.INACCURATE,
                                              Status.TIME_LIMIT))
    # an orbit that holds the equations but not the motion says more than a solver's failure
    chosen = next((a for a in tried if a.status is Status.SUCCESS),
                  next((a for a in tried if a.status is Status.INACCURATE), chosen))
    solution = chosen.outcome[2]
    solution.stats["attempts"] = [{"solver": a.stage.solver, "status": a.status.code,
                                   "iterations": a.stage.iterations, "said": a.stage.said}
                                  for a in tried]
    solution.stats["iterations_total"] = sum(a.stage.iterations for a in tried)
    return solution


def checked_request(system, energy, nodes, section, guess, scheme, params, start, integrals,
                    angles, options: GridOptions, derivatives,
                    start_required: bool = True) -> GridRequest | None:
    """Every argument checked (``InputError`` naming it) and the start made consistent at
    ``E``, before any grid is built; ``section`` comes parsed (``orbit.parse_section``'s
    ``(index, value, label)``). ``start_required=False`` (`check_periodic`, whose caller may
    pass a guess later): no start and no guess check the rest and return ``None``."""
    name = system.name
    scheme = Scheme.coerce(scheme)
    check_energy_problem(system, scheme, "a periodic orbit at a prescribed energy")
    if ca.depends_on(ca.vec(system.G), system.t):
        raise InputError(f"system {name!r} has constraints that depend on t: a periodic orbit "
                         "at a prescribed energy needs autonomous constraints")
    if tuple(angles):
        raise InputError(f"system {name!r} has constraints: angles={tuple(angles)!r} (rotations"
                         " closing with whole turns) are not supported for a constrained system")
    if derivatives:
        raise InputError(f"system {name!r} has constraints: solve_periodic does not give "
                         f"derivatives={derivatives!r} of a constrained orbit yet")
    if options.linear == "banded":
        raise InputError("linear must be 'auto' or 'sparse' for a periodic orbit of a "
                         "constrained system, got 'banded'")
    energy = check_real("energy", energy)
    intervals = check_integer("nodes", nodes, minimum=4) - 1
    index, value, label = section
    theta = system.parameter_vector(params)
    if start is None and guess is None:
        if not start_required:
            return None
        raise InputError(f"system {name!r} has constraints: solve_periodic needs start=(q, p), "
                         "a point near the constraints from which the orbit at the energy is "
                         "traced, or a guess of nodes")
    if guess is not None:  # nodes of one period (a neighbour in a family): projected later
        orbit = ConstrainedOrbit(energy, index, value, label, None, (0.0, 0.0),
                                 guess_nodes(guess, system.n, intervals))
        return GridRequest(system, scheme, intervals + 1, theta, orbit,
                           options.resolved(max_iter=DEFAULT_MAX_ITER))
    try:
        q, p = start
    except (TypeError, ValueError):
        raise InputError(f"start must be a pair (q, p), got {start!r}") from None
    q, p = check_state("start q", q, system.n), check_state("start p", p, system.n)
    z, moved = at_energy(system, theta, q, p, energy)
    orbit = ConstrainedOrbit(energy, index, value, label, z, moved)
    return GridRequest(system, scheme, intervals + 1, theta, orbit,
                       options.resolved(max_iter=DEFAULT_MAX_ITER))


def at_energy(system, theta, q, p, energy: float):
    """``(z, moved)``: ``(q, p)`` projected onto the constraints and its momentum scaled to
    ``H = E`` (module docstring); named errors when that cannot be done."""
    projected = consistent_start(system, q, p, 0.0, theta, warn=False)
    q, p = projected.q0, projected.p0

    def H(momentum):
        return float(system.H_function(q, momentum, 0.0, theta))

    potential, kinetic = H(np.zeros_like(p)), H(p) - H(np.zeros_like(p))
    if not np.isfinite(potential) or not np.isfinite(kinetic):
        raise InputError(f"H is not finite at the start q = {q.tolist()}")
    if energy <= potential:
        raise InputError(f"energy = {energy!r} has no motion at the start: the potential there "
                         f"is H(q, 0) = {potential!r} >= E (q = {q.tolist()} on the "
                         "constraints); give a larger energy or a start lower in the potential")
    quadratic = H(2 * p) - potential
    if kinetic <= 0 or abs(quadratic - 4 * kinetic) > 1e-8 * abs(quadratic):
        raise InputError(f"start p = {p.tolist()} (projected onto the hidden constraint) "
                         "gives no kinetic energy quadratic in p to scale to the energy: give a "
                         "non-zero momentum along the constraints, and H quadratic in p")
    p = p * np.sqrt((energy - potential) / kinetic)
    return np.concatenate([q, p]), (projected.moved_q, projected.moved_p)


def _traced_nodes(request: GridRequest):
    """``(t, z)`` of ``N + 1`` nodes: one period of the exact flow from the section's first
    crossing to the first later crossing in the same direction where the whole state returns
    (within ``RETURN`` of its size; a section may be crossed more often than once a period),
    at uniform times (module docstring)."""
    system, orbit, theta = request.system, request.data, request.theta
    flow = exact_flow(system, compiler=find_compiler(request.compilation.compiler),
                      cache_dir=request.compilation.cache_dir)
    z0, n = orbit.z, system.n
    _, _, H_p, _ = derivatives_function(system)(z0[:n], z0[n:], 0.0, theta)
    speed = float(np.max(np.abs(np.asarray(H_p, float))))
    span = 2 * np.pi * float(np.max(np.abs(z0[:n]))) / speed
    size = float(np.max(np.abs(z0)))
    for _ in range(TRACE_DOUBLINGS):
        run = flow.run(z0, 0.0, span, theta, rtol=TRACE_RTOL, atol=TRACE_RTOL * size)
        crossings = _crossings(run, orbit.index - 1, orbit.value)
        if crossings:
            first = run.z([crossings[0]])[0]
            returns = [c for c in crossings[1:]
                       if np.max(np.abs(run.z([c])[0] - first)) <= RETURN * size]
            if returns:
                t = np.linspace(crossings[0], returns[0], request.intervals + 1)
                return t - t[0], run.z(t)
        if not run.success:
            break
        span *= 2
    said = "does not cross the section" if not crossings else \
        (f"crosses the section {len(crossings)} times in one direction but its state does not "
         "return (the motion through start at this energy is not periodic, or its period is "
         "longer)")
    raise InputError(f"the constrained exact flow from start at E = {orbit.energy!r} {said} "
                     f"{orbit.label} within t = {span:.6g}: give a start on a periodic orbit "
                     "and a section it crosses")


def _crossings(run, component: int, value: float) -> list:
    """The times the traced run crosses ``z[component] = value`` in the direction of its first
    crossing (a start on the section counts as its first crossing)."""
    t, z = run.nodes()
    f = z[:, component] - value
    found, direction = [], 0.0
    if abs(f[0]) <= 64 * EPS * max(float(np.max(np.abs(z[:, component]))), EPS):
        found, direction = [0.0], np.sign(f[1])
    for k in range(t.size - 1):
        if f[k] * f[k + 1] < 0:
            sign = np.sign(f[k + 1] - f[k])
            if direction and sign != direction:
                continue
            direction = sign
            found.append(brentq(lambda s: float(run.z([s])[0, component] - value), t[k],
                                t[k + 1], xtol=4 * EPS * max(abs(t[k + 1]), EPS),
                                rtol=4 * EPS))
    return found


def _closure(request: GridRequest, z0: np.ndarray, integrals) -> ConstrainedClosure:
    """The problem's data; each integral's phase condition at the start's node 0, refused by
    name where its symmetry's flow is the orbit's own motion there (module docstring)."""
    system, orbit = request.system, request.data
    n, r = system.n, len(integrals)
    generators = np.zeros((r, 2 * n))
    if integrals:
        gradients = np.asarray(integral_gradients(system, integrals)(z0[:n], z0[n:],
                                                                     request.theta))
        rotated = np.vstack([gradients[n:], -gradients[:n]]).T  # J grad, one row each
        flow = np.asarray(constrained_field(system)(z0, 0.0, request.theta), float).ravel()
        flow = flow / np.linalg.norm(flow)  # the constrained motion, on the manifold
        for i, row in enumerate(rotated[1:]):
            along = abs(float(row @ flow)) / np.linalg.norm(row)
            if np.sqrt(max(0.0, 1 - along ** 2)) <= PARALLEL:
                raise InputError(
                    f"integrals[{i}]: its symmetry moves node 0 along the orbit's own flow (a "
                    "relative equilibrium, such as the spherical pendulum's conical orbit): "
                    "its phase condition would repeat the section; give no integrals")
        generators = rotated[1:]
    return ConstrainedClosure(orbit.energy, orbit.index, orbit.value, request.theta,
                              z0.copy(), generators)


def _packed(request: GridRequest, grid: ConstrainedClosedGrid, t, z) -> np.ndarray:
    """The start's nodes projected and packed with the exact motion's multipliers."""
    system, N = request.system, request.intervals
    theta = np.tile(request.theta[:, None], (1, N + 1))
    z = np.asarray(projection_function(system).map(N + 1)(z.T, t[None, :], theta)).T
    z[-1] = z[0]
    nu = np.asarray(multipliers_function(system).map(N + 1)(z.T, t[None, :], theta)).T
    return grid.layout.pack(t, z[:, :system.n], z[:, system.n:], np.hstack([nu[:-1], nu[1:]]))


def _sizes(request: GridRequest, grid: ConstrainedClosedGrid, x: np.ndarray) -> np.ndarray:
    """The orbit's size in each coordinate of ``(q, p)`` (`grid.motion_size.orbit_sizes`)."""
    t, q, p, _, _ = grid.layout.unpack(x)
    return orbit_sizes(request.system, request.theta, t, np.hstack([q, p]))


def _targets(request: GridRequest, grid: ConstrainedClosedGrid, x: np.ndarray, closure,
             sizes: np.ndarray) -> np.ndarray:
    """Per-row Newton targets near ``x``, in each row's units (as an unconstrained orbit's,
    ``closed_grid.closed_targets``): ``NOISE_TARGET`` times the largest change of each kind
    of row (every column of the interval block: canonical rows, hidden constraints,
    constraints, prescribed energy) under a move of every unknown by one unit in its last
    place, never below ``eps`` times what the row measures (the coordinate's size for the
    closure and section rows, the period for ``t_0``, the multipliers' own for the rows that
    pin the unused ones). No floor of 1 and no mix of units: ``max(|q|, |p|, |E|, tau)`` put a
    pendulum in lengths of ``1e-8`` at targets ``1e-7`` of its size."""
    layout = grid.layout
    n, m, N, M, r = layout.n, layout.m, layout.intervals, layout.width, layout.integrals
    noise = row_noise(grid, x, closure)
    W = np.asarray(x[:(N + 1) * M], float).reshape(N + 1, M)
    eps = EPS * np.r_[np.ptp(W[:, 0]), sizes, np.max(np.abs(W[:, 2 * n + 1:]), axis=0)]
    head, B = 2 + r, 2 * n + 2 * m + 1
    body = noise[head:head + N * B].reshape(N, B)
    target = np.empty_like(noise)
    target[0] = max(noise[0], eps[0])
    target[1] = max(noise[1], eps[closure.section_index])
    if r:
        target[2:head] = np.maximum(noise[2:head], np.abs(closure.generators) @ eps[1:2 * n + 1])
    rows = target[head:head + N * B].reshape(N, B)
    rows[:] = np.max(body, axis=0)
    rows[:, :2 * n] = np.maximum(rows[:, :2 * n], eps[1:2 * n + 1])
    end = head + N * B
    target[end:end + 2 * n] = np.maximum(noise[end:end + 2 * n], eps[1:2 * n + 1])
    target[end + 2 * n:] = np.maximum(noise[end + 2 * n:], eps[2 * n + 1:])
    return NOISE_TARGET * np.maximum(target, np.finfo(float).tiny)


def _limits(request: GridRequest, grid: ConstrainedClosedGrid, x: np.ndarray, closure,
            targets: np.ndarray, sizes: np.ndarray) -> dict:
    """The largest residual of each kind the point may have (the keys of the verification's
    residuals), ``tol`` relative to what the row measures or ``BOUNDS_ALLOWED`` targets: the
    orbit's size per coordinate (canonical, closure, section rows), ``tol h W`` (energy rows,
    as ``closed_grid.closed_limits``), for a constraint row ``|dg/dq| s_q`` (how far ``g``
    moves when the positions move by their sizes) and for a hidden constraint that over the
    period's radian ``T / 2 pi``; the unused multipliers only their round-off."""
    layout = grid.layout
    n, m, N, r = layout.n, layout.m, layout.intervals, layout.integrals
    t, q, p, _, _ = layout.unpack(x)
    head, B = 2 + r, 2 * n + 2 * m + 1
    body = targets[head:head + N * B].reshape(N, B)[0]
    end = head + N * B
    tol = request.tol
    energy = max(tol * abs(t[-1] - t[0]) / N * energy_rate(t, np.hstack([q, p])),
                 BOUNDS_ALLOWED * float(body[-1]))
    G = np.asarray(constraint_function(request.system)(q[0], t[0], request.theta)[1], float)
    g_size = np.abs(G).reshape(m, n) @ sizes[:n]
    radian = abs(t[-1] - t[0]) / (2 * np.pi)
    return {"canonical": np.maximum(tol * sizes, BOUNDS_ALLOWED * body[:2 * n]),
            "energy": energy, "prescribed_energy": energy,
            "closure": np.maximum(tol * sizes, BOUNDS_ALLOWED * targets[end:end + 2 * n]),
            "section": max(tol * np.r_[abs(t[-1] - t[0]), sizes][closure.section_index],
                           BOUNDS_ALLOWED * targets[1]),
            "g": np.maximum(tol * g_size, BOUNDS_ALLOWED * body[2 * n + m:2 * n + 2 * m]),
            "hidden": np.maximum(tol * g_size / radian if radian > 0 else 0.0,
                                 BOUNDS_ALLOWED * body[2 * n:2 * n + m]),
            "unused_multipliers": BOUNDS_ALLOWED * targets[end + 2 * n:]}


def _run(solver, request: GridRequest, grid, x0, closure, scale) -> GridResult:
    if solver == "newton":
        return closed_newton(grid, x0, closure, request, scale)
    began = time.perf_counter()
    problem = request.built(("constrained_closed_ipopt", request.intervals, closure.section_index,
                             request.tol, request.max_iter, request.verbose),
                            lambda: _ipopt(request, grid, closure.section_index))
    request.build_s += time.perf_counter() - began
    steps = request.intervals
    rows = grid.layout.size
    _, jacobian = grid.evaluate(x0, closure, jacobian=True)
    layout = grid.layout
    sizes = node_grid_sizes(grid.sparse(jacobian), x0, layout.nodes, layout.width,
                            1 + 2 * layout.n, steps, _sizes(request, grid, x0))
    result = problem.solve(x0, p=closure.vector(),
                           lbg=np.r_[np.zeros(rows), np.full(steps, request.tau_floor)],
                           ubg=np.r_[np.zeros(rows), np.full(steps, np.inf)], sizes=sizes)
    result.outcome = f"ipopt: {result.outcome} after {result.iterations} iterations"
    return result


def _ipopt(request, grid: ConstrainedClosedGrid, section_index: int) -> FeasibilityNlp:
    """IPOPT on the same rows (objective 0, ``orbit_nlp.py``'s reasons), steps bounded below,
    on the unknowns and rows divided by their sizes (`grid.ipopt.node_grid_sizes`)."""
    t = grid.x[:grid.layout.nodes * grid.layout.width:grid.layout.width]
    g = ca.vertcat(grid.rows_expression(section_index), t[1:] - t[:-1])
    settings = ipopt_settings(request.tol, request.max_iter, request.verbose,
                              request.remaining(), dict(DEFAULT_OPTIONS))
    return FeasibilityNlp("constrained_periodic", grid.x, grid.P, g, settings, scaled=True)


def _solution(request: GridRequest, grid, result, closure, scale, started) -> Solution:
    """The point verified by its unscaled residuals, then judged against the exact flow."""
    orbit, system = request.data, request.system
    t, q, p, multipliers, unfolding = grid.layout.unpack(result.x)
    finite = bool(np.all(np.isfinite(result.x)))
    parts = grid.parts(result.x, closure) if finite else None
    # the names of an unconstrained orbit's residuals (OrbitRecord), then the constraints'
    names = {"canonical": "interval", "energy": "energy", "prescribed_energy": "prescribed",
             "closure": "closure", "section": "section", "g": "g", "hidden": "hidden",
             "unused_multipliers": "unused"}
    if finite:
        sizes = _sizes(request, grid, result.x)
        limits = _limits(request, grid, result.x, closure,
                         _targets(request, grid, result.x, closure, sizes), sizes)
        worst, limit = worst_against({name: parts[part] for name, part in names.items()},
                                     limits)
    else:
        worst = dict.fromkeys(names, np.nan)
        limit = dict.fromkeys(names, np.nan)
    status, message = closed_verdict(result, worst, limit, np.diff(t),
                                     found="periodic orbit of a constrained system")
    report, local = (None, np.zeros(0))
    if finite:
        report, local = _accuracy(request, t, np.hstack([q, p]))
    found = OrbitRecord(period=float(t[-1] - t[0]), energy=orbit.energy, section=orbit.label,
                        unfolding=float(unfolding[0]),
                        integral_unfoldings=tuple(unfolding[1:].tolist()),
                        residual_limit=limit, winding=(0,) * system.n, residuals=worst,
                        tau_min=float(np.min(np.diff(t))), tau_max=float(np.max(np.diff(t))))
    nan = np.full((request.intervals, 1), np.nan)
    solution = Solution(t=t, q=q, p=p, status=status, message=message, scheme=request.scheme.rule,
                        energy_residual=parts["energy"] if finite else nan[:, 0],
                        canonical_residual=np.max(np.abs(parts["interval"]), axis=1)
                        if finite else nan[:, 0],
                        newton_iterations=result.iterations,
                        timing={"build_s": request.build_s,
                                "solve_s": time.perf_counter() - started - request.build_s},
                        stats={"iterations": result.iterations, "outcome": result.outcome},
                        orbit=found)
    solution.constraints = ConstrainedOrbitRecord(
        np.abs(parts["g"] if finite else nan).max(axis=1),
        np.abs(parts["hidden"] if finite else nan).max(axis=1), multipliers, orbit.moved, limit)
    judge(solution, report, request.options.accuracy, local_error=local,
          advice="try more nodes")
    return solution


def _accuracy(request: GridRequest, t, z):
    """Every interval against the constrained exact flow, the level against ``E``, and the
    flow from node 0 staying on the orbit over the period (``drifted`` becomes
    ``inaccurate``: the discrete orbit is not an orbit of the flow)."""
    check = Judgement(request.system, request.theta, request.options.accuracy,
                      compiler=find_compiler(request.compilation.compiler),
                      cache_dir=request.compilation.cache_dir)
    level = Level(request.data.energy, float(t[0] + (t[1] - t[0]) / 2))
    report, local = check.report(t, z, level=level)
    if report["verdict"] == "drifted":
        step = int(report["drift_step"])
        report["verdict"] = "inaccurate"
        report["first_failure"] = {
            "step": step - 1, "t": float(t[step]), "test": "closure of the exact flow",
            "value": report["error_max"], "limit": report["global_tol"],
            "detail": (f"the constrained exact flow from the orbit's first node leaves the "
                       f"orbit by {report['error_max']:.3e} of its size at t = {t[step]:.6g} "
                       f"(period {t[-1] - t[0]:.10g}): it does not close; more nodes resolve "
                       "the orbit better")}
    return report, local


__all__ = ["ConstrainedOrbitRecord", "at_energy", "checked_request",
           "solve_constrained_periodic"]
