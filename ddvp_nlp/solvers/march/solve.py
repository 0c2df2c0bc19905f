"""Initial-value problems: march node by node with a CasADi rootfinder (docs/theory.md section 5).

Step 0 is a plain implicit step of length ``tau0``: the ``2n`` canonical equations of interval 0
are solved for ``z_1``. Every later step ``k`` solves ``2n + 1`` equations, the canonical equations
of interval ``k`` and the energy equation at node ``k``, for ``(z_{k+1}, tau_k)``. ``tau0`` thus
fixes the discrete energy level and every later step. With ``rule="fixed"`` every step solves the
canonical equations only, on uniform steps that end on ``t_end``.

A step is accepted only if Newton converged, every value is finite, ``tau_k > 0`` (the
time-reversed root ``(z_{k-1}, -tau_{k-1})`` solves the midpoint step equations for every state),
the step's own unscaled residuals are below ``tol`` (relative to ``max(1, |z|)`` and
``max(1, |H|)``) and the optional step bounds hold (``acceptance.py``). The first step that fails
ends the march with a status; every accepted node is kept.

The parts: ``steps.py`` (the step functions, Newton with retries), ``least_squares.py`` (the
step that replaces a failed one with ``breakdown="least_squares"``), ``chunk.py`` (compiled
chunks of steps), ``stepper.py`` (the careful, compiled and composite steppers), ``monitors.py``
(energy guard, solvability monitor). This module checks the input, builds those parts, runs them
with the driver (``driver.py``) and returns the :class:`Solution`.
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
from ...solution import Solution
from ...validation import check_cache_folder, check_integer, check_real, check_state
from ..accuracy import AccuracyMonitor, ErrorEstimates, Tolerance
from ..compiler import buffered
from ..dense import attach
from ..driver import Nodes, drive
from .acceptance import Acceptance
from .chunk import FastChunk
from .monitors import (
    MONITOR_LIMIT,
    Checkpoint,
    EnergyGuard,
    SolvabilityMonitor,
    StopRequest,
)
from .recheck import grid_residuals
from .stepper import (
    BREAKDOWNS,
    LEAST_SQUARES_CASES,
    CarefulStepper,
    Clock,
    CompiledStepper,
    MarchStepper,
    Tally,
)
from .steps import NEWTON_OPTIONS, RETRY_FACTORS, NewtonSteps, StepFunctions, step_functions

# Names that lived here before the march was split into its parts.
# Steps per compiled call: past this the chunk's generated code and its output buffer grow to
# gigabytes (chunk = 10**9 took two minutes and 4.7 GB for a ten-step march) for no speed gained.
MAX_CHUNK = 65536

__all__ = ["BREAKDOWNS", "LEAST_SQUARES_CASES", "MONITOR_LIMIT", "NEWTON_OPTIONS",
           "RETRY_FACTORS", "march"]


def march(system: HamiltonianSystem, q0, p0=None, *, v0=None, tau0: float, t_end: float,
          t0: float = 0.0,
          scheme: str | Scheme = "vddvp", params: Mapping[str, float] | None = None,
          tol: float = 1e-10, max_steps: int = 10_000_000, tau_min: float | None = None,
          tau_max: float | None = None, max_step_ratio: float | None = 10.0,
          progress: bool = False, fast: bool = True, chunk: int = 1024,
          compiler: str | None = "auto", cache_dir=None, time_limit: float | None = None,
          energy_guard: float | None = None, breakdown: str = "stop", rtol: float = 1e-2,
          atol: float = 1e-2, energy_tol: float = 0.1, global_tol: float | None = None,
          accept_inaccurate: bool = False, check_accuracy: bool = True,
          checkpoint=None, checkpoint_interval: float = 5.0, stop=None) -> Solution:
    """March ``z_0 = (q0, p0)`` from ``t0`` until the first node at or past ``t_end``.

    Args:
        system: the Hamiltonian or Lagrangian system.
        q0: initial position, shape ``(n,)``.
        p0: initial momentum, shape ``(n,)`` (or give ``v0``).
        v0: instead of ``p0``, for a Lagrangian system: the first interval's velocity; the
            march takes ``q_1 = q_0 + tau0 v0`` and ``p_0`` by the discrete Legendre transform.
        tau0: first step; for energy rules it sets the discrete energy level, for ``fixed`` the
            step is ``(t_end - t0) / ceil((t_end - t0) / tau0)``, so the march ends on ``t_end``.
        t_end: end time; energy rules stop at the first node with ``t >= t_end``.
        t0: initial time.
        scheme: ``"vddvp"``, ``"lee"``, ``"fixed"`` or a :class:`Scheme`.
        params: values of the system's parameters (defaults filled in).
        tol: acceptance tolerance of each step's unscaled residuals, relative to ``max(1, |z|)``
            (canonical) and ``max(1, |H|)`` (energy).
        max_steps: bound on the number of steps.
        tau_min: optional lower bound on every step length.
        tau_max: optional upper bound on every step length.
        max_step_ratio: bound on ``max(tau_k/tau_{k-1}, tau_{k-1}/tau_k)`` (``None``: none).
            The default 10 stops a march whose energy equation jumped to a far root: on
            ``kepler`` with ``e = 0.99`` and ``tau0 = 0.01``, without it, the fourth step was 235
            time units, past the whole horizon, and every equation held.
        progress: show a progress bar on stderr.
        fast: run the steps in compiled chunks (``chunk.py``); ``False`` forces the careful
            per-step path. Both accept a step by the same test; their nodes differ by
            round-off (the compiled Newton eliminates where the careful one factors by QR).
        chunk: steps per compiled call.
        compiler: C compiler for the fast path: ``"auto"`` (``$CC``, ``gcc``, ``cc``), a
            command, or ``None`` for CasADi's virtual machine.
        cache_dir: folder of compiled chunks (default ``$DDVP_NLP_CACHE`` or
            ``~/.cache/ddvp_nlp``).
        time_limit: optional bound in seconds on the stepping (status ``time_limit``).
        energy_guard: optional bound on ``|H(z_k, t_k) - H(z_0, t_0)| / max(1, |H(z_0, t_0)|)``
            at every node (status ``energy_guard``).
        breakdown: what an energy rule does when a step has no admissible root: ``"stop"``
            (default) or ``"least_squares"``, the step of Kane, Marsden and Ortiz: the ``tau`` in
            ``[tau_min, tau_max]`` (default ``[tau_prev/10, 10 tau_prev]``) that minimises the
            energy residual subject to the canonical equations (a bounded scalar search). Each
            such step is listed in ``stats["least_squares"]`` with its energy defect, and the
            march goes on.
        rtol: the accuracy check (``accuracy.py``), which does not trust the scheme's own
            equations: every step against one RK4 step of the exact flow, ``delta_k <= atol +
            rtol |z|``. The first failure of any of its tests ends the march with status
            ``inaccurate``; ``stats["accuracy"]`` and ``Solution.local_error`` hold the
            estimates.
        atol: see ``rtol``.
        energy_tol: bound on the first step's energy level and (autonomous ``H``) the nodal
            energy drift against ``H(z_0, t_0)``, relative to ``max(1, |H0|)``.
        global_tol: optional bound on the propagated global error estimate.
        accept_inaccurate: record the first failure of the accuracy check and go on.
        check_accuracy: ``False`` leaves the check out (the comparison does, so that run times
            compare like with like, and makes it afterwards with ``accuracy.assess``).
        checkpoint: optional ``save(t, z)``, called with the nodes kept so far every
            ``checkpoint_interval`` seconds of stepping (at most about 5% of it), so that a
            killed march loses at most one interval (``monitors.Checkpoint``). Its cost is in
            ``timing["checkpoint_s"]`` and ``stats["checkpoints"]``.
        stop: optional ``stop() -> bool``, asked after every stepper call; ``True`` ends the
            march with status ``interrupted``, every accepted node kept (how the command line
            turns Ctrl-C and SIGTERM into a clean end, never an exception inside CasADi).

    The solvability monitor (energy rules): at every node the site-density weight
    ``w = f' H_zz f = -8 c(z)`` (docs/theory.md section 7). A positive step needs ``c`` to keep its
    sign and the step to be short against the change of ``w``; the march warns (a
    ``RuntimeWarning`` and ``stats["solvability_warning"]``) at the first node where ``w``
    changes sign or ``|ln(w_k / w_{k-1})|`` exceeds ``MONITOR_LIMIT`` (``monitors.py``).
    ``Solution.solvability`` holds ``c(z_k)`` at every node.

    Returns:
        A :class:`Solution`; failures are a status on it, never an exception.
    """
    scheme = Scheme.coerce(scheme)
    q0, p0, v0 = _check_start(system, q0, p0, v0)
    options = _check_options(scheme, t0=t0, t_end=t_end, tau0=tau0, tol=tol,
                             max_steps=max_steps, tau_min=tau_min, tau_max=tau_max,
                             max_step_ratio=max_step_ratio, chunk=chunk, time_limit=time_limit,
                             energy_guard=energy_guard, breakdown=breakdown)
    accuracy = Tolerance(rtol=rtol, atol=atol, energy_tol=energy_tol, global_tol=global_tol,
                         stop=not accept_inaccurate)
    saver = _checkpoint(checkpoint, checkpoint_interval)
    check_cache_folder(cache_dir)
    if fast:
        from ..compiler import find_compiler
        compiler = find_compiler(compiler)
    theta = system.parameter_vector(params)
    p0, H0 = _start(system, scheme, q0, p0, v0, t0=options.t0, tau0=options.tau0, theta=theta)

    started = time.perf_counter()
    parts = _build(system, scheme, theta, options, fast=fast, compiler=compiler,
                   cache_dir=cache_dir, check_accuracy=check_accuracy)
    built = time.perf_counter()
    nodes = Nodes(options.t0, np.concatenate([q0, p0]))
    monitors, solvability = _monitors(parts, scheme, options, H0, nodes, theta)
    # the check and the recheck are compiled where the march's own chunk is (one fallback
    # warning, not three)
    compiled = parts.fast_chunk is not None and parts.fast_chunk.path == "compiled"
    checker = None
    if check_accuracy:
        checker = _accuracy_monitor(system, scheme, theta, accuracy, H0, parts.errors)
        monitors.append(checker)
    monitors += [StopRequest(stop)] if stop else []
    monitors += [saver] if saver else []  # last: it sees only the nodes the others kept
    outcome = drive(parts.stepper, nodes, t_end=options.t_end, max_steps=options.max_steps,
                    time_limit=options.time_limit, monitors=monitors, progress=progress,
                    catch_interrupt=True)
    solved = time.perf_counter()
    if isinstance(parts.stepper, MarchStepper):  # fast_steps: the fast nodes the run kept
        parts.stepper.compiled.settle(outcome.t.size)
    solution = _solution(system, scheme, theta, outcome, parts, solvability,
                         compiler=compiler if compiled else None, cache_dir=cache_dir,
                         timing={"build_s": built - started, "solve_s": solved - built})
    if checker is not None:
        solution.local_error = checker.local_errors(solution.steps)
        solution.stats["accuracy"] = checker.report(solution.steps)
    if saver:
        solution.timing["checkpoint_s"] = saver.seconds
        solution.stats["checkpoints"] = saver.saves
    return attach(solution, system, theta, options.t_end)


def _checkpoint(save, interval) -> Checkpoint | None:
    """The checkpoint monitor, if a ``save`` is given (``interval`` checked)."""
    if save is None:
        return None
    if not callable(save):
        raise InputError(f"checkpoint must be a callable save(t, z), got {save!r}")
    return Checkpoint(save, check_real("checkpoint_interval", interval, positive=True))


@dataclass(frozen=True)
class _Options:
    """The checked numbers of one march."""

    t0: float
    t_end: float
    tau0: float
    max_steps: int
    chunk: int
    time_limit: float | None
    energy_guard: float | None
    breakdown: str
    acceptance: Acceptance


def _check_start(system, q0, p0, v0):
    """The system and the initial state: ``q0`` and exactly one of ``p0`` and ``v0``."""
    if not isinstance(system, HamiltonianSystem):
        raise InputError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
    q0 = check_state("q0", q0, system.n)
    if (p0 is None) == (v0 is None):
        raise InputError("give exactly one of p0 and v0")
    if v0 is not None and not system.lagrangian_form:
        raise InputError(f"v0 needs a Lagrangian system; {system.name!r} is Hamiltonian: "
                         "give p0")
    p0 = check_state("p0", p0, system.n) if p0 is not None else None
    v0 = check_state("v0", v0, system.n) if v0 is not None else None
    return q0, p0, v0


def _check_options(scheme: Scheme, *, t0, t_end, tau0, tol, max_steps, tau_min, tau_max,
                   max_step_ratio, chunk, time_limit, energy_guard, breakdown) -> _Options:
    """Every other argument of :func:`march`, checked in the order of its signature."""
    t0, t_end, tau0 = _check_times(t0, t_end, tau0)
    tol = check_real("tol", tol, positive=True)
    max_steps = check_integer("max_steps", max_steps)
    tau_min, tau_max, max_step_ratio = _check_step_bounds(tau0, tau_min, tau_max,
                                                          max_step_ratio)
    chunk = check_integer("chunk", chunk, maximum=MAX_CHUNK)
    time_limit = check_real("time_limit", time_limit, positive=True, allow_none=True)
    energy_guard = check_real("energy_guard", energy_guard, positive=True, allow_none=True)
    if breakdown not in BREAKDOWNS:
        raise InputError(f"breakdown must be one of {', '.join(BREAKDOWNS)}, got {breakdown!r}")
    if breakdown == "least_squares" and not scheme.variable_steps:
        raise InputError("breakdown='least_squares' needs an energy rule (vddvp or lee), got "
                         f"scheme {scheme.rule!r}")
    return _Options(t0, t_end, tau0, max_steps, chunk, time_limit, energy_guard, breakdown,
                    Acceptance(tol, tau_min, tau_max, max_step_ratio))


def _check_times(t0, t_end, tau0):
    """``t0 < t_end`` and a first step ``0 < tau0 <= t_end - t0``."""
    t0 = check_real("t0", t0)
    t_end = check_real("t_end", t_end)
    if t_end <= t0:
        raise InputError(f"t_end must be > t0 = {t0!r}, got {t_end!r}")
    tau0 = check_real("tau0", tau0, positive=True)
    if tau0 > t_end - t0:
        raise InputError(f"tau0 must not exceed t_end - t0 = {t_end - t0!r}, got {tau0!r}")
    return t0, t_end, tau0


def _check_step_bounds(tau0, tau_min, tau_max, max_step_ratio):
    """Optional ``0 < tau_min < tau_max`` around ``tau0`` and ``max_step_ratio > 1``."""
    tau_min = check_real("tau_min", tau_min, positive=True, allow_none=True)
    tau_max = check_real("tau_max", tau_max, positive=True, allow_none=True)
    if tau_min is not None and tau_max is not None and tau_min >= tau_max:
        raise InputError(f"tau_min must be < tau_max = {tau_max!r}, got {tau_min!r}")
    if (tau_min is not None and tau0 < tau_min) or (tau_max is not None and tau0 > tau_max):
        raise InputError(f"tau0 must lie in [tau_min, tau_max] = [{tau_min}, {tau_max}], "
                         f"got {tau0!r}")
    max_step_ratio = check_real("max_step_ratio", max_step_ratio, positive=True,
                                allow_none=True)
    if max_step_ratio is not None and max_step_ratio <= 1:
        raise InputError(f"max_step_ratio must be > 1, got {max_step_ratio!r}")
    return tau_min, tau_max, max_step_ratio


def _start(system, scheme, q0, p0, v0, *, t0, tau0, theta) -> tuple[np.ndarray, float]:
    """``p_0`` (from ``v0`` by the discrete Legendre transform if given) and ``H(z_0, t_0)``."""
    if v0 is not None:
        from ...discrete.lagrangian import start_momentum

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
    """What :func:`_build` made: the stepper and what the ``Solution`` reads back from it."""

    functions: StepFunctions
    newton: NewtonSteps
    tally: Tally
    fast_chunk: FastChunk | None
    stepper: CarefulStepper | MarchStepper
    errors: ErrorEstimates | None


def _build(system, scheme, theta, options: _Options, *, fast, compiler, cache_dir,
           check_accuracy=True) -> _Parts:
    """The step functions (cached on the system), the compiled chunk if ``fast`` (cached too;
    with ``check_accuracy`` it computes the accuracy check's estimates too), the stepper and the
    accuracy check's error state (compiled where the chunk is: one fallback warning, not
    two)."""
    functions = step_functions(system, scheme)
    newton = NewtonSteps(functions, theta, options.acceptance)
    tally = Tally()
    clock = Clock.for_rule(scheme.variable_steps, options.t0, options.t_end, options.tau0)
    stepper = CarefulStepper(newton, clock, tally, variable=scheme.variable_steps,
                             breakdown=options.breakdown)
    fast_chunk = errors = None
    if fast:
        fast_chunk = cached(system,
            ("fast", scheme, options.chunk, compiler, str(cache_dir), check_accuracy),
            lambda: FastChunk(system, scheme, functions, chunk=options.chunk, compiler=compiler,
                              cache_dir=cache_dir, accuracy=check_accuracy))
    if check_accuracy:
        compiled = fast_chunk is not None and fast_chunk.path == "compiled"
        errors = ErrorEstimates(system, compiler=compiler if compiled else None,
                                cache_dir=cache_dir)
    if fast_chunk is not None:
        stepper = MarchStepper(stepper, CompiledStepper(fast_chunk, theta, options.acceptance,
                                                        clock, tally, errors=errors))
    return _Parts(functions, newton, tally, fast_chunk, stepper, errors)


def _monitors(parts: _Parts, scheme, options: _Options, H0, nodes, theta):
    """The energy guard (if asked for) and, for energy rules, the solvability monitor, which
    starts from the weight at node 0. Returns the monitors and the solvability monitor."""
    monitors, solvability = [], None
    if options.energy_guard is not None:
        monitors.append(EnergyGuard(options.energy_guard, H0))
    if scheme.variable_steps:
        monitor = buffered(parts.functions.node_monitor, "node_monitor",
                           owner=parts.functions)
        _, w_first = monitor(nodes.z[0], nodes.t[0], theta)
        solvability = SolvabilityMonitor(float(nodes.t[0]), float(w_first[0, 0]))
        monitors.append(solvability)
    return monitors, solvability


def _accuracy_monitor(system, scheme, theta, tolerance, H0, errors):
    """The accuracy check of the march (its error state ``errors`` shared with the compiled
    chunk); for the energy rules it also compares the level the first step sets, the first
    interval's energy, with ``H0``."""
    level = None
    if scheme.variable_steps:
        interval_energy = buffered(equations.midpoint_energy_function(system, scheme),
                                   "interval_energy", scheme, owner=system)
        n = system.n

        def level(t, z):
            return float(interval_energy(t[0], t[1], z[0, :n], z[0, n:], z[1, :n], z[1, n:],
                                         theta)[0][0, 0])
    return AccuracyMonitor(system, theta, tolerance, H0=H0, level=level, errors=errors)


def _solution(system, scheme, theta, outcome, parts: _Parts, solvability, *, compiler,
              cache_dir, timing):
    """The :class:`Solution`, with every equation recomputed on the returned grid (compiled
    with ``compiler``, else on CasADi's virtual machine)."""
    started = time.perf_counter()
    t, z = outcome.t, outcome.z
    n = system.n
    canonical, energy = grid_residuals(system, scheme, t, z[:, :n], z[:, n:], theta,
                                       compiler=compiler, cache_dir=cache_dir)
    verified = time.perf_counter()
    fast_chunk, tally = parts.fast_chunk, parts.tally
    return Solution(
        t=t, q=z[:, :n].copy(), p=z[:, n:].copy(), status=outcome.status,
        message=outcome.message, scheme=scheme.rule, energy_residual=energy,
        canonical_residual=_row_max_abs(canonical) if canonical.size else np.zeros(0),
        newton_iterations=parts.newton.newton_iterations,
        timing={**timing, "compile_s": fast_chunk.compile_s if fast_chunk else 0.0,
                "verify_s": verified - started},
        solvability=solvability.solvability(t.size) if solvability else np.zeros(0),
        stats={"retries": parts.newton.retries, "theta": theta.tolist(),
               "path": fast_chunk.path if fast_chunk else "careful",
               "fast_steps": tally.fast_steps, "careful_steps": tally.careful_steps,
               "solvability_warning": solvability.warning if solvability else None,
               "least_squares": tally.least_squares})


def _row_max_abs(values: np.ndarray) -> np.ndarray:
    """``np.max(np.abs(values), axis=1)``, the same numbers, column by column: numpy's
    reduction along rows of two cost 0.8 ms of the paper's example (20 150 rows), this 0.05
    (past 16 columns the reduction is the faster)."""
    if values.shape[1] > 16:
        return np.max(np.abs(values), axis=1)
    out = np.abs(values[:, 0])
    for j in range(1, values.shape[1]):
        np.maximum(out, np.abs(values[:, j]), out=out)
    return out
