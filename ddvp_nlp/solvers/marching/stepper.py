"""The march's steppers for the one-step-loop driver (``driver.py``).

- `CarefulStepper`: one step per call with CasADi's ``newton`` (``newton.py``). Step 0 of
  the energy rules and every step of the ``fixed`` rule is a fixed-length step on the times of
  the `Clock`; every other step is an energy step, then the step bounds; where an energy
  step fails with a status in ``LEAST_SQUARES_CASES`` and ``breakdown == "least_squares"``, the
  least-squares step (``least_squares.py``) replaces it.
- `CompiledStepper`: a batch of up to ``MAX_CALLS`` chained compiled chunk calls per call
  (``chunk.py``), kept up to the first step that fails the same
  `Acceptance`: the nodes one call per chunk would
  give, with the Python work of decoding, checking and watching (the driver's monitors) paid
  once per batch.
- `MarchStepper`: the composite. It runs compiled chunks; after a chunk step fails a
  check, the careful path redoes the rest of that chunk's window (``careful_left`` steps), then
  the chunks resume. So every step passes the same acceptance test, whichever path took it.

`Tally` holds what the steppers carry from step to step: the compensated energy drift and
the counts the ``Solution`` reports.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...solution import Status
from ..driver import Advance, Nodes, describe_phase_space
from .acceptance import Acceptance
from .chunk import FastChunk
from .least_squares import least_squares_step
from .step_newton import NewtonSteps, StepResult

# Chunk calls per batch of the compiled stepper (the default of Compilation.batch): 1, 2, 4, ...
# up to this while every step is
# kept (one after a failed step), fewer near the end of the run. Eight chunks of 1024 steps cut
# the decoding and checks per step about eightfold; a batch holds a few MB (2 MB for n = 2).
# The driver asks for a stop (Ctrl-C, time limit) between batches: every few milliseconds.
MAX_CALLS = 8
LEAST_SQUARES_CASES = (Status.NO_ADMISSIBLE_STEP, Status.NEWTON_FAILED,
                       Status.RESIDUAL_TOO_LARGE, Status.STEP_BELOW_MIN, Status.STEP_ABOVE_MAX,
                       Status.STEP_RATIO)


@dataclass
class Tally:
    """``drift``: the sum of the energy residuals accepted so far (each energy step solves for
    ``residual_k = -drift``); the counts of fast and careful steps; one record per least-squares
    step."""

    drift: float = 0.0
    fast_steps: int = 0
    careful_steps: int = 0
    least_squares: list = field(default_factory=list)
    fallbacks: int = 0  # compiled steps refused, each handing its chunk's window to the careful
    first_fallback: dict | None = None  # where the first was refused, and why


@dataclass(frozen=True)
class Clock:
    """The node times a rule fixes in advance: ``t_k = t0 + k tau``, and ``t_total = t_end``.

    Fixed rule: ``total = ceil((t_end - t0) / tau0)`` uniform steps of
    ``tau = (t_end - t0) / total``. Energy rules: only ``t_1 = t0 + tau0`` (``total`` is
    ``None``)."""

    t0: float
    t_end: float
    tau: float
    total: int | None = None

    @classmethod
    def for_rule(cls, variable_steps: bool, t0: float, t_end: float, tau0: float) -> Clock:
        if variable_steps:
            return cls(t0, t_end, tau0)
        total = max(1, math.ceil((t_end - t0) / tau0 - 1e-9))
        return cls(t0, t_end, (t_end - t0) / total, total)

    def time(self, k: int) -> float:
        return self.t_end if k == self.total else self.t0 + k * self.tau


class CarefulStepper:
    """One careful step per call (a driver ``Stepper``)."""

    def __init__(self, steps: NewtonSteps, clock: Clock, tally: Tally, *, variable: bool,
                 breakdown: str):
        self.steps = steps
        self.clock = clock
        self.tally = tally
        self.variable = variable
        self.least_squares = breakdown == "least_squares"

    describe = staticmethod(describe_phase_space)

    def advance(self, nodes: Nodes, budget: int) -> Advance:
        k = nodes.count - 1  # its row; nodes.last its index in the run (driver rule 7)
        t, z = nodes.t, nodes.z
        self.tally.careful_steps += 1
        if nodes.last == 0 or not self.variable:
            result = self.steps.fixed_step(t[k], self.clock.time(nodes.last + 1), z[k])
        else:
            result = self._energy_step(t, z, k)
        if result.status is not Status.SUCCESS:
            return Advance.failed(result.status, result.detail, nodes.width)
        return Advance(np.array([result.t_next]), result.z_next[None, :],
                       values={"H": np.array([result.H_node]), "w": np.array([result.w_node]),
                               "carry": np.array([[self.tally.drift, 0.0, 0.0]])})

    def _energy_step(self, t, z, k) -> StepResult:
        result = self.steps.energy_step(t[k - 1], t[k], z[k - 1], z[k], self.tally.drift)
        if result.status is Status.SUCCESS:
            # The residual joins the drift before the bounds are checked, so a least-squares
            # step after a broken bound aims at the level that includes it (kept as it was).
            self.tally.drift += result.energy
            status, detail = self.steps.acceptance.broken_bound(result.tau, t[k] - t[k - 1])
            if status is not Status.SUCCESS:
                result = StepResult.failed(status, detail)
        if result.status in LEAST_SQUARES_CASES and self.least_squares:
            result, record = least_squares_step(self.steps, t[k - 1], t[k], z[k - 1], z[k],
                                                self.tally.drift, result, k)
            if record is not None:
                self.tally.least_squares.append(record)
        return result


class CompiledStepper:
    """A batch of compiled chunk calls per call, kept up to its first step that fails a
    check."""

    def __init__(self, chunk: FastChunk, theta: np.ndarray, acceptance: Acceptance,
                 clock: Clock, tally: Tally, *, max_calls: int = MAX_CALLS):
        self.chunk = chunk
        self.max_calls = max_calls
        self.theta = theta
        self.acceptance = acceptance
        self.clock = clock
        self.tally = tally
        self.calls = 1  # chunk calls of the next batch
        # steps since the last chunk boundary when a batch starts: 0 but in a resumed march,
        # whose first batch starts where the uninterrupted run was inside a chunk
        self.offset = 0
        self._handed = (0, 0)  # (first node index, count) of the last batch handed out
        self._packed = None  # the chunk's parameters

    def settle(self, count: int) -> None:
        """Count in ``tally.fast_steps`` only the nodes of the last batch that the run kept
        (``count`` nodes in all at its end: the driver's monitors may have cut that batch; a
        cut always ends the run, so only the last batch can have been cut)."""
        first, handed = self._handed
        self.tally.fast_steps -= handed - min(handed, max(0, count - first))
        self._handed = (0, 0)

    def inputs(self, nodes: Nodes) -> tuple[np.ndarray, np.ndarray]:
        """The chunk's state from the newest nodes and its parameters."""
        k = nodes.count - 1
        if self.chunk.variable:
            t, z = nodes.t, nodes.z
            return (self.chunk.energy_state(t[k - 1], t[k], z[k - 1], z[k], self.tally.drift),
                    self._parameters())
        return self.chunk.fixed_state(nodes.last, nodes.z[k]), self._parameters()

    def _parameters(self) -> np.ndarray:
        """The chunk's parameters, the same for the whole run: packed once."""
        if self._packed is None:
            clock = self.clock
            self._packed = (
                self.chunk.energy_parameters(self.theta, self.acceptance) if self.chunk.variable
                else self.chunk.fixed_parameters(self.theta, self.acceptance, t0=clock.t0,
                                                 tau=clock.tau, t_end=clock.t_end,
                                                 total=clock.total))
        return self._packed

    def run(self, nodes: Nodes, budget: int) -> tuple[Advance, int | None]:
        """The steps of one batch of chained chunk calls, kept up to the first that fails a
        check, the end or ``budget``, and, where a step failed, how many steps of its chunk
        came before it (``None`` where none failed)."""
        k = nodes.last
        steps = self.chunk.steps(*self.inputs(nodes), self._calls(nodes, budget))
        if self.chunk.variable:
            good, ends = self._energy_checks(nodes, k, steps)
        else:
            good, ends = self._fixed_checks(k, steps)
        limit = min(steps.t_next.size, budget)
        if ends.size:  # steps after the end are not counted, failures included
            limit = min(limit, int(ends[0]) + 1)
        bad = np.flatnonzero(~good[:limit])
        kept = int(bad[0]) if bad.size else limit
        if bad.size:
            self._refused(nodes, steps, kept)
        self.calls = 1 if bad.size else min(2 * self.calls, self.max_calls)
        values = {"H": steps.H_node[:kept], "w": steps.w_node[:kept],
                  "carry": self._carry(steps, kept)}
        if kept and self.chunk.variable:
            self.tally.drift = float(steps.drift[kept - 1])
        self.tally.fast_steps += kept
        self._handed = (nodes.last + 1, kept)
        advance = Advance(steps.t_next[:kept], steps.z_next[:kept], values=values)
        before = (self.offset + kept) % self.chunk.chunk if bad.size else None
        if bad.size:  # the careful path ends the window; the next chunks start a new one
            self.offset = 0
        return advance, before

    def _refused(self, nodes: Nodes, steps, i: int) -> None:
        """Count a compiled step refused by its check; say where and why for the first."""
        self.tally.fallbacks += 1
        if self.tally.first_fallback is not None:
            return
        t = float(steps.t_next[i - 1]) if i else float(nodes.t[nodes.count - 1])
        canonical, size = float(steps.canonical[i]), float(steps.size[i])
        energy = float(steps.energy[i]) if self.chunk.variable else 0.0
        tau = float(steps.t_next[i]) - t
        if not (np.isfinite(canonical) and np.isfinite(energy) and np.isfinite(tau)):
            why = "its Newton returned non-finite values"
        elif self.chunk.variable and not tau > 0:
            why = f"its Newton found a non-positive step ({tau:.3g})"
        else:
            why = (f"its Newton did not converge from the predictor (canonical residual "
                   f"{canonical:.3g} at state size {size:.3g}, energy residual {energy:.3g})")
        self.tally.first_fallback = {"t": t, "why": why}

    def _carry(self, steps, kept: int) -> np.ndarray:
        """Per kept step what a resumed march needs to go on as this one did (``resume.py``):
        the drift after it, no careful steps owed, its place in its chunk."""
        carry = np.zeros((kept, 3))
        carry[:, 0] = steps.drift[:kept] if self.chunk.variable else self.tally.drift
        carry[:, 2] = (self.offset + np.arange(1, kept + 1)) % self.chunk.chunk
        return carry

    def _calls(self, nodes: Nodes, budget: int) -> int:
        """Chunk calls of the next batch: ``self.calls``, fewer where the run ends sooner
        (``budget``; the steps left to ``total``, or to ``t_end`` at the mean step so far)."""
        k, newest = nodes.last, float(nodes.t[nodes.count - 1])
        left = budget
        if self.clock.total is not None:
            left = min(left, self.clock.total - k)
        elif k > 0 and newest > nodes.t_first:
            mean = (newest - nodes.t_first) / k
            ahead = (self.clock.t_end - newest) / mean
            if math.isfinite(ahead):  # a subnormal mean step overflows: no estimate then
                left = min(left, math.ceil(ahead) + 1)
        return max(1, min(self.calls, math.ceil(left / self.chunk.chunk)))

    def _energy_checks(self, nodes, k, steps):
        """Each step's verdict (the chunk's own, ``chunk.step_verdict``) and the steps that
        reach ``t_end``."""
        return steps.good, np.flatnonzero(steps.t_next >= self.clock.t_end)

    def _fixed_checks(self, k, steps):
        return steps.good, np.flatnonzero(k + 1 + np.arange(steps.t_next.size)
                                          == self.clock.total)


class MarchStepper:
    """Compiled chunks with the careful path as fallback (a driver ``Stepper``).

    The energy rules' step 0 is always careful (a chunk needs two nodes). When a chunk's step
    fails a check, the careful path takes the rest of that chunk's window from the last good
    node: it may pass (Newton's retries, the least-squares step) or end the run with the
    careful path's status and message."""

    def __init__(self, careful: CarefulStepper, compiled: CompiledStepper):
        self.careful = careful
        self.compiled = compiled
        self.careful_left = 0  # steps the careful path owes after a chunk step failed

    describe = staticmethod(describe_phase_space)

    def wants_chunk(self, nodes: Nodes) -> bool:
        """Whether the next call runs a compiled chunk (else one careful step)."""
        return self.careful_left == 0 and (not self.careful.variable or nodes.last > 0)

    def advance(self, nodes: Nodes, budget: int) -> Advance:
        if self.wants_chunk(nodes):
            advance, before = self.compiled.run(nodes, budget)
            if before is not None:  # the careful path takes the rest of that chunk's window
                self.careful_left = self.compiled.chunk.chunk - before
            if advance.count:
                return advance
        self.careful_left = max(self.careful_left - 1, 0)
        advance = self.careful.advance(nodes, budget)
        if advance.count:
            advance.values["carry"][0, 1] = self.careful_left
        return advance
