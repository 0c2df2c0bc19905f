"""A reference solution that states its own error: two adaptive runs, at ``rtol`` and at
``rtol / FACTOR``; the finer one is the reference, and the difference of the two, as an
envelope over time, bounds its error.

Why this bound (measured while building it): DOP853's global error is close to
proportional to its tolerance, so the coarse run's error is about ``FACTOR`` times the fine
one's and ``|coarse - fine|`` is about the coarse run's error. On Kepler e = 0.6 and 0.9,
Henon-Heiles' chaotic orbit, the pendulum at H = 1.999 and the paper's pendulum to t = 10^4,
at rtol 1e-8 .. 1e-12, the fine run's true error (max over components, in units of S) was at
most 0.36 of ``max_t |coarse - fine|`` over the run, and pointwise at most 1.32 times
``max(running max |coarse - fine|, rtol_fine)``; the claim below doubles that envelope. With it,
true error / claim <= 0.66 at every time of every case, and the claim is 6 .. 49 times the
largest true error.

Cost: the fine run takes ``FACTOR^(1/8) = 1.33`` times the coarse run's steps: 2.3 runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..columns import row_max_ratio
from .flow import AdaptiveFlow
from .trajectory import Trajectory

FACTOR = 10.0
SAFETY = 2.0
FLOOR_RTOL = 1e-13  # below this DOP853 meets round-off: no finer reference is tried
SAMPLES = 4  # points a fine step where the claim's envelope is sampled
FIRST_SLOTS = 64  # attempts a call of the flow of a `GrowingReference`'s first piece


@dataclass
class Reference:
    fine: Trajectory
    coarse: Trajectory
    rtol: float  # the fine run's
    floor: float = 0.0  # the running maximum before t0 (a window of a `GrowingReference`)
    end_envelope: float = 0.0  # the running maximum at the last time `at` was asked for

    def states(self, times) -> np.ndarray:
        return self.fine.z(times)

    def error(self, times, scale) -> np.ndarray:
        """The claimed bound of the reference's error at ``times`` (increasing from ``t0``, or
        decreasing for a backward run), ``max_i |err_i| / scale_i``:
        ``SAFETY * max(running max of max_i |coarse - fine|_i / scale_i, rtol)``.

        The running max is taken over ``SAMPLES`` points in every step of the fine run (its
        cost follows the motion, not the number of times asked for), read at each time as
        its value at the first sample at or after it; where fewer times than samples are
        asked for, at the times themselves."""
        return self.at(times, scale)[1]

    def at(self, times, scale) -> tuple[np.ndarray, np.ndarray]:
        """The states at ``times`` and their claimed error (`error`), the fine run read once;
        `end_envelope` is then the running maximum at the last of them."""
        times = np.asarray(times, float)
        scale = np.asarray(scale, float)
        forward = self.fine.t_end >= self.fine.t0
        states = self.fine.z(times)
        kernel = self.fine.kernel  # the compiled envelope (``kernel.py``, the same numbers)
        if kernel is not None and not (kernel.run_readable(self.fine) and
                                       kernel.run_readable(self.coarse)):
            kernel = None
        with np.errstate(invalid="ignore"):  # NaN (a run that failed) stays NaN: lost
            if times.size <= SAMPLES * self.fine.steps or not self.fine.steps:
                if kernel is not None:
                    running = kernel.claim_envelope(self.fine, self.coarse, times, scale,
                                                    self.floor)
                else:
                    difference = row_max_ratio(np.abs(self.coarse.z(times) - states), scale)
                    running = np.maximum.accumulate(np.maximum(difference, self.floor))
                claim = SAFETY * np.maximum(running, self.rtol)
            else:
                samples = self._samples()
                if kernel is not None:
                    running = kernel.claim_envelope(self.fine, self.coarse, samples, scale,
                                                    self.floor)
                else:
                    difference = row_max_ratio(np.abs(self.coarse.z(samples) -
                                                      self.fine.z(samples)), scale)
                    running = np.maximum.accumulate(np.maximum(difference, self.floor))
                if kernel is not None:
                    claim = kernel.claim_at(times, forward, samples, running, SAFETY,
                                            self.rtol)
                else:
                    keys = samples if forward else -samples
                    index = np.searchsorted(keys, times if forward else -times, side="left")
                    np.clip(index, 0, samples.size - 1, out=index)
                    claim = SAFETY * np.maximum(np.take(running, index), self.rtol)
        self.end_envelope = float(running[-1]) if running.size else self.floor
        # past where either run stopped (a failed run): no claim
        reached = min(self.fine.t_reached, self.coarse.t_reached) if forward else \
            max(self.fine.t_reached, self.coarse.t_reached)
        claim[(times > reached) if forward else (times < reached)] = np.inf
        return states, claim

    def _samples(self) -> np.ndarray:
        fractions = np.arange(SAMPLES) / SAMPLES
        return np.append((self.fine.t_old[:, None] + self.fine.h[:, None] * fractions)
                         .ravel(), self.fine.t_reached)


def reference(flow: AdaptiveFlow, z0, t0, t_end, theta, scale, *,
              rtol: float = 1e-10) -> Reference:
    """The pair of runs (module docstring), ``atol = rtol * scale`` per component (``scale``:
    the motion's size; no floor of 1, so a change of units changes nothing)."""
    z0 = np.asarray(z0, float)
    atol = rtol * np.asarray(scale, float)
    coarse = flow.run(z0, t0, t_end, theta, rtol=rtol, atol=atol)
    fine = flow.run(z0, t0, t_end, theta, rtol=rtol / FACTOR, atol=atol / FACTOR)
    return Reference(fine=fine, coarse=coarse, rtol=rtol / FACTOR)


class GrowingReference:
    """The pair of runs of `reference`, grown a piece at a time: `advance` carries the fine run
    on by one compiled call of the flow (``flow.slots`` attempted steps) from where it stopped
    and the coarse run to the same time, and returns that piece as a `Reference` whose claim
    continues the running maximum of the pieces before it (``floor``). The pieces follow the
    reference's own steps, not the number of nodes read from it: a run that drifts early is
    integrated one call past its drift, and an accurate one in as many calls as its motion
    needs. ``first_flow``: the same flow with fewer attempts a call (`FIRST_SLOTS`), for the
    first piece, which ends at ``first`` after a few dozen attempts (the same steps, bit for
    bit: a run is the same attempts whatever the calls it is cut into; a call of 1024 slots
    costs its skipped slots, 0.4 ms of the first piece's 0.8 on Henon-Heiles and 3 of 3.8 ms
    on a 16-site lattice)."""

    def __init__(self, flow: AdaptiveFlow, z0, t0: float, t_end: float, theta, scale, *,
                 rtol: float = 1e-10, first: float | None = None,
                 first_flow: AdaptiveFlow | None = None):
        self.flow, self.theta = flow, np.asarray(theta, float)
        self.first_flow = first_flow
        self.rtol, self.scale = rtol, np.asarray(scale, float)
        self.t_end = float(t_end)
        # the first piece ends at ``first`` (a time between t0 and t_end) if given: a run that
        # drifts within it is integrated that far, not a whole call of attempts past it
        self.first = None if first is None or not _between(float(t0), float(first), self.t_end) \
            else float(first)
        z0 = np.asarray(z0, float)
        self._ends = {"coarse": (float(t0), z0, None), "fine": (float(t0), z0, None)}
        self.floor = 0.0  # the running maximum of |coarse - fine| / scale so far
        self.steps = 0  # the fine run's accepted steps so far
        self.reached = float(t0)  # where both runs have come to
        self.done = False  # both reached t_end
        self.failed = False  # a run stopped before t_end (the flow cannot go on)

    def advance(self) -> Reference:
        """The next piece: the fine run one call on (or to ``t_end``), the coarse to where the
        fine one stopped."""
        t, z, h = self._ends["fine"]
        until = self.t_end if self.first is None else self.first
        flow = self.flow if self.first is None or self.first_flow is None else self.first_flow
        self.first = None
        # a run's last attempts in calls of the first piece's flow (`AdaptiveFlow.run`'s
        # ``tail``): the same attempts, without the skipped slots of a call of the full one
        tail = self.first_flow if flow is self.flow else None
        fine = flow.run(z, t, until, self.theta, rtol=self.rtol / FACTOR,
                        atol=self.rtol / FACTOR * self.scale, h0=h, max_attempts=self.flow.slots,
                        tail=tail)
        t, z, h = self._ends["coarse"]
        coarse = flow.run(z, t, fine.t_reached, self.theta, rtol=self.rtol,
                          atol=self.rtol * self.scale, h0=h, tail=tail)
        paused = until != self.t_end and fine.success  # the first piece, ended at `first`
        for name, part in (("fine", fine), ("coarse", coarse)):
            # the next piece starts with the last step (not one cut short to land on `first`)
            back = 2 if name == "fine" and paused and part.steps > 1 else 1
            last = abs(float(part.h[-back])) if part.steps else self._ends[name][2]
            self._ends[name] = (part.t_reached, part.z_end, last)
        forward = self.t_end >= fine.t0
        self.reached = min(fine.t_reached, coarse.t_reached) if forward else \
            max(fine.t_reached, coarse.t_reached)
        self.done = self.reached == self.t_end
        limit = "attempt limit reached"
        self.failed = not self.done and (not coarse.success or fine.steps == 0 or
                                         not (fine.status == limit or paused))
        self.steps += fine.steps
        return Reference(fine=fine, coarse=coarse, rtol=self.rtol / FACTOR, floor=self.floor)

    def at(self, piece: Reference, times) -> tuple[np.ndarray, np.ndarray]:
        """The states of ``piece`` at ``times`` (within it, after the pieces before) and their
        claimed error; the running maximum carried on to the next piece."""
        states, claim = piece.at(np.asarray(times, float), self.scale)
        self.floor = piece.end_envelope
        return states, claim


def _between(t0: float, t: float, t_end: float) -> bool:
    """``t`` strictly between ``t0`` and ``t_end`` (either direction)."""
    return t0 < t < t_end or t_end < t < t0


def exact_reference(system, z0, t0: float, t_end: float, theta, *, rtol: float = 1e-12,
                    scale=None, compiler: str | None = "auto", cache_dir=None) -> Reference:
    """The reference of ``system``'s exact flow from ``z0`` over ``[t0, t_end]`` (the pair of
    runs of `reference`, the finer at ``rtol / FACTOR``), ``scale`` the motion's size per
    component (default: the range of a first run at ``rtol``, at least a tenth of its block's
    largest range, as the accuracy check's scales)."""
    from .flow import exact_flow

    flow = exact_flow(system, compiler=compiler, cache_dir=cache_dir)
    theta = np.asarray(theta, float)
    if scale is None:
        z0 = np.asarray(z0, float)
        size = float(np.max(np.abs(z0))) or 1.0  # the start's size (1 only at rest at 0)
        pilot = flow.run(z0, t0, t_end, theta, rtol=rtol, atol=rtol * size)
        _, states = pilot.nodes()
        states = states[np.all(np.isfinite(states), axis=1)]
        span = states.max(axis=0) - states.min(axis=0)
        n = span.size // 2
        scale = span.copy()
        for block in (slice(0, n), slice(n, 2 * n)):
            scale[block] = np.maximum(scale[block], 0.1 * np.max(span[block]))
        scale = np.maximum(scale, 1e-12 * np.abs(states).max(axis=0))
        scale = np.maximum(scale, np.finfo(float).tiny)
    return reference(flow, z0, t0, t_end, theta, scale, rtol=rtol)
