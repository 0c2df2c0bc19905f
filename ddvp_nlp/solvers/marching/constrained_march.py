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

What it does not do yet is refused by name before anything is built (`refuse_unsupported`):
a backward span, ``v0``, ``target_error``, ``derivatives``, thinned output, checkpoints,
least-squares breakdown steps, step bounds. The accuracy check is not made: the exact flow does
not know constraints yet, so the run is returned unjudged (``Solution.verdict`` is ``None`` and
``accuracy_skipped`` says why), never called accurate.

``Solution.constraints`` (a `ConstraintRecord`) holds, per node, ``|g|`` and the hidden
constraint's residual, the multipliers of every step, its Newton updates and what the
projection of the start moved.
"""

from __future__ import annotations

import math
import time
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
from ...validation import check_memory, check_span, check_state, check_step, check_times
from ..accuracy.judgement import Judgement, judge
from ..compiler import find_compiler
from ..dense import DenseField, EventMonitor, evaluate_at
from ..driver import Advance, Nodes, describe_phase_space, drive
from .acceptance import Acceptance
from .constrained_start import StartProjection, consistent_start
from .constrained_steps import ConstrainedChunk, constrained_chunk
from .null_space_steps import NullSpaceChunk, check_constraint_method

__all__ = ["ConstraintRecord", "march_constrained", "refuse_unsupported"]

RETRY_FACTORS = (0.5, 2.0, 0.25)


@dataclass
class ConstraintRecord:
    """What a constrained march found besides its nodes."""

    constraint_residual: np.ndarray  # |g(q_k, t_k)|_inf per node (N,)
    hidden_residual: np.ndarray  # |G H_p + g_t|_inf per node (N,)
    multipliers: np.ndarray  # (lambda_k, mu_k) per step (N-1, 2m)
    newton_updates: np.ndarray  # Newton updates per step (N-1,)
    start: StartProjection
    retries: int = 0


def refuse_unsupported(system, *, v0, backward, target_error, derivatives, output, steps):
    """``InputError`` naming what a constrained march does not do yet."""
    name = system.name
    asked = [(v0 is not None, "v0 (give p0)"), (backward, "a backward span (t_end < t0)"),
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
        self.multipliers, self.updates = [], []
        self.drift, self.retries, self.steps = 0.0, 0, 0

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
            self.drift += float(rows[:, 4 + n2 + m2 + 2].sum())
        self.multipliers.extend(rows[:, 1 + n2:1 + n2 + m2])
        self.updates.extend(rows[:, 2 + n2 + m2].astype(int))
        self.steps += rows.shape[0]
        return Advance(rows[:, 0].copy(), rows[:, 1:1 + n2].copy())


def march_constrained(system, q0, p0, t_span, *, tau0, v0, scheme, params, steps, accuracy,
                      compilation, output, target_error, derivatives) -> Solution:
    """`march` of a constrained system (module docstring): the options are already objects."""
    backward = t_span is not None and len(tuple(t_span)) == 2 and \
        float(tuple(t_span)[1]) < float(tuple(t_span)[0])
    refuse_unsupported(system, v0=v0, backward=backward, target_error=target_error,
                       derivatives=derivatives, output=output, steps=steps)
    check_constraint_method(system, scheme, steps.constraint_method)
    if output.t_eval is not None:
        count = output.t_eval.size
        check_memory("len(t_eval)", count, count * 8.0 * (8 + 16 * system.n),
                     f"the states at {count} output times")
    q0 = check_state("q0", q0, system.n)
    if p0 is None:
        raise InputError("give p0")
    p0 = check_state("p0", p0, system.n)
    t0, t_end = check_span(t_span)
    tau0 = check_step(tau0, t0, t_end)
    if tau0 > t_end - t0:
        raise InputError(f"tau0 must not exceed |t_end - t0| = {t_end - t0!r}, got {tau0!r}")
    check_times(output.t_eval, (t0, t_end))
    theta = system.parameter_vector(params)
    H0 = float(system.energy(q0[None, :], p0[None, :], np.array([t0]), theta)[0])
    if not math.isfinite(H0):
        raise InputError(f"H is not finite at the initial state q0={q0.tolist()}, "
                         f"p0={p0.tolist()}, t0={t0!r}: H = {H0!r}")
    start = consistent_start(system, q0, p0, t0, theta)
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
    monitors = _monitors(output, events, field, t_end, t0, z0)
    try:
        outcome = drive(stepper, Nodes(t0, z0), t_end=t_end, max_steps=steps.max_steps,
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
    evaluate_at(solution, output.t_eval)
    _judged(solution, system, theta, accuracy, compiler, compilation.cache_dir)
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


def _monitors(output, events, field, t_end, t0, z0) -> list:
    """The events, the stop request and the checkpoints (no carried state: a constrained
    march is not continued yet, so a save that takes one gets ``None``)."""
    from .monitors import Checkpoint, StopRequest, with_state

    monitors = [EventMonitor(events, field, t_end, np.float64(t0), z0)] if events else []
    if output.stop is not None:
        monitors.append(StopRequest(output.stop))
    if output.checkpoint is not None:
        save, _ = with_state(output.checkpoint, _NoCarry())
        monitors.append(Checkpoint(save, output.checkpoint_interval, state=None))
    return monitors


class _NoCarry:
    state = None


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
        return {"node": node, "interval": interval, "energy": energy}
    return cached(system, ("constrained_recheck", scheme), build)
