"""The march of a system with holonomic constraints (``system.constraints``): node by node on
the equations of ``discrete/constrained.py``, with the energy-determined steps of ``vddvp`` and
``lee`` or ``fixed`` steps.

`march` hands a constrained system here (`march_constrained`). The start is made consistent
first (``constrained_start.py``: projected onto ``g = 0`` and the hidden constraint, what moved
said). Step 0 of an energy rule is a fixed-length step of ``tau0``; each later step solves the
interval rows, the node rows and the energy row for ``(z_{k+1}, lambda_k, mu_k, tau_k)``
(``constrained_steps.py``: compiled chunks of steps, each checked, a failed step retried from
other guesses of ``tau``). The one step loop (``solvers/driver.py``) runs it, so ``max_steps``,
``time_limit``, Ctrl-C, ``Output.events`` and the cut at ``t_end`` are the march's own; ``t_eval``
and ``Solution.at`` interpolate with the constrained field's slopes.

A backward span (``t_end < t0``) is the forward march of the time-reversed system, which
carries the constraint ``g(q, -t)`` (``backward.py``), mapped back. `continue_constrained`
(`continue_march`) goes on from a `MarchState` with the carried drift and last multipliers;
the earlier steps' multipliers are recovered from their interval rows (`recover_multipliers`).
`march_ensemble` checks and projects every start first (`check_ensemble_starts`).
What it does not do yet is refused by name before anything is built (`refuse_unsupported`):
``v0``, ``target_error``, ``derivatives``, thinned output, least-squares breakdown steps, an
energy guard. The accuracy check is made against the constrained exact flow (`_judged`).

``Solution.constraints`` (a `ConstraintRecord`) holds, per node, ``|g|`` and the hidden
constraint's residual, the multipliers of every step, its Newton updates and what the
projection of the start moved.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...discrete.constrained import (
    constrained_field_function,
    energy_expression,
    interval_expression,
    node_expression,
)
from ...errors import InputError
from ...solution import MarchRecord, Solution, Status
from ...validation import (
    check_memory,
    check_real,
    check_span,
    check_state,
    check_step,
    check_times,
)
from ..accuracy.judgement import Judgement, judge
from ..compiler import find_compiler
from ..dense import DenseField, EventMonitor, evaluate_at
from ..driver import Advance, Nodes, describe_phase_space, drive
from .acceptance import Acceptance
from .backward import is_backward, march_backward
from .constrained_start import StartProjection, consistent_start
from .constrained_steps import ConstrainedChunk, constrained_chunk
from .null_space_steps import NullSpaceChunk, check_constraint_method

__all__ = ["ConstraintRecord", "attach_constrained", "check_ensemble_starts", "checked_start",
           "continue_constrained", "march_constrained", "refuse_unsupported"]

RETRY_FACTORS = (0.5, 2.0, 0.25)
# Gauss-Newton iterations that recover an earlier run's multipliers (recover_multipliers)
RECOVERY_ITERATIONS = 8


@dataclass
class ConstraintRecord:
    """What a constrained march found besides its nodes."""

    constraint_residual: np.ndarray  # |g(q_k, t_k)|_inf per node (N,)
    hidden_residual: np.ndarray  # |G H_p + g_t|_inf per node (N,)
    multipliers: np.ndarray  # (lambda_k, mu_k) per step (N-1, 2m)
    newton_updates: np.ndarray  # Newton updates per step (N-1,)
    start: StartProjection
    retries: int = 0


def refuse_unsupported(system, *, v0, target_error, derivatives, output, steps):
    """``InputError`` naming what a constrained march does not do yet."""
    name = system.name
    asked = [(v0 is not None, "v0 (give p0)"),
             (target_error is not None, "target_error"), (bool(derivatives), "derivatives"),
             (output.thinned, "thinned output (keep_every / keep)"),
             (steps.breakdown == "least_squares", "breakdown='least_squares'"),
             (steps.energy_guard is not None, "energy_guard")]
    refused = [words for present, words in asked if present]
    if refused:
        raise InputError(f"system {name!r} has constraints; its march does not support "
                         f"{', '.join(refused)} yet")


class ConstrainedStepper:
    """The driver's stepper (``driver.py`` rules 1-2) on `ConstrainedChunk`s; it keeps the
    multipliers and the Newton updates of every step it returns."""

    def __init__(self, system, scheme, theta, acceptance: Acceptance, *, t0, t_end, tau0,
                 chunk, compiler, cache_dir, chunk_class=ConstrainedChunk):
        self.n, self.m = system.n, system.n_constraints
        self.variable = scheme.variable_steps
        self.theta, self.tol = np.asarray(theta, float), float(acceptance.tol)
        self.acceptance, self.tau_prev = acceptance, None
        built = {"chunk": chunk, "compiler": compiler, "cache_dir": cache_dir,
                 "chunk_class": chunk_class}
        self.fixed = constrained_chunk(system, scheme, "fixed", **built)
        self.energy = constrained_chunk(system, scheme, "energy", **built) \
            if self.variable else None
        total = 1 if self.variable else max(1, math.ceil((t_end - t0) / tau0 * (1 - 1e-12)))
        self.grid = (t0, tau0 if self.variable else (t_end - t0) / total, t_end, total)
        self.multipliers, self.updates, self.drifts = [], [], []
        self.drift, self.retries, self.steps = 0.0, 0, 0

    def resume(self, state, multipliers) -> Nodes:
        """The nodes of ``state`` (a `MarchState`) as the driver's, this stepper set as it
        stood after them: their steps, multipliers (the last step's as carried, the next
        Newton's guess), compensated drift and last step length."""
        self.steps = state.t.size - 1
        self.multipliers = list(multipliers)
        if state.multipliers is not None and self.multipliers:
            self.multipliers[-1] = np.asarray(state.multipliers, float)
        self.updates = [0] * self.steps  # the earlier steps' Newton work is the earlier run's
        self.drift = float(state.drift)
        self.drifts = [self.drift] * self.steps
        if self.variable and self.steps:
            self.tau_prev = float(state.t[-1] - state.t[-2])
        return Nodes(state.t, state.z)

    def carried(self, steps: int | None = None) -> dict:
        """What the loop carries besides the nodes after ``steps`` steps (default: all it
        took; a chunk computes steps past the cut at ``t_end``), for `MarchState`
        (``resume.py``): the energy rows' compensated drift and the last step's multipliers
        (its interval's energy enters the next energy row)."""
        steps = self.steps if steps is None else int(steps)
        return {"drift": float(self.drifts[steps - 1]) if steps else 0.0, "careful_left": 0,
                "phase": 0,
                "multipliers": [float(v) for v in (self.multipliers[steps - 1] if steps
                                                   else np.zeros(2 * self.m))]}

    def describe(self, z) -> str:
        return describe_phase_space(z)

    def _state(self, nodes: Nodes) -> np.ndarray:
        last = nodes.count - 1
        lam_mu = self.multipliers[-1] if self.multipliers else np.zeros(2 * self.m)
        if not self.variable or self.steps == 0:
            return np.concatenate([[self.steps], nodes.z[last], lam_mu, [1.0]])
        return np.concatenate([nodes.t[last - 1:last + 1], nodes.z[last - 1], nodes.z[last],
                               lam_mu, [self.drift, 1.0]])

    def advance(self, nodes: Nodes, budget: int) -> Advance:
        first_step = self.steps == 0
        chunk = self.fixed if (first_step or not self.variable) else self.energy
        t0, h, t_end, total = self.grid
        constants = np.concatenate([[t0, h, t0 + h if self.variable else t_end, total],
                                    self.theta, [self.tol]]) if chunk is self.fixed else \
            np.concatenate([self.theta, [self.tol, 1.0]])
        state = self._state(nodes)
        rows = chunk.one(state, constants)[None, :] if first_step else chunk(state, constants)
        good = int(np.argmin(rows[:, -1] > 0)) if not np.all(rows[:, -1] > 0) else rows.shape[0]
        if good == 0 and chunk is self.energy:
            rows, good = self._retry(state, constants)
        rows = rows[:min(good, budget)]
        if rows.shape[0] == 0:
            return Advance.failed(*self._failure(chunk, state, constants), 2 * self.n)
        return self._bounded(rows, chunk is self.energy)

    def _bounded(self, rows, energy_step: bool) -> Advance:
        """The rows up to the first that breaks a step bound (``acceptance.py``)."""
        tau = rows[:, 1 + 2 * self.n + 2 * self.m]
        before = np.concatenate([[np.nan if self.tau_prev is None else self.tau_prev],
                                 tau[:-1]])
        ok = self.acceptance.bounds_ok(tau, before)
        if self.tau_prev is None:  # the first step has no ratio
            ok[0] = self.acceptance.bounds_ok(tau[:1], None)[0]
        keep = rows.shape[0] if ok.all() else int(np.argmin(ok))
        if keep == 0:
            previous = None if self.tau_prev is None else float(before[0])
            return Advance.failed(*self.acceptance.broken_bound(float(tau[0]), previous),
                                  2 * self.n)
        self.tau_prev = float(tau[keep - 1])
        return self._accepted(rows[:keep], energy_step)

    def _retry(self, state, constants):
        for factor in RETRY_FACTORS:
            self.retries += 1
            constants = constants.copy()
            constants[-1] = factor
            row = self.energy.one(state, constants)
            if row[-1] > 0:
                return row[None, :], 1
        return np.zeros((0, self.energy.width)), 0

    def _failure(self, chunk, state, constants) -> tuple[Status, str]:
        row = chunk.one(state, constants)
        n2, m2 = 2 * self.n, 2 * self.m
        tau, residuals = row[1 + n2 + m2], row[3 + n2 + m2:8 + n2 + m2]
        if not np.all(np.isfinite(row)):
            return Status.NON_FINITE, "the step's Newton gave non-finite values"
        if tau <= 0:
            return Status.NO_ADMISSIBLE_STEP, (
                f"Newton found tau = {tau:.6g}: the energy row has no positive root here "
                "(docs/theory.md, constrained steps: c changes sign)")
        return Status.RESIDUAL_TOO_LARGE, (
            f"residuals (interval, g, hidden, energy) = "
            f"{', '.join(f'{v:.3e}' for v in residuals[:4])}")

    def _accepted(self, rows, energy_step: bool) -> Advance:
        n2, m2 = 2 * self.n, 2 * self.m
        if energy_step:
            increments = rows[:, 4 + n2 + m2 + 2]
            self.drifts.extend(self.drift + np.cumsum(increments))  # per step, for carried()
            self.drift += float(increments.sum())
        else:
            self.drifts.extend([self.drift] * rows.shape[0])
        self.multipliers.extend(rows[:, 1 + n2:1 + n2 + m2])
        self.updates.extend(rows[:, 2 + n2 + m2].astype(int))
        self.steps += rows.shape[0]
        return Advance(rows[:, 0].copy(), rows[:, 1:1 + n2].copy())


def checked_start(system, q0, p0, t_span, tau0, params, *, t_eval=None):
    """A constrained march's inputs checked before anything is built: ``(t0, t_end, tau0,
    theta, projected)``, ``projected(warn=...)`` the consistent start (`consistent_start`)."""
    q0 = check_state("q0", q0, system.n)
    if p0 is None:
        raise InputError("give p0")
    p0 = check_state("p0", p0, system.n)
    t0, t_end = check_span(t_span)
    tau0 = check_step(tau0, t0, t_end)
    if tau0 > t_end - t0:
        raise InputError(f"tau0 must not exceed |t_end - t0| = {t_end - t0!r}, got {tau0!r}")
    check_times(t_eval, (t0, t_end))
    theta = system.parameter_vector(params)
    H0 = float(system.energy(q0[None, :], p0[None, :], np.array([t0]), theta)[0])
    if not math.isfinite(H0):
        raise InputError(f"H is not finite at the initial state q0={q0.tolist()}, "
                         f"p0={p0.tolist()}, t0={t0!r}: H = {H0!r}")

    def projected(warn: bool) -> StartProjection:
        return consistent_start(system, q0, p0, t0, theta, warn=warn)
    return t0, t_end, tau0, theta, projected


def check_ensemble_starts(system, q0s, p0s, t_span, tau0, params) -> np.ndarray:
    """`march_ensemble`'s check of a constrained system's starts: each as its march checks
    it (a start that cannot be made consistent is an `InputError` naming its orbit), one
    ``RuntimeWarning`` naming the orbits whose start the projection moves and by how much
    (each orbit's ``Solution.constraints.start`` says it again); returns ``theta``."""
    theta, moved = None, []
    for i, (q0, p0) in enumerate(zip(q0s, p0s, strict=True)):
        try:
            _, _, _, theta, projected = checked_start(system, q0, p0, t_span, tau0, params)
            projection = projected(warn=False)
        except InputError as exc:
            raise InputError(f"orbit {i}: {exc}") from None
        if projection.moved:
            moved.append((i, projection.moved_q, projection.moved_p))
    if moved:
        listed = "; ".join(f"orbit {i}: q0 by {dq:.3g}, p0 by {dp:.3g}"
                           for i, dq, dp in moved[:10])
        more = f" and {len(moved) - 10} more" if len(moved) > 10 else ""
        warnings.warn(f"{len(moved)} of {len(q0s)} starts were projected onto the constraints "
                      f"(max norm) ({listed}{more}); each orbit's Solution.constraints.start "
                      "holds the start used", RuntimeWarning, stacklevel=3)
    return theta


def march_constrained(system, q0, p0, t_span, *, tau0, v0, scheme, params, steps, accuracy,
                      compilation, output, target_error, derivatives, start=None) -> Solution:
    """`march` of a constrained system (module docstring): the options are already objects.
    ``start``: a `MarchState` to go on from (`continue_march`; ``q0``, ``p0`` are its first
    node)."""
    refuse_unsupported(system, v0=v0, target_error=target_error,
                       derivatives=derivatives, output=output, steps=steps)
    check_constraint_method(system, scheme, steps.constraint_method)
    if is_backward(t_span):  # the forward march of H(q, -p, -t) on g(q, -t), mapped back
        solution = march_backward(_reversed_march, system, q0, p0, t_span, tau0=tau0, v0=None,
                                  scheme=scheme, params=params, steps=steps,
                                  accuracy=accuracy, compilation=compilation, output=output)
        theta = np.asarray(solution.march.theta, float)
        return attach_constrained(solution, system, theta, solution.t_end)
    if output.t_eval is not None:
        count = output.t_eval.size
        check_memory("len(t_eval)", count, count * 8.0 * (8 + 16 * system.n),
                     f"the states at {count} output times")
    t0, t_end, tau0, theta, projected = checked_start(system, q0, p0, t_span, tau0, params,
                                                      t_eval=output.t_eval)
    resumed, start = start, projected(warn=start is None)
    events = tuple(output.events or ())  # already checked by Output
    started = time.perf_counter()
    compiler = find_compiler(compilation.compiler) if compilation.fast else None
    acceptance = Acceptance(steps.tol, steps.tau_min, steps.tau_max, steps.max_step_ratio)
    stepper = ConstrainedStepper(system, scheme, theta, acceptance, t0=t0, t_end=t_end,
                                 tau0=tau0, chunk=compilation.chunk, compiler=compiler,
                                 cache_dir=compilation.cache_dir,
                                 chunk_class=NullSpaceChunk if
                                 steps.constraint_method == "null_space" else ConstrainedChunk)
    built = time.perf_counter()
    field = DenseField(constrained_field_function(system), system.H_function, theta,
                       system.name)
    z0 = np.concatenate([start.q0, start.p0])
    nodes = Nodes(t0, z0) if resumed is None else \
        stepper.resume(resumed, recover_multipliers(system, scheme, theta, resumed.t,
                                                    resumed.z))
    monitors = _monitors(output, events, field, t_end, t0, z0, stepper)
    try:
        outcome = drive(stepper, nodes, t_end=t_end, max_steps=steps.max_steps,
                        time_limit=steps.time_limit, monitors=monitors,
                        progress=output.progress, catch_interrupt=True, stop=output.stop)
    finally:
        for monitor in monitors:
            getattr(monitor, "close", lambda: None)()
    solved = time.perf_counter()
    solution = _solution(system, scheme, theta, outcome, stepper, start)
    solution.timing = {"build_s": built - started, "solve_s": solved - built,
                       "compile_s": stepper.fixed.compile_s + (
                           stepper.energy.compile_s if stepper.energy else 0.0),
                       "verify_s": time.perf_counter() - solved}
    for monitor in monitors:
        if isinstance(monitor, EventMonitor):
            monitor.report(solution)
    solution.t_end, solution.vector_field, solution.system = t_end, field, system
    solution.march.carried = stepper.carried(solution.t.size - 1)
    evaluate_at(solution, output.t_eval)
    _judged(solution, system, theta, accuracy, compiler, compilation.cache_dir)
    return solution


def continue_constrained(system, state, t_end, *, tau0, scheme, params, steps, accuracy,
                         compilation, output) -> Solution:
    """`continue_march` of a constrained system: the march of ``state`` (a `MarchState`)
    gone on to ``t_end`` from its last node with what its loop carried (the compensated
    drift, the last multipliers), its earlier steps' multipliers recovered from their
    interval rows (`recover_multipliers`) for the whole run's recheck and verdict. The new
    nodes are an uninterrupted run's to the Newton's tolerance (the multipliers of the last
    step are the next Newton's guess; a run folder keeps them to every bit). Events are
    refused (their earlier crossings are not searched again)."""
    from types import SimpleNamespace

    from .resume import check_resume

    if output.events:
        raise InputError("continue_march of a constrained system does not take events (the "
                         "crossings before the resumed node are not searched again): march "
                         "the whole span with Output(events=...)")
    n, m = system.n, system.n_constraints
    if state.z.shape[1] != 2 * n:
        raise InputError(f"the state has {state.z.shape[1] // 2} coordinates, the system "
                         f"{system.name!r} has {n}")
    if state.multipliers is not None and len(state.multipliers) != 2 * m:
        raise InputError(f"the carried multipliers have {len(state.multipliers)} values; "
                         f"{system.name!r} has {m} constraints, 2m = {2 * m} multipliers")
    t_end = state.t_end if t_end is None else check_real("t_end", t_end)
    tau0 = check_step(tau0, float(state.t[0]), t_end)
    problem = SimpleNamespace(t_end=t_end, tau0=tau0, q0=state.z[0, :n], p0=state.z[0, n:])
    check_resume(state, problem, scheme.variable_steps)
    return march_constrained(system, state.z[0, :n], state.z[0, n:], (float(state.t[0]), t_end),
                             tau0=tau0, v0=None, scheme=scheme, params=params, steps=steps,
                             accuracy=accuracy, compilation=compilation, output=output,
                             target_error=None, derivatives=(), start=state)


def _reversed_march(system, q0, p0, t_span, *, v0, output, **options) -> Solution:
    """`march_constrained` as ``backward.march_backward`` calls a march (the options are
    objects already)."""
    return march_constrained(system, q0, p0, t_span, v0=v0, output=output, target_error=None,
                             derivatives=(), **options)


def attach_constrained(solution: Solution, system, theta, t_end) -> Solution:
    """`dense.attach` for a constrained system: ``Solution.at`` and the events on the
    constrained field's slopes (``DenseField.of`` would take the unconstrained field)."""
    solution.t_end = None if t_end is None else float(t_end)
    solution.vector_field = DenseField(constrained_field_function(system), system.H_function,
                                       np.asarray(theta, float), system.name)
    solution.system = system
    return solution


def _judged(solution, system, theta, accuracy, compiler, cache_dir) -> None:
    """The accuracy check of a constrained march, as of every march: against the constrained
    exact flow (index-reduced, projected onto the constraints inside its error control,
    ``exact/constrained_flow.py``), which the check's exact flow becomes for a system with
    constraints; the RK4 screen of the local test runs on the index-reduced field. No level
    test: the march's energy row holds the interval energies, which the constraints' forces
    do not change."""
    if accuracy is None:
        return
    started = time.perf_counter()
    report, local = Judgement(system, theta, accuracy, compiler=compiler,
                              cache_dir=cache_dir).report(
        solution.t, np.hstack([solution.q, solution.p]), screen=True, exact=accuracy.exact)
    judge(solution, report, accuracy, local_error=local)
    solution.timing["accuracy_s"] = time.perf_counter() - started


def _monitors(output, events, field, t_end, t0, z0, stepper) -> list:
    """The events, the stop request and the checkpoints (a save that takes a third argument
    gets the stepper's carried state, for `MarchState`)."""
    from .monitors import Checkpoint, StopRequest, with_state

    monitors = [EventMonitor(events, field, t_end, np.float64(t0), z0)] if events else []
    if output.stop is not None:
        monitors.append(StopRequest(output.stop))
    if output.checkpoint is not None:
        save, state = with_state(output.checkpoint, _Carry(stepper))
        monitors.append(Checkpoint(save, output.checkpoint_interval, state=state))
    return monitors


class _Carry:
    """The stepper's carried state as the checkpoint reads it (``with_state``)."""

    def __init__(self, stepper):
        self.stepper = stepper

    def state(self) -> dict:
        return self.stepper.carried()


def recover_multipliers(system, scheme, theta, t, z) -> np.ndarray:
    """The multipliers ``(lambda_k, mu_k)`` of the steps between the nodes ``(t, z)`` of an
    earlier march, which a `MarchState` does not hold: each step's ``2n`` interval rows solved
    for its ``2m`` multipliers by Gauss-Newton with the nodes fixed (least squares: the nodes
    satisfy the rows to the march's tolerance). The continued run's recheck reads them."""
    N, m = t.size, system.n_constraints
    if N < 2:
        return np.zeros((0, 2 * m))
    rows = _recheck_functions(system, scheme)["interval_jacobian"].map(N - 1)
    lm = np.zeros((N - 1, 2 * m))
    for _ in range(RECOVERY_ITERATIONS):
        r, J = rows(t[None, :-1], t[None, 1:], z[:-1].T, z[1:].T, lm.T, theta[:, None])
        r = np.asarray(r).T  # (N-1, 2n)
        J = np.asarray(J).reshape(2 * system.n, N - 1, 2 * m).transpose(1, 0, 2)
        JT = J.transpose(0, 2, 1)
        step = np.linalg.solve(JT @ J, (JT @ r[:, :, None]))[:, :, 0]
        lm = lm - step
        if np.abs(step).max() <= 4 * np.finfo(float).eps * max(np.abs(lm).max(), 1e-300):
            break
    return lm


def _solution(system, scheme, theta, outcome, stepper, start) -> Solution:
    """The `Solution` of the kept nodes, every equation recomputed on them."""
    t, z, n = outcome.t, outcome.z, system.n
    steps = t.size - 1
    multipliers = np.asarray(stepper.multipliers[:steps]).reshape(steps, 2 * system.n_constraints)
    residuals = recheck(system, scheme, theta, t, z, multipliers)
    solution = Solution(
        t=t, q=z[:, :n].copy(), p=z[:, n:].copy(), status=outcome.status,
        message=outcome.message, scheme=scheme.rule, energy_residual=residuals["energy"],
        canonical_residual=residuals["canonical"],
        newton_iterations=int(np.sum(stepper.updates[:steps])),
        stats={"retries": stepper.retries, "path": stepper.fixed.path},
        march=MarchRecord(theta=np.asarray(theta).tolist()))
    solution.constraints = ConstraintRecord(
        residuals["constraint"], residuals["hidden"], multipliers,
        np.asarray(stepper.updates[:steps], dtype=int), start, stepper.retries)
    return solution


def recheck(system, scheme, theta, t, z, multipliers) -> dict:
    """Every equation of a constrained grid, unscaled: the interval rows (largest per step),
    ``|g|`` and the hidden residual per node, the energy rows (the scheme's, ``lee`` for
    ``fixed`` steps) at the inner nodes."""
    m, N = system.n_constraints, t.size
    functions = _recheck_functions(system, scheme)
    nodes = np.asarray(functions["node"].map(N)(z.T, t[None, :], theta[:, None]))
    result = {"constraint": np.abs(nodes[:m]).max(axis=0),
              "hidden": np.abs(nodes[m:]).max(axis=0),
              "canonical": np.zeros(max(N - 1, 0)), "energy": np.zeros(max(N - 2, 0))}
    if N >= 2:
        lam, mu = multipliers[:, :m].T, multipliers[:, m:].T
        rows = functions["interval"].map(N - 1)(t[None, :-1], t[None, 1:], z[:-1].T, z[1:].T,
                                                lam, mu, theta[:, None])
        result["canonical"] = np.abs(np.asarray(rows)).max(axis=0)
    if N >= 3:
        energy = functions["energy"].map(N - 2)(
            t[None, :-2], t[None, 1:-1], t[None, 2:], z[:-2].T, z[1:-1].T, z[2:].T,
            multipliers[:-1].T, multipliers[1:].T, theta[:, None])
        result["energy"] = np.asarray(energy).ravel()
    return result


def _recheck_functions(system, scheme) -> dict:
    from ...cache import cached

    def build():
        n, m, theta = system.n, system.n_constraints, system.theta
        t = [ca.SX.sym(f"t{i}") for i in range(3)]
        z = [ca.SX.sym(f"z{i}", 2 * n) for i in range(3)]
        lm = [ca.SX.sym(f"lm{i}", 2 * m) for i in range(2)]
        node = ca.Function("node", [z[0], t[0], theta],
                           [node_expression(system, z[0][:n], z[0][n:], t[0], theta)])
        interval = ca.Function("interval", [t[0], t[1], z[0], z[1], lm[0][:m], lm[0][m:],
                                            theta],
                               [interval_expression(system, scheme, t[0], t[1], z[0][:n],
                                                    z[0][n:], z[1][:n], z[1][n:], lm[0][:m],
                                                    lm[0][m:], theta)])
        rule = scheme.rule if scheme.variable_steps else "lee"
        energy = ca.Function("energy", [*t, *z, *lm, theta], [energy_expression(
            system, scheme, rule, (*t, z[0][:n], z[0][n:], z[1][:n], z[1][n:], z[2][:n],
                                   z[2][n:]), (lm[0][:m], lm[0][m:], lm[1][:m], lm[1][m:]),
            theta)])
        lm_all = lm[0]
        rows = interval(t[0], t[1], z[0], z[1], lm_all[:m], lm_all[m:], theta)
        jacobian = ca.Function("interval_jacobian", [t[0], t[1], z[0], z[1], lm_all, theta],
                               [rows, ca.jacobian(rows, lm_all)])
        return {"node": node, "interval": interval, "energy": energy,
                "interval_jacobian": jacobian}
    return cached(system, ("constrained_recheck", scheme), build)
