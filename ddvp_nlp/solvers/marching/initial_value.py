"""Initial-value problems: march node by node with a CasADi rootfinder (docs/theory.md section 5).

Step 0 is a plain implicit step of length ``tau0``: the ``2n`` canonical equations of interval 0
are solved for ``z_1``. Every later step ``k`` solves ``2n + 1`` equations, the canonical equations
of interval ``k`` and the energy equation at node ``k``, for ``(z_{k+1}, tau_k)``. ``tau0`` thus
fixes the discrete energy level and every later step. With ``rule="fixed"`` every step solves the
canonical equations only, on uniform steps that end on ``t_end``.

A step is accepted only if Newton converged, every value is finite, ``tau_k > 0`` (the
time-reversed root ``(z_{k-1}, -tau_{k-1})`` solves the midpoint step equations for every state),
the step's own unscaled residuals are below ``StepControl.tol`` (relative to ``max(1, |z|)``
and ``max(1, |H|)``) and the optional step bounds hold (``acceptance.py``). The first step that
fails ends the march with a status; every accepted node is kept.

The parts: ``steps.py`` (the step functions), ``newton.py`` (Newton on one step, with retries, and
its compiled unrolled form), ``least_squares.py`` (the
step that replaces a failed one with ``breakdown="least_squares"``), ``chunk.py`` (compiled
chunks of steps), ``stepper.py`` (the careful, compiled and composite steppers), ``monitors.py``
(energy guard, solvability monitor). This module checks the input, builds those parts, runs them
with the driver (``driver.py``) and returns the `Solution`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ...cache import cached
from ...discrete import equations
from ...discrete.scheme import Scheme
from ...errors import InputError
from ...physics.hamiltonian import HamiltonianSystem
from ...solution import MarchRecord, Solution, Status
from ...validation import check_span, check_state, check_step, check_times
from ..accuracy.judgement import CheckStopped, Judgement, Level, judge
from ..accuracy.streaming import StreamingJudgement
from ..columns import row_max_abs
from ..compiler import buffered, find_compiler
from ..dense import DenseField, EventMonitor, attach, evaluate_at
from ..driver import Nodes, drive
from ..options import (
    DEFAULT_TOLERANCE,
    Compilation,
    Output,
    StepControl,
    Tolerance,
    answers_removed_keywords,
    coerce,
)
from .acceptance import Acceptance
from .backward import is_backward, march_backward
from .chunk import FastChunk
from .monitors import Checkpoint, EarlyVerdict, EnergyGuard, SolvabilityMonitor, StopRequest
from .recheck import grid_residuals
from .resume import CarryTracker, MarchState, check_resume, with_state
from .step_newton import NewtonSteps
from .stepper import CarefulStepper, Clock, CompiledStepper, MarchStepper, Tally
from .steps import StepFunctions, step_functions
from .target import check_target, march_to_error
from .thinning import Thinning

# An interrupted march of more nodes than this is returned without its final accuracy check.
INTERRUPTED_JUDGED = 1_000_000


def coerced(scheme, steps, accuracy, compilation, output):
    """The options of a march as their objects (``InputError`` naming a wrong one), before
    anything is built."""
    if accuracy is not None:
        coerce(accuracy, Tolerance, "accuracy")
    return (Scheme.coerce(scheme), coerce(steps, StepControl, "steps"),
            coerce(compilation, Compilation, "compilation"), coerce(output, Output, "output"))


@answers_removed_keywords
def march(system: HamiltonianSystem, q0, p0=None, t_span=None, *, tau0: float, v0=None,
          scheme: str | Scheme = "vddvp", params: Mapping[str, float] | None = None,
          steps: StepControl | None = None, accuracy: Tolerance | None = DEFAULT_TOLERANCE,
          compilation: Compilation | None = None, output: Output | None = None,
          target_error: float | None = None) -> Solution:
    """March ``z_0 = (q0, p0)`` from ``t0`` until the first node at or past ``t_end``.

    Args:
        system: the Hamiltonian or Lagrangian system.
        q0: initial position, shape ``(n,)``.
        p0: initial momentum, shape ``(n,)`` (or give ``v0``).
        t_span: ``(t0, t_end)``; energy rules stop at the first node with ``t >= t_end``.
            With ``t_end < t0`` the march runs backwards in time, as scipy's ``solve_ivp``
            does: the forward march of ``H(q, -p, -t)`` mapped back (``backward.py``), its
            times decreasing, ``t_eval`` sorted in decreasing order.
        tau0: first step; for energy rules it sets the discrete energy level, for ``fixed`` the
            step is ``(t_end - t0) / ceil((t_end - t0) / tau0)``, so the march ends on ``t_end``.
        v0: instead of ``p0``, for a Lagrangian system: the first interval's velocity; the
            march takes ``q_1 = q_0 + tau0 v0`` and ``p_0`` by the discrete Legendre transform.
        scheme: ``"vddvp"``, ``"lee"``, ``"fixed"`` or a `Scheme`.
        params: values of the system's parameters (defaults filled in).
        steps: when a step is accepted and when the march stops (`StepControl`: the
            residual tolerance, step bounds, what to do at a breakdown, ``max_steps``,
            ``time_limit``, ``energy_guard``).
        accuracy: the accuracy check (``solvers/accuracy/judgement.py``), which does not trust the
            scheme's own equations and measures the run against the exact flow
            (``solvers/exact/``, adaptive order-8 Runge-Kutta): each step's local error against
            the flow over that step (a step that one compiled RK4 step of the flow already
            clears is screened with it), the energy level of the first step and the nodal
            energy, and the trajectory error against a reference from the first node that
            states its own error. The verdict is ``accurate``, ``drifted`` or ``inaccurate``;
            the first steps are judged as they come (the early verdict), so a march that
            plainly does not follow the motion ends there with status ``inaccurate`` (unless
            ``Tolerance.stop`` is off); ``Solution.verdict`` and ``Solution.local_error`` hold
            the figures. ``None`` leaves the check out (the comparison does, so that run times
            compare like with like, and judges afterwards against the same exact flow).
        compilation: compiled chunks of steps or the careful path, the compiler and its cache
            (`Compilation`).
        output: progress bar, checkpoints, the stop request, the times to report
            (``t_eval``) and the events (`Output`; ``solvers/dense.py``).
        target_error: the trajectory error asked for, relative to the motion's size: the
            march chooses its own first step from a pilot march at ``tau0`` over the start of
            the span, so that the run is ``accurate`` at ``global_tol = target_error``, with
            one second try where it is not (``target.py``); ``march.target_error`` holds
            the choice and what it cost.

    A step is accepted only if Newton converged, every value is finite, ``tau_k > 0``, its own
    unscaled residuals are below ``steps.tol`` and the step bounds hold (``acceptance.py``).
    The first step that fails ends the march with a status; every accepted node is kept.

    The solvability monitor (energy rules): at every node the site-density weight
    ``w = f' H_zz f = -8 c(z)`` (docs/theory.md section 7). A positive step needs ``c`` to keep its
    sign and the step to be short against the change of ``w``; the march warns (a
    ``RuntimeWarning`` and ``march.solvability_warning``) at the first node where ``w``
    changes sign or ``|ln(w_k / w_{k-1})|`` exceeds ``MONITOR_LIMIT`` (``monitors.py``).
    ``Solution.solvability`` holds ``c(z_k)`` at every node.

    Returns:
        A `Solution`; failures are a status on it, never an exception.
    """
    if is_backward(t_span):  # t_end < t0: the forward march of H(q, -p, -t) (backward.py)
        return march_backward(march, system, q0, p0, t_span, tau0=tau0, v0=v0, scheme=scheme,
                              params=params, steps=steps, accuracy=accuracy,
                              compilation=compilation, output=output,
                              target_error=target_error)
    scheme, steps, compilation, output = coerced(scheme, steps, accuracy, compilation, output)
    target = None
    if target_error is not None:
        target = check_target(target_error, accuracy)
        if v0 is not None:
            raise InputError("target_error needs p0: with v0 the start itself depends on tau0")
    # the options first: the start (p0 from v0, H0) already builds CasADi functions
    problem = check_problem(system, scheme, q0, p0, v0, t_span, tau0, steps, params)
    check_times(output.t_eval, (problem.t0, problem.t_end))
    if target is not None:
        def run(tau, span, tolerance):
            return march(system, problem.q0, problem.p0, span, tau0=tau, scheme=scheme,
                         params=params, steps=steps, accuracy=tolerance,
                         compilation=compilation,
                         output=output if tolerance is not None else None)
        return march_to_error(run, system, np.concatenate([problem.q0, problem.p0]),
                              problem.t0, problem.t_end, problem.tau0, problem.theta, target,
                              accuracy)
    return run_march(problem, accuracy, compilation, output)


@answers_removed_keywords
def continue_march(system: HamiltonianSystem, state: MarchState, t_end: float | None = None, *,
                   tau0: float, scheme: str | Scheme = "vddvp",
                   params: Mapping[str, float] | None = None, steps: StepControl | None = None,
                   accuracy: Tolerance | None = DEFAULT_TOLERANCE,
                   compilation: Compilation | None = None,
                   output: Output | None = None) -> Solution:
    """Continue the march whose nodes and carried state are ``state`` (a killed run's last
    checkpoint, or a finished run) to ``t_end`` (default: the one it was asked for; the same or
    later), with the options it ran with (``tau0``, ``scheme``, ``params``, ``steps``,
    ``accuracy``, ``compilation``, as for `march`).

    The loop goes on as if it had never stopped (``resume.py``): the returned nodes are the
    earlier ones followed by those an uninterrupted `march` to ``t_end`` gives, bit for
    bit, on the compiled and the careful path. A fixed-step march keeps its ``t_end``.

    Returns:
        A `Solution` of the whole run, from the first node.
    """
    scheme, steps, compilation, output = coerced(scheme, steps, accuracy, compilation, output)
    if not isinstance(state, MarchState):
        raise InputError(f"state must be a MarchState, got {type(state).__name__}")
    if output.thinned:
        raise InputError(f"continue_march keeps every node (it goes on from consecutive "
                         f"nodes): give output without keep_every = {output.keep_every!r} or "
                         f"keep = {output.keep!r}")
    n = state.z.shape[1] // 2
    t_end = state.t_end if t_end is None else t_end
    problem = check_problem(system, scheme, state.z[0, :n], state.z[0, n:], None,
                            (state.t[0], t_end), tau0, steps, params)
    check_resume(state, problem, scheme.variable_steps)
    check_times(output.t_eval, (problem.t0, problem.t_end))
    return run_march(problem, accuracy, compilation, output, start=state)


def run_march(problem: MarchProblem, accuracy, compilation: Compilation, output: Output,
              start=None) -> Solution:
    """Build the march of a checked ``problem`` and drive it from its start, or from ``start``
    (a `MarchState`: the nodes of an earlier run of the
    same problem and what its loop carried, ``resume.py``)."""
    compiler = find_compiler(compilation.compiler) if compilation.fast else compilation.compiler
    started = time.perf_counter()
    parts = _build(problem, compilation, compiler)
    built = time.perf_counter()
    nodes = Nodes(problem.t0, np.concatenate([problem.q0, problem.p0]))
    # the check and the recheck are compiled where the march's own chunk is (one fallback
    # warning, not three), or (careful path) with the compiler asked for
    compiled = parts.fast_chunk is not None and parts.fast_chunk.path == "compiled"
    judging = compiler if compiled else \
        None if compilation.fast else find_compiler(compilation.compiler)
    thinning = _thinning(problem, accuracy, output, compiler=compiler if compiled else None,
                         judging=judging, cache_dir=compilation.cache_dir) \
        if output.thinned else None
    monitors, solvability = _monitors(parts, problem, nodes, thinning)
    if accuracy is not None and accuracy.stop:
        monitors.append(EarlyVerdict(Judgement(problem.system, problem.theta, accuracy,
                                               compiler=judging,
                                               cache_dir=compilation.cache_dir),
                                     screen=True))
    events = None
    if output.events:
        events = EventMonitor(output.events, DenseField.of(problem.system, problem.theta),
                              problem.t_end, nodes.t[0], nodes.z[0])
        monitors.append(events)
    if start is not None:  # the earlier nodes, watched again; the loop's state restored
        nodes = start.restore(parts.stepper, parts.tally, monitors, parts.functions,
                              problem.theta)
    carry = CarryTracker(parts.tally, *((start.careful_left, start.phase) if start else ()))
    saver = None
    if output.checkpoint is not None:
        save, state = with_state(output.checkpoint, carry)
        saver = Checkpoint(save, output.checkpoint_interval, state=state)
    monitors += [StopRequest(output.stop)] if output.stop else []
    monitors += [carry]
    monitors += [saver] if saver else []  # last: it sees only the nodes the others kept
    try:
        outcome = drive(parts.stepper, nodes, t_end=problem.t_end,
                        max_steps=problem.steps.max_steps, time_limit=problem.steps.time_limit,
                        monitors=monitors, progress=output.progress, catch_interrupt=True,
                        stop=output.stop, thinning=thinning)
    finally:
        if saver:  # a checkpoint in flight lands before the final write can start
            saver.finish()
    solved = time.perf_counter()
    if isinstance(parts.stepper, MarchStepper):  # fast_steps: the fast nodes the run kept
        parts.stepper.compiled.settle(outcome.marched)
    timing = {"build_s": built - started, "solve_s": solved - built}
    if thinning is not None:
        return _thinned(problem, outcome, parts, solvability, thinning, accuracy, output,
                        carry, timing, events)
    solution = _solution(problem, outcome, parts, solvability,
                         compiler=compiler if compiled else None,
                         cache_dir=compilation.cache_dir, timing=timing,
                         recheck=not _stopping(outcome, output))
    solution.march.carried = carry.state()
    if accuracy is not None and _left_unjudged(solution, outcome, output):
        accuracy = None
    if accuracy is not None:
        started = time.perf_counter()
        try:
            report, local = _judged(
                problem, solution, accuracy, compiler=judging, cache_dir=compilation.cache_dir,
                stop=output.stop if _too_many_to_judge(outcome.t.size) else None)
        except CheckStopped:
            _left_unjudged(solution, outcome, output, asked=True)
            return _finished(solution, problem, events, output)
        judge(solution, report, accuracy, local_error=local)
        solution.timing["accuracy_s"] = time.perf_counter() - started
    if saver:
        solution.timing["checkpoint_s"] = saver.seconds
        solution.march.checkpoints = saver.saves
        solution.march.checkpoints_landed_s = [round(t, 3) for t in saver.landed]
    return _finished(solution, problem, events, output)


def _finished(solution: Solution, problem: MarchProblem, events, output: Output) -> Solution:
    """The dense field, the events and the ``t_eval`` states put on ``solution``."""
    attach(solution, problem.system, problem.theta, problem.t_end)
    if events is not None:
        events.report(solution)
    evaluate_at(solution, output.t_eval)
    return solution


@dataclass(frozen=True)
class MarchProblem:
    """The checked inputs of one march: the system and scheme, the start (``p0`` from ``v0``
    if that was given), the times, the parameter vector, ``H(z_0, t_0)``, the step control and
    the acceptance test it makes."""

    system: HamiltonianSystem
    scheme: Scheme
    q0: np.ndarray
    p0: np.ndarray
    t0: float
    t_end: float
    tau0: float
    theta: np.ndarray
    H0: float
    steps: StepControl
    acceptance: Acceptance


def check_problem(system, scheme: Scheme, q0, p0, v0, t_span, tau0, steps: StepControl,
                  params) -> MarchProblem:
    """Every input of `march` but the options objects, checked in the order of its
    signature (``InputError`` naming the argument and the value), before anything is built;
    ``march_ensemble`` checks each of its starts with it."""
    if not isinstance(system, HamiltonianSystem):
        raise InputError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
    q0, p0, v0 = _check_state(system, q0, p0, v0)
    t0, t_end, tau0 = _check_times(t_span, tau0)
    if (steps.tau_min is not None and tau0 < steps.tau_min) or \
            (steps.tau_max is not None and tau0 > steps.tau_max):
        raise InputError(f"tau0 must lie in [tau_min, tau_max] = [{steps.tau_min}, "
                         f"{steps.tau_max}], got {tau0!r}")
    if steps.breakdown == "least_squares" and not scheme.variable_steps:
        raise InputError("breakdown='least_squares' needs an energy rule (vddvp or lee), got "
                         f"scheme {scheme.rule!r}")
    theta = system.parameter_vector(params)
    p0, H0 = _start(system, scheme, q0, p0, v0, t0=t0, tau0=tau0, theta=theta)
    return MarchProblem(system, scheme, q0, p0, t0, t_end, tau0, theta, H0, steps,
                        Acceptance(steps.tol, steps.tau_min, steps.tau_max,
                                   steps.max_step_ratio))


def _check_state(system, q0, p0, v0):
    """``q0`` and exactly one of ``p0`` and ``v0``."""
    q0 = check_state("q0", q0, system.n)
    if (p0 is None) == (v0 is None):
        raise InputError("give exactly one of p0 and v0")
    if v0 is not None and not system.lagrangian_form:
        raise InputError(f"v0 needs a Lagrangian system; {system.name!r} is Hamiltonian: "
                         "give p0")
    p0 = check_state("p0", p0, system.n) if p0 is not None else None
    v0 = check_state("v0", v0, system.n) if v0 is not None else None
    return q0, p0, v0


def _check_times(t_span, tau0):
    """``t0 < t_end`` and a first step ``0 < tau0 <= t_end - t0``."""
    t0, t_end = check_span(t_span)
    tau0 = check_step(tau0, t0, t_end)
    if tau0 > t_end - t0:
        raise InputError(f"tau0 must not exceed |t_end - t0| = {t_end - t0!r}, got {tau0!r}")
    return t0, t_end, tau0


def _start(system, scheme, q0, p0, v0, *, t0, tau0, theta) -> tuple[np.ndarray, float]:
    """``p_0`` (from ``v0`` by the discrete Legendre transform if given) and ``H(z_0, t_0)``."""
    if v0 is not None:
        from ...discrete.lagrangian_action import start_momentum

        p0 = start_momentum(system, scheme, q0, v0, t0=t0, tau0=tau0, theta=theta)
        if not np.all(np.isfinite(p0)):
            raise InputError(f"p0 from v0 = {v0.tolist()} is not finite: {p0.tolist()}")
    H0 = float(system.energy(q0[None, :], p0[None, :], np.array([t0]), theta)[0])
    if not math.isfinite(H0):
        raise InputError(f"H is not finite at the initial state q0={q0.tolist()}, "
                         f"p0={p0.tolist()}, t0={t0!r}: H = {H0!r}")
    return p0, H0


@dataclass
class _Parts:
    """What `_build` made: the stepper and what the ``Solution`` reads back from it."""

    functions: StepFunctions
    newton: NewtonSteps
    tally: Tally
    fast_chunk: FastChunk | None
    stepper: CarefulStepper | MarchStepper


def _build(problem: MarchProblem, compilation: Compilation, compiler) -> _Parts:
    """The step functions (cached on the system), the compiled chunk if ``compilation.fast``
    (cached too, once per system, scheme and compiler: the same chunk with the accuracy check
    on or off) and the stepper."""
    system, scheme, steps = problem.system, problem.scheme, problem.steps
    cache_dir = compilation.cache_dir
    functions = step_functions(system, scheme)
    newton = NewtonSteps(system, scheme, functions, problem.theta, problem.acceptance)
    tally = Tally()
    clock = Clock.for_rule(scheme.variable_steps, problem.t0, problem.t_end, problem.tau0)
    stepper = CarefulStepper(newton, clock, tally, variable=scheme.variable_steps,
                             breakdown=steps.breakdown)
    fast_chunk = None
    if compilation.fast:
        fast_chunk = cached(system, ("fast", scheme, compilation.chunk, compiler, str(cache_dir)),
                            lambda: FastChunk(system, scheme, functions, chunk=compilation.chunk,
                                              compiler=compiler, cache_dir=cache_dir))
        stepper = MarchStepper(stepper, CompiledStepper(fast_chunk, problem.theta,
                                                        problem.acceptance, clock, tally,
                                                        max_calls=compilation.batch))
    return _Parts(functions, newton, tally, fast_chunk, stepper)


def _too_many_to_judge(nodes: int) -> bool:
    """Whether a stopped march of ``nodes`` nodes is returned unjudged."""
    return nodes > INTERRUPTED_JUDGED


def _stopping(outcome, output: Output) -> bool:
    """Whether a march of more than ``INTERRUPTED_JUDGED`` nodes was stopped, or is asked to
    stop now that it has ended (a Ctrl-C during its last chunks): it is returned without
    the work over every node (the recheck, the check), so that a user who stopped it waits
    for nothing but the writing of its nodes (7.8 million nodes: 1.6 s of recheck and 6.3 s
    of check had come between the Ctrl-C and the writing)."""
    if not _too_many_to_judge(outcome.t.size):
        return False
    return outcome.status is Status.INTERRUPTED or (output.stop is not None and output.stop())


def _left_unjudged(solution: Solution, outcome, output: Output, asked: bool = False) -> bool:
    """`_stopping` (or ``asked``: a stop came during the check), said in
    ``Solution.accuracy_skipped``; the early verdict judged the run's first steps."""
    if not (asked or _stopping(outcome, output)):
        return False
    solution.accuracy_skipped = (
        f"the run was stopped after {outcome.t.size - 1} steps: the accuracy check (of stopped "
        f"runs over {INTERRUPTED_JUDGED} nodes) was left out; judge its nodes with "
        f"accuracy.assess, or keep fewer (Output(keep_every=k) judges every node as it goes)")
    return True


def _thinning(problem: MarchProblem, accuracy, output: Output, *, compiler, judging,
              cache_dir) -> Thinning:
    """What a thinned march keeps (``thinning.py``), with its streamed accuracy check."""
    system, scheme, theta, n = problem.system, problem.scheme, problem.theta, problem.system.n
    judge = None
    if accuracy is not None:
        judge = StreamingJudgement(
            Judgement(system, theta, accuracy, compiler=judging, cache_dir=cache_dir),
            screen=True, exact=accuracy.exact, level=lambda t, z: _level(problem, t, z))

    def residuals(t, z):
        return grid_residuals(system, scheme, t, z[:, :n], z[:, n:], theta, compiler=compiler,
                              cache_dir=cache_dir)
    return Thinning(output.keep_every, output.keep, residuals=residuals, judge=judge,
                    t_eval=output.t_eval, field=DenseField.of(system, theta),
                    window=output.window)


def _thinned(problem: MarchProblem, outcome, parts: _Parts, solvability, thinning: Thinning,
             accuracy, output: Output, carry, timing, events) -> Solution:
    """The `Solution` of a thinned march: the kept nodes and what `Thinning` kept of the
    rest; the verdict of the streamed check."""
    started = time.perf_counter()
    t, z = outcome.t, outcome.z
    n = problem.system.n
    kept = thinning.arrays(z.shape[1])
    tally, fast_chunk = parts.tally, parts.fast_chunk
    solution = Solution(
        t=t, q=z[:, :n].copy(), p=z[:, n:].copy(), status=outcome.status,
        message=outcome.message, scheme=problem.scheme.rule, energy_residual=kept["energy"],
        canonical_residual=kept["canonical"], newton_iterations=parts.newton.newton_iterations,
        timing={**timing, "compile_s": fast_chunk.compile_s if fast_chunk else 0.0},
        solvability=solvability.solvability(outcome.marched) if solvability else np.zeros(0),
        stats={"retries": parts.newton.retries,
               "path": fast_chunk.path if fast_chunk else "careful",
               "fast_steps": tally.fast_steps, "careful_steps": tally.careful_steps,
               "fallbacks": tally.fallbacks, "first_fallback": tally.first_fallback},
        march=MarchRecord(theta=problem.theta.tolist(),
                          solvability_warning=solvability.warning if solvability else None,
                          least_squares=tally.least_squares,
                          kept=thinning.record(outcome.marched, int(t.size))))
    solution.march.carried = carry.state()
    if accuracy is not None:
        judge(solution, thinning.judge.report(float(t[-1])), accuracy, local_error=kept["local"])
    solution.timing["finish_s"] = time.perf_counter() - started
    attach(solution, problem.system, problem.theta, problem.t_end)
    if events is not None:
        events.report(solution)
    if output.t_eval is not None:
        solution.t_eval, solution.z_eval = kept["t_eval"], kept["z_eval"]
    return solution


def _monitors(parts: _Parts, problem: MarchProblem, nodes, thinning=None):
    """The energy guard (if asked for) and, for energy rules, the solvability monitor, which
    starts from the weight at node 0. Returns the monitors and the solvability monitor."""
    monitors, solvability = [], None
    if problem.steps.energy_guard is not None:
        monitors.append(EnergyGuard(problem.steps.energy_guard, problem.H0))
    if problem.scheme.variable_steps:
        monitor = buffered(parts.functions.node_monitor, "node_monitor",
                           owner=parts.functions)
        _, w_first = monitor(nodes.z[0], nodes.t[0], problem.theta)
        solvability = SolvabilityMonitor(float(nodes.t[0]), float(w_first[0, 0]), thinning)
        monitors.append(solvability)
    return monitors, solvability


def _judged(problem: MarchProblem, solution, tolerance, *, compiler, cache_dir, stop=None):
    """The accuracy check of the march's nodes (``accuracy/judgement.py``), the exact flow
    compiled with ``compiler``; for the energy rules the level the first step sets, the first
    interval's energy at its clock, is tested too. The RK4 screen of the local test suits a
    second-order scheme."""
    t, z = solution.t, np.hstack([solution.q, solution.p])
    judge = Judgement(problem.system, problem.theta, tolerance, compiler=compiler,
                      cache_dir=cache_dir)
    return judge.report(t, z, level=_level(problem, t, z), screen=True, exact=tolerance.exact,
                        stop=stop)


def _level(problem: MarchProblem, t, z) -> Level | None:
    """The energy level the first step of an energy rule sets: the first interval's energy
    at its clock (``None`` for fixed steps, or before a step)."""
    system, scheme, theta = problem.system, problem.scheme, problem.theta
    if not scheme.variable_steps or t.size < 2:
        return None
    interval_energy = buffered(equations.midpoint_energy_function(system, scheme),
                               "interval_energy", scheme, owner=system)
    n = system.n
    value = float(interval_energy(t[0], t[1], z[0, :n], z[0, n:], z[1, :n], z[1, n:],
                                  theta)[0][0, 0])
    return Level(value, float(t[0] + (t[1] - t[0]) / 2 if scheme.clock == "midpoint"
                              else t[0]))


def _solution(problem: MarchProblem, outcome, parts: _Parts, solvability, *, compiler,
              cache_dir, timing, recheck: bool = True):
    """The `Solution`, with every equation recomputed on the returned grid (compiled
    with ``compiler``, else on CasADi's virtual machine; not with ``recheck`` off, a stopped
    long march: its residual arrays are then empty)."""
    started = time.perf_counter()
    system, scheme, theta = problem.system, problem.scheme, problem.theta
    t, z = outcome.t, outcome.z
    n = system.n
    canonical, energy = grid_residuals(system, scheme, t, z[:, :n], z[:, n:], theta,
                                       compiler=compiler, cache_dir=cache_dir) if recheck \
        else (np.zeros((0, 2 * n)), np.zeros(0))
    verified = time.perf_counter()
    fast_chunk, tally = parts.fast_chunk, parts.tally
    return Solution(
        t=t, q=z[:, :n].copy(), p=z[:, n:].copy(), status=outcome.status,
        message=outcome.message, scheme=scheme.rule, energy_residual=energy,
        canonical_residual=row_max_abs(canonical) if canonical.size else np.zeros(0),
        newton_iterations=parts.newton.newton_iterations,
        timing={**timing, "compile_s": fast_chunk.compile_s if fast_chunk else 0.0,
                "verify_s": verified - started},
        solvability=solvability.solvability(t.size) if solvability else np.zeros(0),
        stats={"retries": parts.newton.retries,
               "path": fast_chunk.path if fast_chunk else "careful",
               "fast_steps": tally.fast_steps, "careful_steps": tally.careful_steps,
               "fallbacks": tally.fallbacks, "first_fallback": tally.first_fallback},
        march=MarchRecord(theta=theta.tolist(),
                          solvability_warning=solvability.warning if solvability else None,
                          least_squares=tally.least_squares))
