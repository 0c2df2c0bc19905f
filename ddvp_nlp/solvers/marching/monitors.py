"""The march's monitors (driver rule 5), each a `MarchMonitor`: made from the options by its
``from_options``, watching every accepted node, adding what it found to the `Solution` at the
end (``finish``; the protocol: ``session.py``).

The energy guard and the solvability monitor read per-node values the steppers computed with
each step (``Advance.values``): ``"H"``, the Hamiltonian ``H(z_k, t_k)``, and ``"w"``, the
site-density weight ``w = f' H_zz f = -8 c(z)`` (docs/theory.md section 7), so watching costs no
extra CasADi call.

- `EnergyGuard` ends the run (status ``ENERGY_GUARD``) at the first node with
  ``|H(z_k, t_k) - H_0| > energy_guard * max(|H_0|, E)``; that node and the ones after it are
  dropped.
- `SolvabilityMonitor` (energy rules) only warns: a positive step needs ``c`` to keep its
  sign and the step to be short against the change of ``w``, so it warns once, at the first node
  where ``w`` changes sign or ``|ln(w_k / w_{k-1})|`` exceeds ``MONITOR_LIMIT``.
- `EarlyVerdict` ends a march whose first steps plainly do not follow the motion (status
  ``INACCURATE``), instead of marching on to a verdict made at the end.
- `Events` (``Output.events``, ``dense.py``) locates the events and ends the run at a terminal
  one; `StopRequest` ends it when asked; `Checkpoint` saves the nodes so far.
"""

from __future__ import annotations

import inspect
import math
import os
import time
import warnings

import numpy as np

from ...solution import Status
from ..accuracy.judgement import ADVICE, Judgement, motion_scales, screened_errors, table_extremes
from ..compiler import buffered
from ..dense import DenseField, EventMonitor

# The solvability monitor warns once |ln(w_k / w_{k-1})| passes this. Measured on kepler
# (tau0 = 0.01): at most 0.36 per step for e = 0.7 (which runs), 0.6-0.9 in the 3-4 steps before
# the breakdown at e = 0.78 and 0.8; rotating pendulum (p0 = 2): 0.74 two steps before.
MONITOR_LIMIT = 0.5


class MarchMonitor:
    """What a monitor of a march session is (``session.py``): made by `from_options` from
    the session (``None``: the options do not ask for it), watching every accepted node
    (``watch``, driver rule 5), told when the loop is over (`close`) and adding what it found
    to the `Solution` (`finish`). ``rewatch``: whether it also watches the earlier nodes of a
    continued march (``resume.py``), to rebuild its state."""

    rewatch = True

    @classmethod
    def from_options(cls, session) -> MarchMonitor | None:
        """The monitor ``session``'s options ask for, or ``None``."""
        raise NotImplementedError

    def watch(self, nodes, first, advance):
        return None

    def close(self) -> None:
        """The loop has ended (or raised)."""

    def finish(self, solution, outcome) -> None:
        """What the monitor adds to ``solution`` (``outcome``: how the drive ended)."""


# The early verdict: the first EARLY_STEPS steps are judged as they come (once EARLY_NODES nodes
# give the motion's scales), and a step whose local error passes EARLY_FACTOR times the bound
# ends the run. The final check judges every node against the whole run's scales, which only
# grow; a factor of ten keeps a run the final check would pass from being cut (a stiff-soft
# pair with its stiff mode under-resolved, frequency x tau0 = 10: 46 times the bound at step 0,
# where the march had gone on for 57 s to be judged inaccurate from step 0 at the end).
EARLY_NODES = 64
EARLY_STEPS = 4096
EARLY_FACTOR = 10.0


class EarlyVerdict(MarchMonitor):
    """Ends the march at the first of its first ``EARLY_STEPS`` steps whose local error against
    the exact flow passes ``EARLY_FACTOR`` times the accuracy check's bound, with the scales of
    the nodes so far (``judge``: the run's `Judgement`; ``screen``: a second-order scheme's
    steps go through the RK4 screen first). The nodes up to that step's end are kept."""

    def __init__(self, judge, *, screen: bool):
        self.judge, self.screen = judge, screen
        self.checked = 0  # the steps judged so far
        # (rows, low, high) of the nodes' columns seen so far: the nodes before a watch's first
        # new one never change (a truncation ends the run), so each watch reads only the new
        # rows (min and max are exact: the same numbers as a pass over all of them)
        self._seen = None

    @classmethod
    def from_options(cls, session):
        """With an accuracy check that may stop the march (``Tolerance.stop``)."""
        accuracy, problem = session.accuracy, session.problem
        if accuracy is None or not accuracy.stop:
            return None
        return cls(Judgement(problem.system, problem.theta, accuracy, compiler=session.judging,
                             cache_dir=session.compilation.cache_dir), screen=True)

    def watch(self, nodes, first, advance):
        count = nodes.count
        if self.checked >= EARLY_STEPS or not advance.count or count - 1 < EARLY_NODES or \
                nodes.dropped:  # a thinned march drops rows only past EARLY_STEPS
            return None
        start, end = self.checked, min(count - 1, EARLY_STEPS)
        z = nodes.z[:count]
        scale = motion_scales(*self._extremes(z), z.shape[1] // 2)
        t, z = nodes.t[start:end + 1], z[start:end + 1]
        # the steps alone: no node values at the window's last node
        look = self.judge.values.first_look(t, z, last=False) if self.screen else None
        _, _, steps, relative, ratio = screened_errors(self.judge, t, z, scale, look)
        self.checked = end
        over = np.flatnonzero(~(ratio <= EARLY_FACTOR))
        if not over.size:
            return None
        j = int(over[0])
        i = int(steps[j])
        k = start + i
        rtol = self.judge.tolerance.rtol
        return Status.INACCURATE, (
            f"the local error of step {k} (from t = {t[i]:.10g}) is {relative[j]:.3e} of the "
            f"motion's size so far, more than {EARLY_FACTOR:g} times the bound {rtol:g}: the "
            f"march stopped there; {ADVICE}"), \
            max(0, k + 2 - first)

    def _extremes(self, z):
        """`table_extremes` of the nodes ``z`` (rows), the rows seen by the watches before
        not read again (``np.minimum``/``np.maximum`` carry a NaN on, as a pass over all)."""
        seen = self._seen
        if seen is None or not 0 < seen[0] <= z.shape[0]:
            low, high, _ = table_extremes(self.judge, z)
        elif seen[0] == z.shape[0]:
            low, high = seen[1], seen[2]
        else:
            new_low, new_high, _ = table_extremes(self.judge, z[seen[0]:])
            low, high = np.minimum(seen[1], new_low), np.maximum(seen[2], new_high)
        self._seen = (z.shape[0], low, high)
        return low, high, np.maximum(np.abs(low), np.abs(high))


class EnergyGuard(MarchMonitor):
    """Ends the run at the first node whose ``H`` leaves ``H0 +- guard * max(|H0|, E)``, ``E``
    the motion's energy scale from the start (``acceptance.start_values``: how much ``H``
    changes when the state moves by its own size), not a floor of 1: the same motion in other
    units stops at the same node."""

    def __init__(self, guard: float, H0: float, energy_scale: float = 0.0):
        self.H0 = H0
        self.limit = guard * max(abs(H0), energy_scale)

    @classmethod
    def from_options(cls, session):
        """With ``StepControl.energy_guard``."""
        guard = session.problem.steps.energy_guard
        return None if guard is None else cls(guard, session.problem.H0,
                                              session.problem.acceptance.H_motion)

    def watch(self, nodes, first, advance):
        if not advance.count:  # a failed step brings no node
            return None
        H = advance.values["H"]
        over = np.flatnonzero(np.abs(H - self.H0) > self.limit)
        if not over.size:
            return None
        i = int(over[0])
        return Status.ENERGY_GUARD, (
            f"at t = {nodes.t[first + i]:.10g} |H - H0| = {abs(H[i] - self.H0):.3e} > "
            f"energy_guard * max(|H0|, E) = {self.limit:.3e}"), i


class SolvabilityMonitor(MarchMonitor):
    """Keeps ``w`` at every node and warns (``RuntimeWarning``) at the first alarming node.

    ``warning`` is ``None`` or ``{"step", "t", "c", "reason"}``; `solvability` gives
    ``c(z_k) = -w_k / 8`` at the kept nodes. The warning points at the first caller outside
    this folder (the code that called the march)."""

    def __init__(self, t0: float, w0: float, selector=None):
        self._weights: list[np.ndarray] = []  # blocks of w, in order (no per-node floats)
        self._count = 0
        self._last = math.nan
        self.warning: dict | None = None
        # a thinned march (`thinning.py`): only the kept nodes' w, and the newest two blocks
        self.selector = selector
        self._recent: list = []  # (first node, w) of the newest blocks
        self._observe(np.array([w0]), np.array([t0]))

    @classmethod
    def from_options(cls, session):
        """For the energy rules, from the weight at node 0 (a thinned march's: only at the
        kept nodes)."""
        problem, functions = session.problem, session.parts.functions
        if not problem.scheme.variable_steps:
            return None
        monitor = buffered(functions.node_monitor, "node_monitor", owner=functions)
        t0 = np.float64(problem.t0)
        _, w_first = monitor(problem.z0, t0, problem.theta)
        return cls(float(t0), float(w_first[0, 0]), session.thinning)

    def finish(self, solution, outcome):
        """``Solution.solvability`` at the kept nodes and ``march.solvability_warning``."""
        solution.solvability = self.solvability(outcome.marched)
        solution.march.solvability_warning = self.warning

    @property
    def weights(self) -> list[float]:
        """``w`` at every node watched so far."""
        return np.concatenate(self._weights).tolist() if self._weights else []

    def watch(self, nodes, first, advance):
        if not advance.count:  # a failed step brings no node
            return None
        w = advance.values["w"]
        self._observe(w, nodes.t[first:first + w.size])
        return None

    def solvability(self, count: int) -> np.ndarray:
        """``c`` at the first ``count`` nodes; in a thinned march at the kept ones among them
        and at node ``count - 1``, the last."""
        weights = np.concatenate(self._weights) if self._weights else np.zeros(0)
        if self.selector is None:
            return -weights[:count] / 8
        kept = self.selector.selected(0, count - 1)
        last = [w[count - 1 - first] for first, w in self._recent
                if first <= count - 1 < first + w.size]
        return -np.concatenate([weights[:kept.size], last[:1]]) / 8

    def _keep(self, w):
        w = np.array(w, dtype=float)  # a copy: the stepper's arrays may be reused
        if self.selector is None:
            self._weights.append(w)
        else:
            rows = self.selector.selected(self._count, self._count + w.size) - self._count
            self._weights.append(w[rows])
            self._recent = [*self._recent[-1:], (self._count, w)]
        self._count += w.size
        self._last = float(w[-1])

    def _observe(self, w, t):
        if self.warning is not None or not w.size:
            if w.size:
                self._keep(w)
            return
        if w.size == 1 and self._count:  # one careful node: plain floats are cheaper
            last, now = self._last, float(w[0])
            if last * now > 0 and abs(math.log(now / last)) <= MONITOR_LIMIT:
                self._keep(w)
                return
        if self._count and w.size > 1 and _quiet(w, self._last):
            self._keep(w)
            return
        previous = np.concatenate([[self._last if self._count else w[0]], w[:-1]])
        with np.errstate(divide="ignore", invalid="ignore"):
            jump = np.abs(np.log(np.abs(w) / np.abs(previous)))
        sign = np.sign(w) != np.sign(previous)
        alarm = np.flatnonzero(sign | ~(jump <= MONITOR_LIMIT))
        if alarm.size:
            i = int(alarm[0])
            if w[i] == 0 or previous[i] == 0:
                reason = ("the site-density weight w = -8 c(z) is zero: the energy rule does "
                          "not fix the step here (the motion is at rest, or f' H_zz f vanishes)")
            elif sign[i]:
                reason = "the site-density weight w = -8 c(z) changed sign"
            else:
                reason = (f"|ln(w_k / w_k-1)| = {jump[i]:.3g} > {MONITOR_LIMIT}: the step is "
                          "long against the change of c(z)")
            self.warning = {"step": self._count + i, "t": float(t[i]),
                            "c": float(-w[i] / 8), "reason": reason}
            warnings.warn(f"solvability monitor at step {self.warning['step']}, t = "
                          f"{self.warning['t']:.10g}: {reason}; a breakdown of the energy step "
                          "may follow", RuntimeWarning, stacklevel=_caller_level())
        self._keep(w)


# Ratios w_k / w_{k-1} strictly inside these pass the test above for certain: a margin of 1e-9
# against the few units of round-off of a logarithm near MONITOR_LIMIT.
_QUIET = (math.exp(-MONITOR_LIMIT) * (1 + 1e-9), math.exp(MONITOR_LIMIT) * (1 - 1e-9))


def _quiet(w: np.ndarray, last: float) -> bool:
    """Whether no node of ``w`` (after ``last``) can alarm the solvability monitor: every ratio
    ``w_k / w_{k-1}`` positive (same sign, no zero, no NaN) and well inside ``MONITOR_LIMIT``.
    A division and two reductions, against the logarithms, signs and comparisons of the full
    test (which still decides every block this does not clear, so the warning is the same)."""
    low, high = _QUIET
    if not last or not low < float(w[0]) / last < high:
        return False
    with np.errstate(all="ignore"):  # a zero or an overflow only fails the test
        ratio = w[1:] / w[:-1]
    return bool(low < ratio.min() and ratio.max() < high)


_HERE = os.path.dirname(os.path.abspath(__file__)) + os.sep


def _caller_level() -> int:
    """``stacklevel`` of the first frame outside this folder, seen from the caller."""
    frame, level = inspect.currentframe().f_back, 1
    while frame is not None and frame.f_code.co_filename.startswith(_HERE):
        frame, level = frame.f_back, level + 1
    return level


class Checkpoint(MarchMonitor):
    """Never ends the run: hands the nodes kept so far to ``save(t, z)`` so that they land
    about every ``interval`` seconds of stepping (at ``interval``, ``2 interval``, ... after the
    start; a killed march loses at most one interval).

    The save runs on a thread of its own while the march goes on: it gets views of the nodes
    ``[0, count)``, which the march never writes again (new nodes go after them; a grown array
    is a new one, the thread keeps the old). It starts early by the time the last save took,
    scaled to the node count, so that it lands on time (saves had run in the loop and a 5%
    budget had pushed the next one back: every 5 s landed at 5.9 and 17.9 s of a 26.6 s run).
    ``landed`` records when each save landed (seconds since the start), ``seconds`` their
    total cost, ``saves`` their number. A save that raises ``OSError`` stops the checkpoints
    with one warning (the final write then says what cannot be written)."""

    # Until a save has been timed: seconds per byte written (a disk of about 100 MB/s with
    # its fsync and the checksum).
    FIRST_GUESS_S_PER_BYTE = 1e-8
    rewatch = False  # a continued march's earlier nodes are saved with its first checkpoint

    def __init__(self, save, interval: float, clock=time.perf_counter, state=None):
        self.save = save
        self.state = state  # a snapshot taken with the nodes, passed to save as a third argument
        self.interval = interval
        self.clock = clock  # seconds; a test's own clock
        self.started = clock()
        self.target = interval  # when the next save should land, seconds since the start
        self.seconds_per_byte = self.FIRST_GUESS_S_PER_BYTE
        self.seconds = 0.0
        self.saves = 0
        self.landed: list[float] = []
        self.thread = None
        self.failure = None

    @classmethod
    def from_options(cls, session):
        """With ``Output.checkpoint``: the save gets the carried state (``session.carry``)
        where it takes it."""
        output = session.output
        if output.checkpoint is None:
            return None
        save, state = with_state(output.checkpoint, session.carry)
        return cls(save, output.checkpoint_interval, state=state)

    def watch(self, nodes, first, advance):
        if self.save is None or (self.thread is not None and self.thread.is_alive()):
            return None
        self._report_failure()
        if self.save is None:
            return None
        count = nodes.count
        cost = self.seconds_per_byte * count * (nodes.z.shape[1] + 1) * 8
        if self.clock() - self.started + cost < self.target:
            return None
        import threading

        t, z = nodes.t[:count], nodes.z[:count]  # views: rows below count never change
        extra = (self.state(),) if self.state is not None else ()
        self.thread = threading.Thread(target=self._write, args=(t, z, *extra), daemon=True,
                                       name="ddvp-checkpoint")
        self.thread.start()
        return None

    def _write(self, t, z, *state):
        began = self.clock()
        try:
            self.save(t, z, *state)
        except Exception as exc:  # noqa: BLE001 - reported from the march's own thread
            self.failure = exc
            return
        now = self.clock()
        spent = now - began
        self.seconds += spent
        self.saves += 1
        # a tenth more than measured: a save slowed by the disk or the other core lands early
        # by a little rather than late
        self.seconds_per_byte = 1.1 * spent / max(1, t.size * (z.shape[1] + 1) * 8)
        landed = now - self.started
        self.landed.append(landed)
        # the next multiple of the interval after this one and after now
        self.target = max(self.target + self.interval,
                          (math.floor(landed / self.interval) + 1) * self.interval)

    def _report_failure(self):
        if self.failure is not None:
            warnings.warn(f"checkpoints stopped: {self.failure}", RuntimeWarning, stacklevel=3)
            self.failure, self.save = None, None

    def close(self):
        """Wait for a save in flight (the final write must come after it), then report a
        failure."""
        if self.thread is not None:
            self.thread.join()
        self._report_failure()

    def finish(self, solution, outcome):
        """What the checkpoints cost (``timing["checkpoint_s"]``), how many there were and
        when each landed."""
        solution.timing["checkpoint_s"] = self.seconds
        solution.march.checkpoints = self.saves
        solution.march.checkpoints_landed_s = [round(t, 3) for t in self.landed]


def with_state(save, carry):
    """``(save, state)`` for the `Checkpoint`: the user's ``save`` called with the carried
    state (``carry``: the `CarryTracker`, ``resume.py``) as a third argument where it takes one
    (``save(t, z, carried)``), else ``save(t, z)``; ``state`` snapshots it."""
    try:
        takes = len(inspect.signature(save).parameters) >= 3
    except (TypeError, ValueError):
        takes = False
    return (lambda t, z, state: save(t, z, state)) if takes else (
        lambda t, z, state: save(t, z)), carry.state


class StopRequest(MarchMonitor):
    """Ends the run (status ``INTERRUPTED``, every new node kept) once ``stop()`` is true: an
    interrupt noted by a signal handler, acted on between two stepper calls."""

    rewatch = False  # a stop asked for before the loop is the driver's (``drive(stop=...)``)

    def __init__(self, stop):
        self.stop = stop

    @classmethod
    def from_options(cls, session):
        """With ``Output.stop``."""
        return cls(session.output.stop) if session.output.stop else None

    def watch(self, nodes, first, advance):
        if self.stop():
            return Status.INTERRUPTED, "", advance.count
        return None


class Events(EventMonitor, MarchMonitor):
    """The events of ``Output.events`` (`EventMonitor`, ``dense.py``): located as the march
    goes, a terminal one ends it; their times and states go on the solution."""

    @classmethod
    def from_options(cls, session):
        """With ``Output.events``, from the start's values of ``g``."""
        output, problem = session.output, session.problem
        if not output.events:
            return None
        return cls(output.events, DenseField.of(problem.system, problem.theta), problem.t_end,
                   np.float64(problem.t0), problem.z0)

    def finish(self, solution, outcome):
        """``Solution.t_events`` and ``z_events``."""
        self.report(solution)
