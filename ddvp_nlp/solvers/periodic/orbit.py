"""Periodic orbits at a prescribed energy: the discrete action with free node times, closed on
itself (docs/theory.md sections 2, 3, 6).

For autonomous ``H`` and ``N`` intervals the unknowns are the node states ``z_0 .. z_N`` and the
node times ``t_0 .. t_N``; ``t_N - t_0`` is the period. The scheme's equations:

- the canonical equations of every interval ``k = 0 .. N-1``: ``2n N``;
- the energy equation at every interior node ``1 .. N-1`` and at the wrap-around node (interval
  ``N-1`` against interval ``0``): ``N``. For autonomous ``H`` both rules (``vddvp``, ``lee``)
  read ``H_k = H_{k-1}`` with ``H_k = H(Q_k, P_k)``;
- the prescribed energy ``H_0 = E``: 1;
- closure ``q_N = q_0``, ``p_N = p_0``: ``2n``;
- ``t_0 = 0`` and the phase condition ``z_0[section] = value``: 2.

That is ``2nN + N + 2n + 3`` equations for ``(N+1)(2n+1) = 2nN + N + 2n + 1`` unknowns, two too
many, and the count is made square as follows.

1. The wrap-around energy equation is dependent: the interior ones chain ``H_0 = H_1 = ... =
   H_{N-1}``, which contains ``H_{N-1} = H_0``. It is dropped; the remaining ``N`` energy
   equations, with the prescribed one, are equivalent to ``H_k = E`` for every interval, and
   that is how they are written (one row per interval, no differences of nearly equal numbers,
   no ``O(tau)`` derivative to rescale). The scheme's own energy equations, wrap-around
   included, are recomputed on the result and reported.
2. The continuous problem has a one-parameter family of solutions (the time shift) and one
   dependent closure equation (energy is conserved by the flow); the phase condition removes
   the first, the dependency removes one equation. The discrete problem has neither exactly: the
   nodes of the midpoint rule do not lie on one level set of a conserved function, and shifting
   the nodes along the orbit is a symmetry only up to a tiny defect (for ``n = 1`` the nodes
   are an outer billiard orbit of the level curve, whose periodic orbits of a given rotation
   number are isolated, two of them, with actions that differ by an amount exponentially small
   in ``N`` for analytic ``H``). Without the phase condition the Jacobian is singular to
   round-off; with it and nothing else the system is overdetermined by one. So the phase
   condition is kept and one unknown is added, the unfolding ``lambda`` of Munoz-Almaraz,
   Freire, Galan, Doedel and Vanderbauwhede (2003): the canonical equations become
   ``z_{k+1} - z_k = tau_k (J + lambda I) grad H(Q_k, P_k)``. Along a closed orbit ``lambda = 0``
   wherever the phase condition is compatible with a discrete orbit (a symmetric section of a
   reversible system, or a rotationally symmetric one); otherwise ``lambda`` measures the
   defect. Either way the canonical residuals are verified *without* ``lambda``: a point with a
   ``lambda`` above round-off fails its verification.

Square count: ``(N+1)(2n+1) + 1`` unknowns (nodes and ``lambda``); equations ``2nN``
(canonical) ``+ N`` (``H_k = E``) ``+ 2n`` (closure) ``+ 2`` (``t_0``, section).

3. Continuous symmetries besides the time shift (translations and rotations of the three-body
   problem) are exact symmetries of the discrete equations too, and the midpoint rule conserves
   their integrals (linear and quadratic) exactly: each adds a direction of solutions and a
   dependent closure equation. Each integral ``I_i`` given in ``integrals`` gets the same
   treatment as ``H``: a phase condition ``g_i . (z_0 - z_0^ref) = 0`` (``g_i = J grad I_i`` at
   the start's node 0) and an unfolding parameter ``mu_i`` (``+ tau_k mu_i grad I_i`` in the
   canonical equations); the count stays square with ``r`` more rows and unknowns. The Jacobian
(``closed_grid.py``) is the fixed-endpoint solver's band plus corner entries (closure) and a
full column (``lambda``): sparse LU (SuperLU), in the grid's Newton iteration
(``grid/newton.py``: its ``tau_floor`` safeguard and Deuflhard's monotonicity line search).

The same rows are also handed to IPOPT (``orbit_nlp.py``: objective 0, the rows as
equality constraints, the steps bounded below, exact Hessian). ``solver="auto"`` runs Newton and,
when its point fails the verification, IPOPT from the same start.

The start decides. On the pendulum's rotations the solution's steps have a spike (3-5x the
others at N = 100..800) where the level curve ``p(q)`` has an inflection: there the ``tau_k^2``
term of the interval energy ``H(Q_k, P_k)`` (the chord's midpoint against the curve,
``-tau^2 w / 8`` with ``w = f' H_zz f``) changes sign, and the energy equation barely fixes
``tau_k``. From the march's uniform times Newton's monotone line search stalled at every N and
IPOPT's filter line search got there in 13, 28, 69, 296 iterations for N = 100, 200, 400, 800
at E = 2.5. The default start is therefore the march on the predicted grid ``tau ~
|w|^(-1/3)`` (``start.predicted_grid``), solved on a coarse grid first and refined by
continuation in N (``arclength.py``: 100, 200, 400, 800, resampled by node index so that
each level starts with the step distribution of the last): 5 Newton iterations on every level,
0.11 s CPU to N = 800 in all (measured). A user's guess is solved on N as it is.

Rotations: a coordinate named in ``angles`` is an angle (``H`` is ``2 pi``-periodic in it); the
closure rows read ``q_N - q_0 = 2 pi w`` with the number of turns ``w`` taken from the start (a
march returns to a section on an angle one turn on), and the wrap-around energy equation uses
node 1 shifted by ``2 pi w``.

Every returned point, whichever solver found it, is verified by its own unscaled residuals
(closure, canonical, the scheme's energy equations, the prescribed energy, the section, every
step positive), then by the accuracy check of ``accuracy/judgement.py``, which does not trust the
scheme's equations: each interval against the exact flow, the level against ``E``, and the
closure of the exact flow from the first node over the period (status ``inaccurate`` when a
test fails: a grid too coarse to resolve the orbit is refused). The start: ``first_orbit.py``.
"""

from __future__ import annotations

import re
import time
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from ...discrete import equations
from ...discrete.scheme import Scheme
from ...errors import InputError
from ...physics.hamiltonian import HamiltonianSystem, symplectic_weights
from ...solution import OrbitRecord, Solution, Status
from ...validation import check_angles, check_integer, check_real, check_state
from ..accuracy.judgement import Judgement, Level, judge
from ..compiler import find_compiler
from ..exact.closure import nearest_exact_orbit
from ..grid.motion_size import orbit_sizes
from ..grid.newton import newton
from ..grid.policy import Attempt, Stage, solve_in_order, solver_order, worst_against
from ..grid.problem import GridRequest, check_energy_problem
from ..options import GridOptions, answers_removed_keywords, coerce
from .closed_grid import (
    Closure,
    PeriodicAssembly,
    closed_limits,
    closed_newton,
    closed_targets,
    closed_verdict,
    integral_gradients,
    unfolding_metric,
)
from .first_orbit import (
    NoMotion,
    closing_shift,
    guess_nodes,
    march_to_return,
    predicted_grid,
    section_point,
)
from .orbit_derivatives import check_derivatives, orbit_derivatives
from .orbit_nlp import periodic_ipopt, scaled_sizes
from .refinement import continue_in_nodes, node_levels

# The defaults of GridOptions' None fields for this problem.
DEFAULT_MAX_ITER = 100
SECTION = re.compile(r"^\s*([qp])(\d+)\s*=\s*(.+?)\s*$")


def parse_section(section, n: int) -> tuple[int, float, str]:
    """``(index in z = (t, q, p), value, label)`` of ``"q1=0.5"`` / ``"p2=0"`` or of a pair
    ``("p1", 0.0)``; coordinates count from 1."""
    text = f"{section[0]}={section[1]}" if isinstance(section, tuple) else section
    match = SECTION.match(text) if isinstance(text, str) else None
    if match is None:
        raise InputError(f"section must be NAME=VALUE with NAME one of q1..q{n}, p1..p{n}, "
                         f"got {section!r}")
    kind, number = match.group(1), int(match.group(2))
    if not 1 <= number <= n:
        raise InputError(f"section names no coordinate: {kind}{number} (the system has "
                         f"q1..q{n}, p1..p{n}), got {section!r}")
    try:
        value = float(match.group(3))
    except ValueError:
        raise InputError(f"section value must be a real number, got {section!r}") from None
    check_real("section value", value)
    index = number if kind == "q" else n + number
    return index, value, f"{kind}{number}={value:g}"


@dataclass
class Orbit:
    """The data of a periodic problem (the ``data`` of its `GridRequest`): the
    prescribed energy, the section (index into ``z = (t, q, p)``, value, label), the angle
    coordinates, the direction along which the section's point is looked for, and the start:
    that ``point`` (marched to its return) or the user's ``guess`` nodes."""

    energy: float
    index: int
    value: float
    label: str
    angles: tuple
    direction: np.ndarray
    point: np.ndarray | None = None
    guess: tuple | None = None
    start_note: str | None = None


@answers_removed_keywords
def solve_periodic(system: HamiltonianSystem, *, energy: float, nodes: int,
                   section="p1=0", guess: Solution | Mapping | None = None,
                   scheme: str | Scheme = "vddvp", params: Mapping[str, float] | None = None,
                   start=None, integrals=(), angles=(),
                   options: GridOptions | None = None, derivatives=None) -> Solution:
    """A periodic orbit of ``system`` at energy ``E`` on a closed grid of ``nodes`` nodes,
    ``N = nodes - 1`` intervals (module docstring).

    Args:
        system: an autonomous Hamiltonian (or Lagrangian) system.
        energy: the prescribed interval energy ``E = H(Q_k, P_k)``.
        nodes: the number of nodes ``N + 1 >= 4`` of the closed grid, the last equal to the
            first shifted by the period (as every solver counts them: ``nodes`` rows in the
            result).
        section: the phase condition on node 0, ``"NAME=VALUE"`` with ``NAME`` in ``q1..qn``,
            ``p1..pn``, or a pair ``(NAME, VALUE)``.
        guess: a start (a `Solution` or a mapping with ``t``, ``q``, ``p`` over one
            period); default: the march from the section's point at ``E`` to its return
            (``first_orbit.py``).
        scheme: ``"vddvp"`` or ``"lee"`` (the same equations for autonomous ``H``).
        params: the system's parameter values.
        start: ``(q, p)``: the direction along which the section's point at ``E`` is looked for
            (``start.section_point``); default all ones.
        integrals: first integrals ``I(q, p)`` (functions on CasADi symbols) besides ``H``
            whose flows are symmetries of ``H`` (total momentum: translations; angular
            momentum: rotations). Each makes one more direction of solutions and one more
            dependent closure equation; each gets a phase condition ``g . (z_0 - z_0^ref) = 0``
            (``g = J grad I`` at the start's node 0) and an unfolding parameter ``mu``, as
            ``H`` gets the section and ``lambda`` (module docstring).
        angles: names of coordinates that are angles (``"q1"``; ``H`` ``2 pi``-periodic in
            them): the orbit may close with ``q_N = q_0 + 2 pi w`` (a rotation, ``w`` turns,
            taken from the start), and the return to a section on an angle is counted modulo
            ``2 pi``.
        options: the solver (``"newton"``: sparse LU in the grid's Newton, ``"ipopt"``:
            ``orbit_nlp.py``, ``"auto"``: Newton, then IPOPT from the same start when Newton's point
            fails the verification of its residuals), the verification tolerance ``tol``
            (default 1e-10) of the unscaled residuals above their round-off, ``max_iter`` of
            either solver (default 100) and IPOPT's log (`GridOptions`).
        derivatives: names from ``("energy", "params")``: the derivatives of the discrete
            orbit (its period and nodes) in them, by the implicit-function theorem on the
            verified orbit (``orbit_derivatives.py``), into ``Solution.derivatives``.

    Returns:
        A `Solution` with ``N + 1`` nodes; ``orbit`` (`OrbitRecord`) holds ``period``,
        ``energy``, ``unfolding`` (``lambda``), ``winding`` and the largest residuals of each
        kind, ``verdict`` the accuracy check (every interval against the exact flow, the
        orbit's energy against the one prescribed, and the exact flow from the first node
        closing on the orbit over the period: `_accuracy`) and
        ``stats`` the solver's counts and ``attempts``; ``energy_residual`` holds the
        scheme's energy equation at nodes ``1 .. N`` (node ``N`` the wrap-around). No orbit
        found is a failure status with the residuals in the message; an orbit whose steps
        do not follow the exact flow is ``inaccurate``.
    """
    if getattr(system, "n_constraints", 0):  # constrained_orbit.py
        from .constrained_orbit import solve_constrained_periodic
        return solve_constrained_periodic(
            system, energy=energy, nodes=nodes, section=parse_section(section, system.n),
            guess=guess, scheme=scheme,
            params=params, start=start, integrals=check_integrals(integrals), angles=angles,
            options=coerce(options, GridOptions, "options"), derivatives=derivatives)
    integrals = check_integrals(integrals)
    names = check_derivatives(system, derivatives)
    request = _checked(system, energy, nodes, section, guess, scheme, params, start, angles,
                       coerce(options, GridOptions, "options"))
    started = request.start_clock()
    intervals = request.intervals
    levels = node_levels(intervals) if request.data.guess is None else [intervals]
    t, z = _start_nodes(request, levels[0])

    def solve_level(intervals, t, z):
        return _solve_on(replace(request, nodes=intervals + 1, phases=[]), t, z, integrals,
                         started)

    solution, records = continue_in_nodes(solve_level, t, z, levels, request.data.angles)
    if solution.status not in (Status.SUCCESS, Status.INACCURATE) \
            and records[-1]["intervals"] != intervals and request.data.start_note is None:
        # a level below N failed (the first one too): the predicted grid at N itself, as
        # without continuation
        fallback = solve_level(intervals, *_start_nodes(request, intervals))
        records.append({"intervals": intervals, "status": fallback.status.code,
                        "iterations": fallback.newton_iterations, "from": "predicted grid"})
        solution = fallback
    solution.stats["levels"] = records
    solution.stats["iterations_total"] = sum(r["iterations"] for r in records)
    if names:
        solution.derivatives = orbit_derivatives(request, solution, integrals, names)
    return solution


def _solve_on(request: GridRequest[Orbit], t, z, integrals, started) -> Solution:
    """The orbit on ``request.intervals`` intervals from the nodes ``(t, z)``: each solver of
    the request's option in turn until one's point holds the equations."""
    system, intervals = request.system, request.intervals
    closure = _closure(request, t, z, integrals)
    began = time.perf_counter()
    assembly = PeriodicAssembly(system, request.scheme, intervals, integrals)
    request.build_s += time.perf_counter() - began
    x0 = assembly.layout.pack(t, z[:, :system.n], z[:, system.n:])
    sizes = _sizes(request, t, z)
    scale = closed_targets(assembly, x0, closure, sizes)
    request.tau_floor = _tau_floor(request, t[-1])
    attempts = []

    def attempt(solver: str) -> Attempt:
        began, cpu = time.perf_counter(), time.process_time()
        result = _run(solver, request, assembly, x0, closure, scale, integrals)
        solution = _solution(request, assembly, result, scale, started, closure, integrals)
        solution.stats["solver"] = solver
        stage = Stage("periodic orbit", solver, result.converged, result.outcome,
                      result.iterations, time.perf_counter() - began)
        request.phases.append(stage)
        attempts.append({"solver": solver, "status": solution.status.code,
                         "iterations": result.iterations, "said": result.outcome,
                         "wall_s": stage.seconds, "cpu_s": time.process_time() - cpu})
        return Attempt(result.x, stage, (solution.status, solution.message, solution))

    # an inaccurate orbit holds the equations: another solver would find the same grid
    chosen, _, _ = solve_in_order(solver_order(request.solver), attempt,
                                  enough=(Status.SUCCESS, Status.INACCURATE, Status.TIME_LIMIT))
    solution = chosen.outcome[2]
    solution.stats["attempts"] = attempts
    return _noted(solution, attempts)


def _run(name, request: GridRequest[Orbit], assembly, x0, closure, targets, integrals):
    """One solver from ``x0``: the grid's Newton to the rows' ``targets``, or IPOPT then the
    grid's Newton from IPOPT's point (`_polished`), as a ``GridResult``."""
    if name == "newton":
        return closed_newton(assembly, x0, closure, request, targets)
    _, jacobian = assembly.evaluate(x0, closure, jacobian=True)
    z = x0[:(request.intervals + 1) * assembly.layout.m].reshape(request.intervals + 1, -1)
    sizes = scaled_sizes(assembly.layout, assembly.sparse(jacobian), x0,
                         _sizes(request, z[:, 0], z[:, 1:]))
    began = time.perf_counter()  # the build (or the cache's answer) counts as build time
    # IPOPT works on the rows scaled by their sizes (`orbit_nlp.scaled_sizes`), and its
    # tolerance is one number for all: never below the largest row's round-off in those
    # units (a decade up, so that nearby starts share the build)
    scaled = targets / sizes[1][:targets.size]
    floor = 10.0 ** np.ceil(np.log10(float(np.max(scaled))))
    problem = periodic_ipopt(request.system, request.scheme, request.intervals, integrals,
                             request.data.index, tol=max(request.tol, floor),
                             max_iter=request.max_iter, verbose=request.verbose,
                             time_limit=request.remaining())
    request.build_s += time.perf_counter() - began
    return _polished(problem.solve(x0, closure, request.tau_floor, sizes), request, assembly,
                     closure, targets)


# Newton's iterations from IPOPT's point: it is at or near a root, so a few full-size steps
# bring every row to its own target.
POLISH_ITERATIONS = 6


def _polished(result, request, assembly, closure, targets):
    """IPOPT's ``result`` taken on by the grid's Newton to each row's own target: IPOPT stops
    at one tolerance for rows in several units (the canonical rows of each coordinate, the
    energy rows), which cannot be every row's, so its point is finished where the rows are
    judged. Newton's point is kept where it converges, IPOPT's otherwise."""
    if not np.all(np.isfinite(result.x)):
        return result
    finish = newton(assembly, result.x, closure, targets, tau_floor=request.tau_floor,
                    max_iter=POLISH_ITERATIONS, linear="sparse", deadline=request.deadline)
    if finish.converged:
        result.x, result.converged = finish.x, True
    result.iterations += finish.iterations
    result.outcome += f"; Newton from its point: {finish.outcome}"
    return result


def _tau_floor(request: GridRequest, period: float) -> float:
    """``options.tau_floor`` if given (below the start's mean step), else a thousandth of the
    start's mean step."""
    mean = period / request.intervals
    floor = request.options.tau_floor
    if floor is None:
        return 1e-3 * period / request.intervals
    if floor >= mean:
        raise InputError(f"tau_floor must be < the start's mean step {mean!r}, got {floor!r}")
    return floor


def _noted(solution: Solution, attempts: list) -> Solution:
    """``solution`` with the other attempts named in its message (``auto``)."""
    others = [a for a in attempts if a["solver"] != solution.stats["solver"]]
    if others:
        solution.message += "; " + "; ".join(
            f"{a['solver']} also tried: {a['status']} ({a['said']})" for a in others)
    return solution


def check_periodic(system, *, energy, nodes, section="p1=0", scheme="vddvp", params=None,
                   start=None, integrals=(), angles=(), options=None) -> None:
    """Raise the ``InputError`` `solve_periodic` would raise for these arguments without
    a guess (the section's point at ``energy`` included), and build nothing."""
    integrals = check_integrals(integrals)
    if getattr(system, "n_constraints", 0):
        from .constrained_orbit import checked_request
        checked_request(system, energy, nodes, parse_section(section, system.n), None, scheme,
                        params, start, integrals, angles, coerce(options, GridOptions, "options"),
                        None, start_required=False)  # a family's caller may give a guess
        return
    _checked(system, energy, nodes, section, None, scheme, params, start, angles,
             coerce(options, GridOptions, "options"))


def _closure(request: GridRequest[Orbit], t: np.ndarray, z: np.ndarray, integrals) -> Closure:
    """The problem's data; the phase conditions of the integrals at the start's node 0, the
    closure shift (turns of the angle coordinates) from the start's ends, the unfolding's
    metric from the symplectic weights at the start's node 0 and its period
    (`closed_grid.unfolding_metric`)."""
    system, orbit = request.system, request.data
    n = system.n
    reference = z[0]
    generators = np.zeros((len(integrals), 2 * n))
    if integrals:
        gradients = np.asarray(integral_gradients(system, integrals)(
            reference[:n], reference[n:], request.theta))[:, 1:].T
        generators = np.hstack([gradients[:, n:], -gradients[:, :n]])  # J grad I
    return Closure(orbit.energy, orbit.index, orbit.value, request.theta, reference.copy(),
                   generators, closing_shift(z[0], z[-1], orbit.angles),
                   unfolding_metric(symplectic_weights(system, z[0], 0.0, request.theta),
                                    float(t[-1] - t[0])))


def _checked(system, energy, nodes, section, guess, scheme, params, start, angles,
             options: GridOptions) -> GridRequest[Orbit]:
    """Every argument checked (``InputError`` naming argument and value) before any build."""
    scheme = Scheme.coerce(scheme)
    if not isinstance(system, HamiltonianSystem):
        raise InputError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
    check_energy_problem(system, scheme, "a periodic orbit at a prescribed energy")
    if options.linear == "banded":
        raise InputError("linear must be 'auto' or 'sparse' for a periodic orbit (its "
                         "Jacobian has closure rows in a corner and a full unfolding column: "
                         "not banded), got 'banded'")
    energy = check_real("energy", energy)
    intervals = check_integer("nodes", nodes, minimum=4) - 1
    index, value, label = parse_section(section, system.n)
    n = system.n
    angle_indices = check_angles(angles, n)
    direction = np.ones(2 * n)
    if start is not None:
        try:
            q, p = start
        except (TypeError, ValueError):
            raise InputError(f"start must be a pair (q, p), got {start!r}") from None
        direction = np.concatenate([check_state("start q", q, n), check_state("start p", p, n)])
    theta = system.parameter_vector(params)
    orbit = Orbit(energy, index, value, label, angle_indices, direction)
    if guess is None:
        try:
            orbit.point = section_point(system, theta, energy, index, value, direction, label)
        except NoMotion:  # below the least energy: another section cannot help
            raise
        except InputError as error:
            if angle_indices and index - 1 not in angle_indices:
                raise InputError(f"{error}; a rotation of the angle q{angle_indices[0] + 1} "
                                 f"has a section on it, e.g. q{angle_indices[0] + 1}=0") \
                    from None
            raise
    else:
        orbit.guess = guess_nodes(guess, n, intervals, angle_indices)
    return GridRequest(system, scheme, intervals + 1, theta, orbit,
                       options.resolved(max_iter=DEFAULT_MAX_ITER))


def check_integrals(integrals) -> tuple:
    """``integrals`` as a tuple of functions ``I(q, p)``."""
    try:
        integrals = tuple(integrals)
    except TypeError:
        integrals = (integrals,)
    if not all(callable(integral) for integral in integrals):
        raise InputError(f"integrals must be functions I(q, p), got {integrals!r}")
    return integrals


def _start_nodes(request: GridRequest[Orbit], intervals: int):
    """``(t, z)`` of ``intervals + 1`` nodes: the user's guess, or the march to the return on
    the predicted grid (``start.predicted_grid``; a march that does not return leaves the
    point repeated: the solve then fails with a status)."""
    orbit = request.data
    if orbit.guess is not None:
        return orbit.guess
    angle = orbit.index - 1 in orbit.angles
    traced = march_to_return(request.system, request.theta, orbit.point, orbit.index,
                             orbit.value, request.scheme, angle)
    if traced is None:
        orbit.start_note = "the march from the section's point did not return to it"
        return np.linspace(0.0, 1.0, intervals + 1), np.tile(orbit.point, (intervals + 1, 1))
    return predicted_grid(request.system, request.theta, *traced, intervals, orbit.angles)


def periodic_residuals(system, scheme: Scheme, t, q, p, theta, energy: float, shift=0.0):
    """The scheme's equations on a closed grid of ``N + 1`` nodes, unscaled: ``canonical (N,
    2n)`` (increment form), ``energy (N,)`` (the scheme's energy equation at nodes ``1 .. N-1``
    and at the wrap-around node, interval ``N-1`` against interval ``0``, node ``N + 1`` being
    node 1 shifted by ``shift``), ``prescribed`` (``H_0 - E``), ``closure (2n,)`` (``z_N - z_0 -
    shift``; ``shift`` is ``2 pi`` times the turns of the angle coordinates)."""
    n = q.shape[1]
    shift = np.broadcast_to(np.asarray(shift, float), (2 * n,))
    canonical, interior = equations.grid_residuals(system, scheme, t, q, p, theta)
    wrap_t = [t[-2], t[-1], t[-1] + t[1] - t[0]]
    _, wrap = equations.grid_residuals(system, scheme, wrap_t,
                                       np.vstack([q[-2:], q[1:2] + shift[:n]]),
                                       np.vstack([p[-2:], p[1:2] + shift[n:]]), theta)
    first = equations.interval_energies(system, scheme, t[:2], q[:2], p[:2], theta)[0]
    closure = np.concatenate([q[-1] - q[0], p[-1] - p[0]]) - shift
    return canonical, np.concatenate([interior, wrap]), float(first - energy), closure


def _solution(request: GridRequest[Orbit], assembly, result, scale, started,
              closure, integrals=()) -> Solution:
    """The point ``result.x`` verified (whichever solver found it): its unscaled residuals
    recomputed, then the accuracy check against the exact flow."""
    system, scheme, orbit = request.system, request.scheme, request.data
    t, q, p, unfolding = assembly.layout.unpack(result.x)
    finite = bool(np.all(np.isfinite(result.x)))
    N, n = request.intervals, system.n
    if finite:
        canonical, energy, prescribed, closing = periodic_residuals(
            system, scheme, t, q, p, request.theta, orbit.energy, closure.shift)
    else:
        canonical, energy = np.full((N, 2 * n), np.nan), np.full(N, np.nan)
        prescribed, closing = np.nan, np.full(2 * n, np.nan)
    section = float(np.concatenate([[t[0]], q[0], p[0]])[orbit.index] - orbit.value)
    sizes = _sizes(request, t, np.hstack([q, p])) if finite else np.ones(2 * n)
    if finite:  # the rows' round-off where the point is
        scale = closed_targets(assembly, result.x, closure, sizes)
    limits = closed_limits(assembly, result.x, closure, scale, request.tol, sizes)
    worst, limit = worst_against({"canonical": canonical, "energy": energy,
                                  "prescribed_energy": prescribed, "closure": closing,
                                  "section": section}, limits)
    status, message = closed_verdict(result, worst, limit, np.diff(t), orbit.start_note)
    accuracy, local_error = None, np.zeros(0)
    if finite:
        accuracy, local_error = _accuracy(request, t, q, p, closure, integrals)
    winding = np.round(np.asarray(closure.shift, float) / (2 * np.pi)) * np.ones(2 * n)
    found = OrbitRecord(period=float(t[-1] - t[0]), energy=orbit.energy, section=orbit.label,
                        unfolding=float(unfolding[0]),
                        integral_unfoldings=tuple(unfolding[1:].tolist()),
                        residual_limit=limit, winding=tuple(int(winding[i]) for i in range(n)),
                        residuals=worst, tau_min=float(np.min(np.diff(t))),
                        tau_max=float(np.max(np.diff(t))))
    solution = Solution(t=t, q=q, p=p, status=status, message=message, scheme=scheme.rule,
                        energy_residual=energy,
                        canonical_residual=np.max(np.abs(canonical), axis=1),
                        newton_iterations=result.iterations,
                        timing={"build_s": request.build_s,
                                "solve_s": time.perf_counter() - started - request.build_s},
                        stats={"iterations": result.iterations, "outcome": result.outcome},
                        orbit=found)
    judge(solution, accuracy, request.options.accuracy, local_error=local_error,
          advice="try more nodes")
    return solution


def _sizes(request: GridRequest[Orbit], t, z) -> np.ndarray:
    """The orbit's size in each coordinate (`grid.motion_size.orbit_sizes`)."""
    return orbit_sizes(request.system, request.theta, t, z)


def _accuracy(request: GridRequest[Orbit], t, q, p, closure: Closure, integrals=()):
    """The accuracy check of an orbit against the exact flow (``accuracy/judgement.py``): every
    interval (a grid too coarse to resolve the orbit fails here), the energy of the orbit through
    the first node against the one prescribed, and the closure of the exact flow: the flow from
    the first node must stay within ``global_tol`` of the orbit over the whole period, or, where
    it does not (an unstable orbit amplifies node 0's error), the exact periodic orbit nearest
    it (multiple shooting on segments cut by the flow's growth, `nearest_exact_orbit`) must;
    else the orbit is refused (``inaccurate``: it is not an orbit of the exact flow)."""
    check = Judgement(request.system, request.theta, request.options.accuracy,
                      compiler=find_compiler(request.compilation.compiler),
                      cache_dir=request.compilation.cache_dir)
    level = Level(request.data.energy, float(t[0] + (t[1] - t[0]) / 2))
    report, local = check.report(t, np.hstack([q, p]), level=level)
    if report["verdict"] == "drifted":
        report, local = _against_nearest(check, request, t, np.hstack([q, p]), level, closure,
                                         integrals, (report, local))
    if report["verdict"] == "drifted":
        report["verdict"] = "inaccurate"
        report["first_failure"] = {
            "step": int(report["drift_step"]) - 1, "t": float(t[report["drift_step"]]),
            "test": "closure of the exact flow", "value": report["error_max"],
            "limit": report["global_tol"],
            "detail": (f"the exact flow from the orbit's first node leaves the orbit by "
                       f"{report['error_max']:.3e} of its size at t = "
                       f"{t[report['drift_step']]:.6g} (period {t[-1] - t[0]:.10g}): it does "
                       "not close; more nodes resolve the orbit better")}
    return report, local


def _against_nearest(check, request, t, z, level, closure, integrals, single):
    """The report against the exact periodic orbit nearest ``(t, z)`` where it is found and
    the orbit stays within ``global_tol`` of it, else ``single`` (the report against the flow
    from node 0)."""
    exact = nearest_exact_orbit(request.system, request.theta, t, z,
                                energy=request.data.energy, section_index=request.data.index,
                                section_value=request.data.value, integrals=integrals,
                                shift=closure.shift)
    if not exact.converged:
        return single
    report, local = check.report(t, z, level=level, exact=lambda times: exact.states(
        request.system, request.theta, np.asarray(times, float) - float(t[0])))
    if report["verdict"] == "drifted":
        return single
    report["estimate"] = (f"the exact periodic orbit nearest this one (multiple shooting on "
                          f"{exact.cuts.size - 1} segments cut by the flow's growth, DOP853; "
                          f"closure {exact.closure:.1e} of its size; the flow from node 0 alone "
                          f"leaves the orbit by {single[0]['error_max']:.2e}: it is unstable)")
    return report, local


