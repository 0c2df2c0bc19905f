"""One step loop for every integrator that marches: the driver and the contract of a stepper.

A *stepper* knows one scheme: how to take steps and whether a step is acceptable. The *driver*
(`drive`) owns everything else: the node arrays, the end, the bounds, the interrupt, the
monitors, the progress bar and the message. The contract, rule by rule:

1. ``stepper.advance(nodes, budget)`` takes steps from the newest node of ``nodes`` (a
   `Nodes`, read-only for the stepper) and returns an `Advance`: the new nodes ``t``
   ``(m,)`` and ``z`` ``(m, d)`` in order, each already accepted by the stepper's own acceptance
   test, with ``m <= budget`` (the steps left under ``max_steps``).
2. ``Advance.status`` is ``Status.SUCCESS`` while the stepper can go on; any other status ends the
   run, with ``Advance.detail`` saying why in words. The nodes returned with a failure are kept:
   they were accepted before the step that failed.
3. The run ends at the first node with ``t >= t_end``; the driver drops nodes after it. A stepper
   may therefore return a whole compiled chunk and leave the cut to the driver.
4. Before every call the driver checks ``max_steps`` (status ``MAX_STEPS``) and ``time_limit``
   (seconds since the loop started, status ``TIME_LIMIT``). With ``catch_interrupt`` a Ctrl-C
   during a call ends the run with status ``INTERRUPTED`` and keeps every accepted node;
   without it, it propagates (a grid of runs stops as a whole).
5. Monitors see every accepted node once, in order (``monitor.watch(nodes, first, advance)``,
   with the new nodes at ``first ..``). A monitor returns ``None`` to go on, or
   ``(status, detail, keep)``: the run ends with ``status`` and only the first ``keep`` new nodes
   stay; the monitors after it in ``monitors`` see only those (and may cut further).
6. The message of the result is written here and only here (`message`): on success
   ``"reached t_end = ... in N steps"``, on failure the status's own text, the step, the time and
   state of the last kept node (``stepper.describe(z)``), and the detail.

7. With a ``thinning`` (a march that keeps only some nodes, ``marching/thinning.py``), the
   driver hands it the nodes every monitor has seen once they pass ``thinning.window`` rows
   (``thinning.settle(nodes)``, which keeps what it wants of them and drops all but the newest
   rows from ``nodes``: ``nodes.dropped`` counts the rows gone, so a node's index in the run is
   ``nodes.dropped`` plus its row), and the rest at the end (``thinning.finish(nodes)``, which
   returns the kept nodes).

Steps are counted from ``step_offset`` (the index of the node the first step starts from: 0 for
a march from one node, more for schemes that start from several).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from ..solution import Status, bound_reached


@dataclass
class Advance:
    """What one call of a stepper produced: accepted nodes, then how it ended.

    ``values`` holds per-node quantities the stepper computed for the monitors (for example
    ``"H"`` and ``"w"``, each of shape ``(m,)``)."""

    t: np.ndarray
    z: np.ndarray
    status: Status = Status.SUCCESS
    detail: str = ""
    values: dict = field(default_factory=dict)

    @classmethod
    def failed(cls, status: Status, detail: str, width: int) -> Advance:
        """No new node, and ``status``."""
        return cls(np.zeros(0), np.zeros((0, width)), status, detail)

    @property
    def count(self) -> int:
        return int(self.t.size)

    def head(self, count: int) -> Advance:
        """The first ``count`` nodes (and values), same status."""
        return Advance(self.t[:count], self.z[:count], self.status, self.detail,
                       {k: v[:count] for k, v in self.values.items()})


class Stepper(Protocol):
    def advance(self, nodes: Nodes, budget: int) -> Advance: ...

    def describe(self, z: np.ndarray) -> str: ...


class Monitor(Protocol):
    def watch(self, nodes: Nodes, first: int, advance: Advance): ...


def describe_phase_space(z: np.ndarray) -> str:
    """``q = [...], p = [...]`` of a phase-space state ``z = (q, p)``."""
    n = z.size // 2
    return f"q = {z[:n]}, p = {z[n:]}"


class Nodes:
    """The accepted nodes, in arrays that grow by doubling: ``t[:count]``, ``z[:count]``; in a
    thinned march (rule 7) the newest of them, row ``r`` being node ``dropped + r`` of the run
    (``t_first``: the time of node 0)."""

    def __init__(self, t0, z0):
        t0 = np.atleast_1d(np.asarray(t0, dtype=float))
        z0 = np.asarray(z0, dtype=float).reshape(t0.size, -1)
        size = max(1024, 2 * t0.size)
        self.t = np.empty(size)
        self.z = np.empty((size, z0.shape[1]))
        self.t[:t0.size], self.z[:t0.size] = t0, z0
        self.count = t0.size
        self.dropped = 0
        self.t_first = float(t0[0])

    @property
    def last(self) -> int:
        """The index in the run of the newest node."""
        return self.dropped + self.count - 1

    def drop(self, rows: int) -> None:
        """Forget the first ``rows`` rows (rule 7); the rest move to the front."""
        rest = self.count - rows
        self.t[:rest] = self.t[rows:self.count].copy()
        self.z[:rest] = self.z[rows:self.count].copy()
        self.count, self.dropped = rest, self.dropped + rows

    @property
    def width(self) -> int:
        return self.z.shape[1]

    def extend(self, t, z):
        extra = np.size(t)
        end = self.count + extra
        if end > self.t.size:
            # new arrays with the kept rows copied (np.resize also filled the rest by repeating
            # them: twice the copying)
            size = max(2 * self.t.size, end)
            t_new, z_new = np.empty(size), np.empty((size, self.z.shape[1]))
            t_new[:self.count], z_new[:self.count] = self.t[:self.count], self.z[:self.count]
            self.t, self.z = t_new, z_new
        self.t[self.count:end] = t
        self.z[self.count:end] = z
        self.count = end

    def truncate(self, count: int):
        self.count = count

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the kept nodes."""
        return self.t[:self.count].copy(), self.z[:self.count].copy()


@dataclass
class Outcome:
    """How a driven run ended: the kept nodes, the status and the message."""

    t: np.ndarray
    z: np.ndarray
    status: Status
    message: str
    marched: int = -1  # nodes of the run, kept or not (-1: t.size)

    def __post_init__(self):
        if self.marched < 0:
            self.marched = int(self.t.size)


def message(status: Status, *, steps: int, t_end: float, t: float, state: str,
            detail: str = "") -> str:
    """The one place a status becomes a sentence (rule 6)."""
    if status is Status.SUCCESS:
        return f"reached t_end = {t_end:.12g} in {steps} steps"
    return (f"{status.value}: step {steps} from t = {t:.10g}, {state}"
            + (f"; {detail}" if detail else ""))


def drive(stepper: Stepper, nodes: Nodes, *, t_end: float, max_steps: int,
          time_limit: float | None = None, monitors=(), progress: bool = False,
          catch_interrupt: bool = False, step_offset: int = 0, stop=None,
          thinning=None) -> Outcome:
    """Run ``stepper`` from the newest node of ``nodes`` until one of rules 2-5 ends it.
    ``stop()``, if given, is asked once before the first call (a stop requested while the
    march was built ends it at once, status ``INTERRUPTED``); after that a ``StopRequest``
    monitor asks it after every call."""
    started = time.perf_counter()
    bar = _ProgressBar(progress, float(nodes.t[nodes.count - 1]), t_end)
    status, detail = Status.SUCCESS, ""
    watched = nodes.count  # the nodes every monitor has seen
    try:
        if stop is not None and stop():
            status = Status.INTERRUPTED
        while status is Status.SUCCESS and nodes.t[nodes.count - 1] < t_end:
            steps = nodes.last - step_offset
            reached = bound_reached(steps, max_steps, started, time_limit)
            if reached:
                status, detail = reached
                break
            advance = stepper.advance(nodes, max_steps - steps)
            status, detail = accept(nodes, advance, t_end, monitors)
            if thinning is not None and nodes.count > thinning.window:
                thinning.settle(nodes)
            watched = nodes.count
            bar.update(float(nodes.t[nodes.count - 1]))
            if status is not Status.SUCCESS:
                break
    except KeyboardInterrupt:
        if not catch_interrupt:
            raise
        # an interrupt inside accept: nodes added but not yet seen by every monitor go
        nodes.truncate(watched)
        status, detail = Status.INTERRUPTED, ""
    finally:
        bar.close()
    marched = nodes.last + 1
    t, z = nodes.arrays() if thinning is None else thinning.finish(nodes)
    # the state is printed only in a failure's sentence (numpy's array printing cost 0.6 ms of
    # a 2.9 ms short march)
    text = message(status, steps=marched - 1, t_end=t_end, t=float(t[-1]),
                   state="" if status is Status.SUCCESS else stepper.describe(z[-1]),
                   detail=detail)
    return Outcome(t, z, status, text, marched)


def accept(nodes: Nodes, advance: Advance, t_end: float, monitors) -> tuple[Status, str]:
    """Rules 2, 3 and 5 on one stepper call: cut at the end, keep, let the monitors look."""
    if advance.count and advance.t[-1] >= t_end:  # the nodes are in order (rule 1)
        # what the stepper did after the end does not count, failures included
        advance = advance.head(int(np.flatnonzero(advance.t >= t_end)[0]) + 1)
        advance.status, advance.detail = Status.SUCCESS, ""
    first = nodes.count
    nodes.extend(advance.t, advance.z)
    status, detail = advance.status, advance.detail
    for monitor in monitors:
        verdict = monitor.watch(nodes, first, advance)
        if verdict is not None:
            status, detail, keep = verdict
            nodes.truncate(first + keep)
            advance = advance.head(keep)
    return status, detail


class _ProgressBar:
    """Progress over ``[t0, t_end]`` (``ddvp_nlp/progress.py``: a bar on a terminal, plain
    lines elsewhere), updated with the newest node time (a no-op when off)."""

    def __init__(self, enabled: bool, t0: float, t_end: float):
        from ..progress import progress

        self.reported = t0
        self.t_end = t_end
        self.bar = progress(t_end - t0, unit="t", label="march", enabled=enabled)

    def update(self, t: float):
        if math.isfinite(t):
            now = min(t, self.t_end)
            self.bar.update(now - self.reported)
            self.reported = now

    def close(self):
        self.bar.close()
