"""A march session: one march of a checked `MarchProblem` (``march_problem.py``), from its
parts to its `Solution`.

    solution = MarchSession(problem, accuracy, compilation, output).run()

`MarchSession.run` reads as the march does:

1. build the parts: the step functions, the compiled chunk, the stepper (`build_parts`), and
   for ``Output(keep_every=k)`` or ``keep="t_eval"`` the `Thinning` the driver hands its
   windows to (driver rule 7, ``thinning.py``);
2. make the monitors the options ask for (`make_monitors`, from `MONITORS`);
3. drive them (``driver.py``; a continued march first watches its earlier nodes again,
   ``resume.py``);
4. finish: every equation rechecked on the returned grid (``recheck.py``; a thinned march did
   it as it went), the verdict of the accuracy check, what each monitor adds, the dense output
   and the ``t_eval`` states.

The monitors. Everything a march watches node by node is a `MarchMonitor` (``monitors.py``)
listed in `MONITORS`, in the order they watch (a monitor that ends the run cuts the nodes the
ones after it see): the energy guard (``StepControl.energy_guard``), the solvability monitor
(energy rules), the early verdict (``Tolerance.stop``), the events (``Output.events``), the
stop request (``Output.stop``), the carried state (``resume.py``), the derivatives
(``derivatives.py``) and the checkpoints
(``Output.checkpoint``, last: it saves what the others kept). Each kind knows how it is made
and what it adds to the solution:

- ``Kind.from_options(session)`` makes it from the session's ``problem``, ``accuracy`` (a
  `Tolerance` or ``None``), ``output``, ``compilation``, ``parts``, ``judging`` (the compiler
  of the checks), ``thinning``, ``carry`` and ``derivatives``, or returns ``None`` when the
  options do not ask for it;
- ``watch(nodes, first, advance)`` sees every accepted node once (driver rule 5);
- ``rewatch``: whether it also watches a continued march's earlier nodes (to rebuild its state);
- ``close()`` runs when the loop has ended (or raised); ``finish(solution, outcome)`` puts what
  it found on the `Solution`, after the recheck and the verdict.

A new feature is one monitor, and this module is not edited for it. The forward derivatives
(issue 47, ``march(..., derivatives=...)``) are one: `Sensitivity` (``derivative_check.py``) is made
when the session's ``derivatives`` name inputs, watches nothing as the loop runs, and in its
``finish`` carries ``S_{k+1} = A_k S_k + B_k`` over the kept nodes (the step Jacobians that
``StepProblem``, ``step_newton.py``, is built from) into ``Solution.derivatives``. A monitor
not listed here is marched with ``MarchSession(problem, ..., kinds=(*MONITORS, Kind)).run()``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ...cache import cached
from ...solution import MarchRecord, Solution, Status
from ..accuracy.judgement import CheckStopped, Judgement, judge
from ..accuracy.streaming import StreamingJudgement
from ..columns import row_max_abs
from ..compiler import find_compiler
from ..dense import DenseField, attach, evaluate_at
from ..driver import Nodes, drive
from ..options import Compilation, Output, Tolerance
from .chunk import FastChunk
from .derivative_check import Sensitivity
from .march_problem import MarchProblem
from .monitors import (
    Checkpoint,
    EarlyVerdict,
    EnergyGuard,
    Events,
    MarchMonitor,
    SolvabilityMonitor,
    StopRequest,
)
from .recheck import recheck_residuals
from .resume import CarryTracker, MarchState
from .step_newton import NewtonSteps
from .stepper import CarefulStepper, Clock, CompiledStepper, MarchStepper, Tally
from .steps import StepFunctions, step_functions
from .thinning import Thinning

__all__ = ["MONITORS", "MarchMonitor", "MarchSession", "make_monitors"]

# The monitor kinds of every march, in the order they watch (module docstring).
MONITORS: tuple[type[MarchMonitor], ...] = (
    EnergyGuard, SolvabilityMonitor, EarlyVerdict, Events, StopRequest, CarryTracker,
    Sensitivity, Checkpoint)

# An interrupted march of more nodes than this is returned without its final accuracy check.
INTERRUPTED_JUDGED = 1_000_000


def make_monitors(kinds, session: MarchSession) -> list[MarchMonitor]:
    """The monitors ``session``'s options ask for, one per kind of ``kinds`` at most, in
    their order."""
    made = (kind.from_options(session) for kind in kinds)
    return [monitor for monitor in made if monitor is not None]


class MarchSession:
    """One march of ``problem`` (a `MarchProblem`) with the accuracy check ``accuracy`` (a
    `Tolerance`, or ``None``: none), ``compilation`` and ``output``, from its start or from
    ``start`` (a `MarchState`: the nodes of an earlier run of the same problem and what its
    loop carried, ``resume.py``); ``kinds``: the monitor kinds (module docstring);
    ``derivatives``: the inputs `Sensitivity` differentiates in (``derivatives.py``)."""

    def __init__(self, problem: MarchProblem, accuracy: Tolerance | None,
                 compilation: Compilation, output: Output, *, start: MarchState | None = None,
                 kinds=MONITORS, derivatives: tuple[str, ...] = ()):
        self.problem, self.accuracy = problem, accuracy
        self.derivatives = tuple(derivatives)
        self.compilation, self.output = compilation, output
        self.start, self.kinds = start, tuple(kinds)
        self.carry = CarryTracker.of(start)  # what the loop carries; a checkpoint saves it
        self.parts: Parts | None = None
        self.judging = self.rechecking = None  # the compilers of the check and the recheck
        self.thinning: Thinning | None = None

    def run(self) -> Solution:
        """Build the parts, make the monitors, drive, finish (module docstring)."""
        compilation = self.compilation
        compiler = find_compiler(compilation.compiler) if compilation.fast else \
            compilation.compiler
        started = time.perf_counter()
        self.parts = build_parts(self.problem, compilation, compiler)
        built = time.perf_counter()
        # the check and the recheck are compiled where the march's own chunk is (one fallback
        # warning, not three), or (careful path) with the compiler asked for
        compiled = self.parts.fast_chunk is not None and self.parts.fast_chunk.path == "compiled"
        self.judging = compiler if compiled else \
            None if compilation.fast else find_compiler(compilation.compiler)
        self.rechecking = compiler if compiled else None
        self.thinning = self._thinning() if self.output.thinned else None
        monitors = make_monitors(self.kinds, self)
        outcome = self._drive(monitors)
        timing = {"build_s": built - started, "solve_s": time.perf_counter() - built}
        solution = self._thinned(outcome, timing) if self.thinning is not None else \
            self._rechecked(outcome, timing)
        for monitor in monitors:
            monitor.finish(solution, outcome)
        attach(solution, self.problem.system, self.problem.theta, self.problem.t_end)
        if self.thinning is None:  # a thinned march read its t_eval states as it went
            evaluate_at(solution, self.output.t_eval)
        return solution

    def _drive(self, monitors):
        """The driver's run of the stepper under ``monitors``, from the start or from the
        earlier nodes (watched again by the monitors that ``rewatch``)."""
        problem, parts, output = self.problem, self.parts, self.output
        nodes = Nodes(problem.t0, problem.z0)
        if self.start is not None:  # the earlier nodes, watched again; the loop's state restored
            nodes = self.start.restore(parts.stepper, parts.tally,
                                       [monitor for monitor in monitors if monitor.rewatch],
                                       parts.functions, problem.theta)
        try:
            outcome = drive(parts.stepper, nodes, t_end=problem.t_end,
                            max_steps=problem.steps.max_steps,
                            time_limit=problem.steps.time_limit, monitors=monitors,
                            progress=output.progress, catch_interrupt=True, stop=output.stop,
                            thinning=self.thinning)
        finally:
            for monitor in monitors:  # a checkpoint in flight lands before the final write
                monitor.close()
        if isinstance(parts.stepper, MarchStepper):  # fast_steps: the fast nodes the run kept
            parts.stepper.compiled.settle(outcome.marched)
        return outcome

    def _solution(self, outcome, timing, canonical, energy) -> Solution:
        """The `Solution` of the kept nodes, with the residuals ``canonical`` (per step) and
        ``energy`` (per inner node) and the stepper's counts."""
        problem, parts = self.problem, self.parts
        t, z = outcome.t, outcome.z
        n = problem.system.n
        fast_chunk, tally = parts.fast_chunk, parts.tally
        return Solution(
            t=t, q=z[:, :n].copy(), p=z[:, n:].copy(), status=outcome.status,
            message=outcome.message, scheme=problem.scheme.rule, energy_residual=energy,
            canonical_residual=canonical, newton_iterations=parts.newton.newton_iterations,
            timing={**timing, "compile_s": fast_chunk.compile_s if fast_chunk else 0.0},
            stats={"retries": parts.newton.retries,
                   "path": fast_chunk.path if fast_chunk else "careful",
                   "fast_steps": tally.fast_steps, "careful_steps": tally.careful_steps,
                   "fallbacks": tally.fallbacks, "first_fallback": tally.first_fallback},
            march=MarchRecord(theta=problem.theta.tolist(), least_squares=tally.least_squares))

    def _rechecked(self, outcome, timing) -> Solution:
        """The `Solution` with every equation recomputed on the returned grid (compiled with
        ``rechecking``, else on CasADi's virtual machine; not for a stopped long march, whose
        residual arrays are then empty) and the verdict of the accuracy check on every node
        (none for a stopped long march, `_left_unjudged`)."""
        problem, accuracy, output = self.problem, self.accuracy, self.output
        started = time.perf_counter()
        t, z, n = outcome.t, outcome.z, problem.system.n
        canonical, energy = (np.zeros((0, 2 * n)), np.zeros(0)) if _stopping(outcome, output) \
            else recheck_residuals(problem.system, problem.scheme, t, z[:, :n], z[:, n:],
                                   problem.theta, compiler=self.rechecking,
                                   cache_dir=self.compilation.cache_dir)
        verified = time.perf_counter()
        solution = self._solution(outcome, timing, row_max_abs(canonical) if canonical.size
                                  else np.zeros(0), energy)
        solution.timing["verify_s"] = verified - started
        if accuracy is None or _left_unjudged(solution, outcome, output):
            return solution
        started = time.perf_counter()
        try:
            report, local = self._judged(
                solution, outcome.z,
                stop=output.stop if _too_many_to_judge(outcome.t.size) else None)
        except CheckStopped:
            _left_unjudged(solution, outcome, output, asked=True)
            return solution
        judge(solution, report, accuracy, local_error=local)
        solution.timing["accuracy_s"] = time.perf_counter() - started
        return solution

    def _judged(self, solution, z, *, stop=None):
        """The accuracy check of the march's nodes (``accuracy/judgement.py``), the exact flow
        compiled with ``judging``; for the energy rules the level the first step sets is tested
        too (`MarchProblem.level`). The RK4 screen of the local test suits a second-order
        scheme. ``z``: the nodes ``(q, p)`` as the drive kept them (``solution.q`` and
        ``solution.p`` are copies of its columns: not joined again)."""
        problem, tolerance = self.problem, self.accuracy
        t = solution.t
        judgement = Judgement(problem.system, problem.theta, tolerance, compiler=self.judging,
                              cache_dir=self.compilation.cache_dir)
        return judgement.report(t, z, level=problem.level(t, z), screen=True,
                                exact=tolerance.exact, stop=stop)

    def _thinning(self) -> Thinning:
        """What a thinned march keeps (``thinning.py``), with its streamed accuracy check."""
        problem, accuracy, output = self.problem, self.accuracy, self.output
        system, scheme, theta, n = problem.system, problem.scheme, problem.theta, problem.system.n
        cache_dir = self.compilation.cache_dir
        streamed = None
        if accuracy is not None:
            streamed = StreamingJudgement(
                Judgement(system, theta, accuracy, compiler=self.judging, cache_dir=cache_dir),
                screen=True, exact=accuracy.exact, level=problem.level)

        def residuals(t, z):
            return recheck_residuals(system, scheme, t, z[:, :n], z[:, n:], theta,
                                     compiler=self.rechecking, cache_dir=cache_dir)
        return Thinning(output.keep_every, output.keep, residuals=residuals, judge=streamed,
                        t_eval=output.t_eval, field=DenseField.of(system, theta),
                        window=output.window)

    def _thinned(self, outcome, timing) -> Solution:
        """The `Solution` of a thinned march: the kept nodes and what `Thinning` kept of the
        rest (``march.kept``, the ``t_eval`` states); the verdict of the streamed check."""
        started = time.perf_counter()
        thinning, t = self.thinning, outcome.t
        kept = thinning.arrays(outcome.z.shape[1])
        solution = self._solution(outcome, timing, kept["canonical"], kept["energy"])
        solution.march.kept = thinning.record(outcome.marched, int(t.size))
        if self.accuracy is not None:
            judge(solution, thinning.judge.report(float(t[-1])), self.accuracy,
                  local_error=kept["local"])
        solution.timing["finish_s"] = time.perf_counter() - started
        if self.output.t_eval is not None:
            solution.t_eval, solution.z_eval = kept["t_eval"], kept["z_eval"]
        return solution


@dataclass
class Parts:
    """What `build_parts` made: the stepper and what the ``Solution`` reads back from it."""

    functions: StepFunctions
    newton: NewtonSteps
    tally: Tally
    fast_chunk: FastChunk | None
    stepper: CarefulStepper | MarchStepper


def build_parts(problem: MarchProblem, compilation: Compilation, compiler) -> Parts:
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
    return Parts(functions, newton, tally, fast_chunk, stepper)


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
