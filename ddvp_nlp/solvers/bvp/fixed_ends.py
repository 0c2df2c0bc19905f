"""Fixed-endpoint problems: the whole discrete action's equations on one grid (docs/theory.md
sections 2, 4, 5).

Given ``q(t_0)``, ``q(t_end)``, ``t_0``, ``t_end`` and ``N`` nodes, the unknowns are the interior
``q``, all ``p`` and (energy rules) the interior node times; the equations are the canonical
equations of every interval (``2n(N-1)``) and the energy equation of every interior node
(``N-2``): a square system. The node times stay variables (a cumulative sum of steps would make
the Jacobian dense) and every step stays above ``tau_floor > 0``, which excludes the
time-reversed root. For a Lagrangian system the interval equations are its discrete Legendre
transform (``discrete/lagrangian_action.py``), in the same unknowns.

The system is assembled node by node (``interleaved.py``): its Jacobian is banded, with
bandwidth ``3n + 1`` whatever ``N``. Two solvers take it:

- ``"newton"``: Newton's method with banded LU, a line search on the residual and the
  ``tau_floor`` safeguard (``grid/newton.py``; blocks compiled, band LU in C, ``grid/band.py``):
  ``O(N)`` time and memory per iteration;
- ``"ipopt"``: IPOPT on the same assembly through callbacks (``ends_nlp.py``, the grid's IPOPT
  build), the design's NLP solver, on the unknowns and rows divided by their sizes
  (``phases.ipopt_scales``: the same iterations in any units). Its tolerance on the released
  times is the scaled rows' round-off where that is above ``1e-2 tol``, and it is not run
  from a start that already passes the verification (the start phases' own point, at large
  N);
- ``"auto"`` (default): Newton, 6-80x faster on the benchmark (``docs/benchmarks/bench_bvp.md``),
  then IPOPT from the same start if Newton's point does not pass the verification.

Starts: ``first_guess.py`` (straight line or shooting, then fixed steps on uniform and on predicted
times, then the times released).

Every returned point is verified by its own unscaled residuals, whatever the solver said
(IPOPT's default ``constr_viol_tol`` once accepted node times off by 3e-2): success means every
canonical residual (increment form) is below ``max(tol S, c)``, ``S`` the motion's size in the
row's units (the largest range of a position, or of a momentum, over the nodes), every energy
residual below ``max(tol h W, c_E)``, ``h`` the mean step and ``W`` the rate at which the motion
trades energy (so that ``tol`` bounds the node times relative to the motion's own time scale,
whatever ``N``), with ``c``, ``c_E`` 64 times Newton's target on the row, which is twice the
row's round-off read off the rows themselves at the point (`phases.row_round_offs`: below that
no solver can go), and every step is positive (`verification_limits`). Every scale comes from the
problem: the same solve in other units of length, momentum or time, or with the clock or the
origin shifted, gives the same nodes (``tests/library/bvp/test_fixed_ends_units.py``). The
message says what the solver said.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from ...discrete import equations
from ...discrete.scheme import Scheme
from ...errors import InputError
from ...physics.hamiltonian import HamiltonianSystem
from ...solution import EndsRecord, Solution, Status
from ...validation import check_integer, check_span, check_state
from ..accuracy.judgement import Level, judge
from ..columns import row_max_abs
from ..dense import attach
from ..grid.motion_size import energy_rate
from ..grid.policy import Attempt, Stage, failure_status, solve_in_order, solver_order
from ..grid.problem import GridRequest
from ..options import Compilation, GridOptions, Output, answers_removed_keywords, coerce
from .at_energy import AtEnergy, check_transfer, duration_guess, fixed_time_start, release_end_time
from .continuous_check import judged_against_shooting
from .end_derivatives import bvp_derivatives, check_derivatives
from .first_guess import (
    Shooting,
    branch_obstacle,
    check_guess,
    check_tau_floor,
    check_times,
    start_point,
)
from .interleaved import NodeLayout
from .phases import (
    BOUNDS_ALLOWED,
    Boundary,
    assembly,
    canonical_sizes,
    ends,
    mean_step,
    row_round_offs,
    run_phase,
)

GUESSES = ("straight", "march")
# What a failed solve from a built-in start suggests: over a long horizon the problem has many
# solutions, and the straight line (a motion that never turns) rarely leads to one (henon_heiles
# over 50 time units at N = 1e3: failed from it, solved in 7 iterations from a fixed-step march;
# measured).
START_HINT = {
    "straight": "the straight-line start may lead to another solution or to none: give "
                "guess=Shooting(p_start) (shooting, p_start near the motion's momentum) or a "
                "march's "
                "nodes as the guess",
    "march": "shooting picks the branch the march from p_start reaches: try another p_start, "
             "or a march's nodes as the guess"}
# The defaults of GridOptions' None fields for this problem.
DEFAULT_MAX_ITER = 200


@answers_removed_keywords
def solve_bvp(system: HamiltonianSystem, q_start, q_end, t_span=None, *, nodes: int,
              scheme: str | Scheme = "vddvp", params: Mapping[str, float] | None = None,
              guess: Solution | Mapping | Shooting | str | None = None, times=None,
              options: GridOptions | None = None, compilation: Compilation | None = None,
              output: Output | None = None, derivatives=None) -> Solution:
    """Solve the fixed-endpoint problem ``q(t_0) = q_start``, ``q(t_end) = q_end`` on ``nodes``.

    Args:
        system: the Hamiltonian (or Lagrangian) system.
        q_start, q_end: fixed positions at the two ends, each of shape ``(n,)``.
        t_span: ``(t0, t_end)``, the two end times; or ``AtEnergy(E, t0, duration)``: a
            transfer at the prescribed energy ``E`` with the end time an unknown
            (``at_energy.py``: the fixed-time problem at the guessed duration first, then the end
            time released; Newton only).
        nodes: number of nodes ``N >= 3``.
        scheme: ``"vddvp"``, ``"lee"``, ``"fixed"`` or a `Scheme`.
        params: the system's parameter values.
        guess: ``"straight"`` (default), shooting (``Shooting(p_start)``, the momentum it
            starts from choosing the branch of a problem with several solutions; ``"march"``
            is ``Shooting()``, from the straight line's momentum; ``first_guess.py``), or a start: a
            `Solution` (for example a march) or a mapping with ``t``, ``q``, ``p``
            arrays (``nodes`` rows, or any number of rows, resampled by node index onto
            ``nodes`` rows with the times mapped onto ``[t0, t_end]``).
        times: node times of the ``fixed`` rule (default uniform); ignored by energy rules.
        options: the solver (``"auto"``, the default, ``"newton"`` or ``"ipopt"``; module
            docstring), the verification tolerance ``tol`` (default 1e-10), ``max_iter`` per
            phase (default 200), ``tau_floor`` (default ``1e-3 (t_end - t_0)/(N-1)``), the
            linear solver, a ``time_limit`` and IPOPT's log (`GridOptions`).
        compilation: which compiled code the assembly and the band LU run.
        output: ``progress`` reports each Newton iteration (and IPOPT's log) on stderr.
        derivatives: names from ``("q_start", "q_end", "params")``: the derivatives of the
            discrete solution (the end momenta, every node) in them, by the implicit-function
            theorem on the verified solution (``end_derivatives.py``), into
            ``Solution.derivatives``.

    Returns:
        A `Solution` whose ``ends`` (`EndsRecord`) holds each stage's solver run, the largest
        residuals, the action and the number of sign changes of each ``p`` component (which of
        several solutions it is), and whose ``stats`` hold the solver's counts; failures are a
        status on it.
    """
    output = coerce(output, Output, "output")
    if getattr(system, "n_constraints", 0):  # constrained_ends.py: the rows of g = 0 too
        from .constrained_ends import solve_constrained_bvp
        return solve_constrained_bvp(
            system, q_start, q_end, t_span, nodes=nodes, scheme=scheme, params=params,
            guess=guess, times=times, options=coerce(options, GridOptions, "options"),
            compilation=coerce(compilation, Compilation, "compilation"), output=output,
            derivatives=derivatives)
    names = check_derivatives(system, derivatives, t_span)
    if output.checkpoint is not None or output.stop is not None:
        raise InputError("solve_bvp reports progress only (Output(progress=...)); checkpoint "
                         "and stop belong to a march")
    if isinstance(t_span, AtEnergy):
        return _transfer(system, q_start, q_end, t_span, nodes=nodes, scheme=scheme,
                         params=params, guess=guess, options=options, compilation=compilation,
                         output=output)
    request, start = _checked(system, q_start, q_end, t_span, nodes=nodes, scheme=scheme,
                              params=params, guess=guess, times=times,
                              options=coerce(options, GridOptions, "options"),
                              compilation=coerce(compilation, Compilation, "compilation"),
                              output=output)
    started = request.start_clock()
    start_kind = start
    start = start_point(request, start)
    layout = NodeLayout(system.n, request.nodes)
    x0 = layout.pack(np.asarray(start["t"], float), np.asarray(start["q"], float),
                     np.asarray(start["p"], float))
    name = f"{request.scheme.rule} equations"
    obstacle = []  # why IPOPT was held back, or why the first solve failed (the branch)

    def held_back(first: Attempt) -> str | None:
        obstacle.append(branch_obstacle(request, start) if request.scheme.variable_steps
                        else None)
        # IPOPT from the same start: kepler's radial branch took 200 iterations (150 s at
        # N = 1e4) to end where Newton did (measured)
        return obstacle[0]

    chosen, tried, held = solve_in_order(
        solver_order(request.solver), lambda solver: _final_phase(request, x0, name, solver,
                                                                  first=not obstacle),
        held_back=held_back)
    x, phase, outcome = chosen.x, chosen.stage, chosen.outcome
    if outcome[0] is not Status.SUCCESS and not obstacle and request.scheme.variable_steps:
        obstacle.append(branch_obstacle(request, start))  # one solver only: still say why
    reason = obstacle[0] if obstacle else None
    if held is not None:
        reason += " (IPOPT not tried from this start)"
    if reason is not None and outcome[0] is not Status.SUCCESS:
        outcome = (outcome[0], f"{outcome[1]}; {reason}", outcome[2])
    elif outcome[0] is not Status.SUCCESS and isinstance(start_kind, str) \
            and outcome[0] is not Status.TIME_LIMIT:
        outcome = (outcome[0], f"{outcome[1]}; {START_HINT[start_kind]}", outcome[2])
    solution = _solution(request, x, phase, outcome, started)
    if names:
        solution.derivatives = bvp_derivatives(request, x, solution, names)
    return attach(solution, system, request.theta, solution.t[-1] if solution.t.size else None)


def _final_phase(request: GridRequest, x0: np.ndarray, name: str, solver: str, *,
                 first: bool) -> Attempt:
    """The scheme's own system solved from ``x0`` by ``solver`` (``first``: the policy's first
    solver). IPOPT is not run first from a start that already passes the verification: the
    start phases end that close at N = 1e6 on the pendulum (inf_pr 2.5e-11), and IPOPT had
    nothing left to do but iterate on round-off (measured). Newton is always run: its targets
    are tighter than the verification."""
    if first:
        # The start phases' IPOPT problems are done with: each holds its solver's memory
        # (MUMPS's factors among it), about 3 GB at N = 1e6, while the verification builds
        # the assembly.
        request.forget(lambda key: key[0] == "bvp_ipopt" and key[1] != request.scheme)
    if solver == "ipopt" and first:
        skipped = Stage(name, solver, True, "not run: the start passes the verification")
        outcome = _outcome(request, x0, skipped)
        if outcome[0] is Status.SUCCESS:
            request.phases.append(skipped)
            return Attempt(x0, skipped, outcome)
    x, stage = run_phase(request, request.scheme, x0, name, solver)
    return Attempt(x, stage, _outcome(request, x, stage))


def _transfer(system, q_start, q_end, span: AtEnergy, *, nodes, scheme, params, guess, options,
              compilation, output) -> Solution:
    """A transfer at a prescribed energy (``at_energy.py``): the fixed-time problem at the guessed
    duration, then the end time released."""
    scheme = Scheme.coerce(scheme)
    if not isinstance(system, HamiltonianSystem):
        raise InputError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
    options = coerce(options, GridOptions, "options")
    check_transfer(system, scheme, options)
    theta = system.parameter_vector(params)
    q_a, q_b = check_state("q_start", q_start, system.n), check_state("q_end", q_end, system.n)
    duration = span.duration or duration_guess(system, theta, q_a, q_b, span.energy, guess)

    def solve_fixed(length, start):
        return solve_bvp(system, q_a, q_b, (span.t0, span.t0 + length), nodes=nodes,
                         scheme=scheme, params=params, guess=guess if start is None else start,
                         options=options, compilation=compilation, output=output)
    fixed, durations = fixed_time_start(solve_fixed, system, scheme, theta, duration,
                                        span.energy)
    if not fixed.success:
        fixed.message = (f"the fixed-time problem at the guessed duration {duration:.6g} was "
                         f"not solved, so the end time was not released: {fixed.message}")
        return fixed
    resolved = options.resolved(max_iter=DEFAULT_MAX_ITER)
    solution = release_end_time(system, scheme, fixed, span, theta, tol=resolved.tol,
                                max_iter=resolved.max_iter,
                                compilation=coerce(compilation, Compilation, "compilation"),
                                accuracy=options.accuracy)
    solution.transfer = replace(solution.transfer, fixed_time_start={"durations": durations,
                                                                     "message": fixed.message})
    return attach(solution, system, theta, solution.t[-1])


def _checked(system, q_start, q_end, t_span, *, nodes, scheme, params, guess, times,
             options: GridOptions, compilation: Compilation, output: Output):
    """The validated `GridRequest` and start (``InputError`` naming the argument and
    value, before anything is built)."""
    scheme = Scheme.coerce(scheme)
    if not isinstance(system, HamiltonianSystem):
        raise InputError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
    n = system.n
    q_start = check_state("q_start", q_start, n)
    q_end = check_state("q_end", q_end, n)
    t0, t1 = check_span(t_span)
    nodes = check_integer("nodes", nodes, minimum=3)
    options = options.resolved(max_iter=DEFAULT_MAX_ITER)
    _check_memory(nodes, n, options.solver)
    tau_floor = check_tau_floor(options.tau_floor, t0, t1, nodes)
    grid_times = check_times(times, nodes, t0, t1)
    p_start = None
    if isinstance(guess, Shooting):
        start = "march"
        if guess.p_start is not None:
            p_start = check_state("p_start", guess.p_start, n)
    elif guess is None or (isinstance(guess, str) and guess in GUESSES):
        start = guess or "straight"
    elif isinstance(guess, str):
        raise InputError(f"unknown guess {guess!r} (choose from {', '.join(GUESSES)}, or give "
                         f"Shooting(p_start), a Solution or a mapping with t, q and p)")
    else:
        start = check_guess(guess, nodes, n, t0, t1)
    request = GridRequest(system, scheme, nodes, system.parameter_vector(params),
                          Boundary(q_start, q_end, t0, t1, grid_times, p_start), options,
                          compilation, tau_floor=tau_floor, progress=output.progress)
    return request, start


# Peak memory per node, measured (docs/benchmarks/bench_bvp.md, bench_ipopt.md): Newton 0.67 GB
# at 1e6 nodes of the pendulum (n = 1; 1.06 GB before the band store was reused), IPOPT on the
# assembly 3.9-4.3 GB at 1e6 (9.3 GB before its tolerance sat at the rows' round-off and the
# pinned times left its patterns); the blocks grow like (2n + 1)^2.
BYTES_PER_NODE = {"newton": 0.8e3, "auto": 0.8e3, "ipopt": 4.5e3}


def _check_memory(nodes: int, n: int, solver: str) -> None:
    """Refuse a grid whose estimated peak memory exceeds what this machine has available."""
    per_node = BYTES_PER_NODE.get(solver, BYTES_PER_NODE["ipopt"]) * ((2 * n + 1) / 3) ** 2
    needed = nodes * per_node
    available = _available_memory()
    if available is not None and needed > available:
        raise InputError(
            f"nodes = {nodes} needs about {needed / 1e9:.3g} GB with solver {solver!r} "
            f"(measured {per_node / 1e3:.3g} kB per node for n = {n}), more than the "
            f"{available / 1e9:.3g} GB this machine has available")


def _available_memory() -> float | None:
    """Bytes of memory available (``MemAvailable`` of /proc/meminfo), or None if unknown."""
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def _residuals(request: GridRequest, x: np.ndarray):
    """Canonical ``(N-1, 2n)`` and energy ``(N-2,)`` residuals of ``x``, unscaled (for ``fixed``
    steps the ``lee`` balance they do not enforce, as ``grid_residuals`` reports it), and the
    grid's ``F`` at ``x`` where it was evaluated (energy rules; else ``None``)."""
    if not request.scheme.variable_steps:
        t, q, p = NodeLayout(request.system.n, request.nodes).unpack(x)
        return (*equations.grid_residuals(request.system, request.scheme, t, q, p,
                                          request.theta), None)
    grid = assembly(request, request.scheme)
    data = ends(request, request.scheme)
    F, _ = grid.evaluate(x, data, jacobian=False)
    return (*grid.residuals(F, data), F)


def _outcome(request: GridRequest, x: np.ndarray, phase: Stage):
    """``(status, message, stats)`` of the point ``x`` that ``phase`` returned."""
    t = x.reshape(request.nodes, -1)[:, 0]
    finite = bool(np.all(np.isfinite(x)))
    canonical, energy, F = _residuals(request, x) if finite else (None, None, None)
    limits = verification_limits(request, x, F) if finite else (np.full(2 * request.system.n,
                                                                         np.nan), np.nan)
    stats = {"canonical": canonical, "energy": energy}
    status, message = _verify(phase, t, canonical, energy, request.scheme, limits, stats)
    return status, message, stats


def verification_limits(request: GridRequest, x: np.ndarray,
                        F: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """``(canonical (2n,), energy)``: the largest residual each row of the point ``x`` may have
    and pass. Each is ``tol`` relative to what the row measures, or ``BOUNDS_ALLOWED``
    times Newton's target on the row (`phases.row_round_offs`), whichever is larger:

    - a canonical row: ``tol`` times the motion's size in the row's units, the largest range
      of a position over the nodes for a position row, of a momentum for a momentum row
      (``Scheme``'s ``row_units``: the increment form has one block of each, the discrete
      Legendre transform two of momenta);
    - an energy row: ``tol`` times the mean step times the rate at which the motion trades
      energy, ``sum_i max |dq_i/dt| max |dp_i/dt|`` (energy per time, read off the nodes), so
      that ``tol`` bounds the node times relative to the motion's own time scale whatever ``N``
      (the row's derivative in a node time is ``O(tau)``).

    Every scale comes from the problem: under a change of units of length, momentum or time,
    or a shift of the coordinates' origin, the limits follow the rows (a floor of 1 and ``tol``
    as an absolute number had passed a pendulum in lengths of ``1e-8`` whose energy rows were
    not solved, ``1e-5`` of its energy off). ``F``: the grid's rows at ``x``, if evaluated."""
    n, N = request.system.n, request.nodes
    z = x.reshape(N, 2 * n + 1)
    rows = row_round_offs(request, x, request.scheme, base=F)
    q, p = z[:, 1:n + 1], z[:, n + 1:]
    size = canonical_sizes(request.system, request.scheme, q, p)
    canonical = np.maximum(request.tol * size, BOUNDS_ALLOWED * rows.canonical)
    energy = max(request.tol * mean_step(request) * energy_rate(z[:, 0], z[:, 1:]),
                 BOUNDS_ALLOWED * rows.energy)
    return canonical, energy


def _verify(phase, t, canonical, energy, scheme, limits, stats):
    """Status and message from the point's own residuals against ``limits`` (per canonical
    row, and the energy rows'); the solver's verdict is quoted, and decides only when the point
    fails (solver failure, time limit)."""
    if canonical is None:
        stats.update(canonical_limit=np.nan, energy_limit=np.nan)
        return Status.NON_FINITE, f"the solver returned non-finite values ({phase.quoted})"
    tau = np.diff(t)
    worst_canonical = float(np.max(np.abs(canonical)))
    worst_energy = float(np.max(np.abs(energy), initial=0.0))
    row_limits, energy_limit = limits
    # the limit beside the largest residual: of its row
    column = int(np.argmax(np.max(np.abs(canonical), axis=0)))
    stats.update(canonical_limit=float(row_limits[column]), energy_limit=float(energy_limit),
                 canonical_residual_max=worst_canonical, energy_residual_max=worst_energy,
                 tau_min=float(np.min(tau)))
    problems = []
    if np.min(tau) <= 0:
        k = int(np.argmin(tau))
        problems.append(f"step {k} is not positive: tau = {tau[k]:.6g} (t = {t[k]:.10g})")
    over = np.abs(canonical) / row_limits
    if np.max(over) > 1:
        k, i = np.unravel_index(int(np.argmax(over)), over.shape)
        problems.append(f"canonical residual {abs(canonical[k, i]):.3e} on interval {k} "
                        f"(t = {t[k]:.6g}), tolerance {row_limits[i]:.3e}")
    if scheme.variable_steps and worst_energy > energy_limit:
        k = int(np.argmax(np.abs(energy))) + 1
        problems.append(f"energy residual {worst_energy:.3e} at node {k} (t = {t[k]:.6g}), "
                        f"tolerance {energy_limit:.3e}")
    said = phase.quoted
    if not problems:
        return Status.SUCCESS, (f"solved and verified: largest residuals canonical "
                                f"{worst_canonical:.3e}, energy {worst_energy:.3e}; "
                                f"{phase.iterations} iterations ({said})")
    status = failure_status(phase, tau)
    if status is Status.NO_ADMISSIBLE_STEP:
        return status, problems[0] + f" ({said})"
    if status is Status.NOT_VERIFIED:
        return status, f"{status.value}: {'; '.join(problems)} ({said})"
    return status, f"{status.value} ({said})" + "".join(f"; {p}" for p in problems)


def _solution(request: GridRequest, x, phase, outcome, started) -> Solution:
    status, message, checks = outcome
    layout = NodeLayout(request.system.n, request.nodes)
    t, q, p = layout.unpack(x)
    finite = bool(np.all(np.isfinite(x)))
    canonical, energy = checks.pop("canonical"), checks.pop("energy")
    if canonical is None:
        canonical = np.full((request.nodes - 1, 2 * request.system.n), np.nan)
        energy = np.full(request.nodes - 2 if request.scheme.variable_steps else 0, np.nan)
    phases = request.phases
    sign_changes = [int(np.count_nonzero(np.diff(np.sign(p[:, i])) != 0))
                    for i in range(request.system.n)]
    if status is Status.SUCCESS:
        if len(sign_changes) == 1:
            message += f"; p changes sign {sign_changes[0]} times"
        else:
            message += "; sign changes of " + ", ".join(
                f"p{i + 1}: {count}" for i, count in enumerate(sign_changes))
    stats = {"solver": phase.solver, "return_status": phase.said,
             "iterations": phase.iterations,
             "iterations_total": sum(stage.iterations for stage in phases),
             "energy_scale": mean_step(request), "tau_floor": request.tau_floor}
    found = EndsRecord(stages=tuple(replace(stage) for stage in phases),
                       action=assembly(request, request.scheme).action(x, request.theta)
                       if finite else math.nan, p_sign_changes=tuple(sign_changes), **checks)
    report, local_error = None, np.zeros(0)
    judged, judged_cpu = time.perf_counter(), time.process_time()
    if finite:
        report, local_error = _accuracy(request, t, q, p)
    judged_cpu = time.process_time() - judged_cpu
    total = time.perf_counter() - started
    solution = Solution(
        t=t, q=q, p=p, status=status, message=message, scheme=request.scheme.rule,
        energy_residual=energy, canonical_residual=row_max_abs(canonical),
        newton_iterations=stats["iterations_total"],
        timing={"build_s": request.build_s, "solve_s": total - request.build_s,
                "accuracy_s": total - (judged - started), "accuracy_cpu_s": judged_cpu},
        stats=stats, ends=found)
    judge(solution, report, request.options.accuracy, local_error=local_error,
          advice="try more nodes")
    return solution


def _accuracy(request: GridRequest, t, q, p):
    """The accuracy check (``accuracy/judgement.py``) on the grid, against the exact flow:
    each interval, the energy level of the first interval (energy rules), the nodal drift; and
    the trajectory against the continuous problem's solution, found by multiple shooting from
    the grid's own start (``exact/shooting.py``, segments chosen by the flow's error control,
    read at the nodes: a 10^6-node grid costs what a 10^3-node grid of the same motion does).
    With no continuous solution near, the problem is refused with that reason (a verified
    discrete solution can exist where no motion does: its end error, small beside a huge
    motion, says nothing then)."""
    system, scheme = request.system, request.scheme
    level = None
    if scheme.variable_steps:
        value = float(equations.interval_energies(system, scheme, t[:2], q[:2], p[:2],
                                                  request.theta)[0])
        level = Level(value, float(t[0] + (t[1] - t[0]) / 2 if scheme.clock == "midpoint"
                                   else t[0]))
    return judged_against_shooting(request, t, q, p, level=level)


