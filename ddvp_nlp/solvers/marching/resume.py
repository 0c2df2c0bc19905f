"""A march continued from an earlier run's nodes, as if it had never stopped.

What the march's loop carries from step to step besides the nodes (found by reading the
steppers, ``stepper.py``):

- the compensated energy drift (``Tally.drift``): each energy step solves ``residual = -drift``;
- on the composite path, the careful steps still owed after a chunk step failed its check
  (``MarchStepper.careful_left``) and where the run is inside a chunk (``CompiledStepper.offset``):
  a failing step hands the rest of *its chunk's* window to the careful path, so the chunk
  boundaries decide which path takes which step, and the two paths agree to round-off only;
- the monitors' state (solvability, energy guard, accuracy check, events), which is rebuilt by
  watching the earlier nodes again;
- the step-size predictor needs nothing more: it is the last step ``t_k - t_k-1``, in the nodes.

The steppers put the first three into every node's ``Advance.values["carry"]``
(``[drift, careful_left, phase]``), `CarryTracker` keeps the newest kept node's, and a
checkpoint or a finished run writes them beside the nodes. `MarchState` restores them,
so the continued nodes are an uninterrupted run's bit for bit, on the compiled and the careful
path (the batch sizes, which are not carried, only change how many steps a call computes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ..driver import Advance, Nodes
from .monitors import MarchMonitor


@dataclass(frozen=True)
class MarchState:
    """The nodes of an earlier march (``t`` ``(N,)``, ``z = (q, p)`` ``(N, 2n)``), the
    ``t_end`` it was asked for and what its loop carried at its last node (``carried``:
    ``drift``, ``careful_left``, ``phase``; `carried_state` of a run)."""

    t: np.ndarray
    z: np.ndarray
    t_end: float
    drift: float = 0.0
    careful_left: int = 0
    phase: int = 0
    multipliers: tuple | None = None  # a constrained march's last (lambda, mu)

    @classmethod
    def of(cls, t, q, p, t_end: float, carried: dict | None) -> MarchState:
        """From a run's arrays and its ``carried`` record (``Solution.march.carried``,
        ``meta.json``'s ``carried``); an `InputError` says what is missing."""
        if not isinstance(carried, dict) or not {"drift", "careful_left", "phase"} <= set(
                carried):
            raise InputError(f"the run does not record the march's carried state (drift, "
                             f"careful_left, phase), got {carried!r}: it was written by an "
                             f"older ddvp and cannot be continued bit for bit")
        t = np.asarray(t, float)
        z = np.hstack([np.atleast_2d(q), np.atleast_2d(p)]).astype(float)
        if t.ndim != 1 or t.size < 1 or z.shape[0] != t.size:
            raise InputError(f"a march state needs t (N,) and q, p (N, n), got {t.shape} and "
                             f"{z.shape}")
        return cls(t, z, float(t_end), float(carried["drift"]), int(carried["careful_left"]),
                   int(carried["phase"]), _multipliers(carried.get("multipliers")))

    def restore(self, stepper, tally, monitors, functions, theta) -> Nodes:
        """The nodes as the driver's `Nodes`, the loop's carried state put back into
        ``stepper`` and ``tally``, and the earlier nodes watched by ``monitors`` (with ``H`` and
        ``w`` of every node, as the steppers give them). A monitor that would have ended the
        earlier run is an `InputError`: the options differ from that run's."""
        nodes = Nodes(self.t, self.z)
        tally.drift = self.drift
        if hasattr(stepper, "careful_left"):
            stepper.careful_left = self.careful_left
            stepper.compiled.offset = self.phase
        if self.t.size < 2:
            return nodes
        count = self.t.size - 1
        H, w = functions.node_monitor.map(count)(self.z[1:].T, self.t[None, 1:],
                                                 np.asarray(theta, float)[:, None])
        values = {"H": np.asarray(H).ravel(), "w": np.asarray(w).ravel()}
        advance = Advance(self.t[1:], self.z[1:], values=values)
        for monitor in monitors:
            verdict = monitor.watch(nodes, 1, advance)
            if verdict is not None:
                raise InputError(f"the earlier nodes end the march again ({verdict[0].code}: "
                                 f"{verdict[1]}): continue it with the options it ran with")
        return nodes


def _multipliers(value) -> tuple | None:
    """A constrained march's carried multipliers: finite numbers (its length is checked
    against the system by `continue_march`)."""
    if value is None:
        return None
    numbers = (isinstance(value, np.ndarray) and value.dtype.kind in "iuf") or (
        isinstance(value, (list, tuple)) and all(
            isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool)
            for x in value))  # a boolean is no multiplier, though numpy reads it as one
    array = np.asarray(value, float) if numbers else None
    if array is None or array.ndim != 1 or not np.all(np.isfinite(array)):
        raise InputError(f"the carried multipliers must be a list of finite numbers, got "
                         f"{value!r:.200}")
    return tuple(array.tolist())


class CarryTracker(MarchMonitor):
    """A monitor that keeps the carried state of the newest kept node (never ends the run),
    from the state a continued march starts with (`of`); the session's own (``session.carry``:
    a `Checkpoint` saves it), ``march.carried`` at the end."""

    rewatch = False  # it starts from the earlier run's carried state

    def __init__(self, drift: float = 0.0, careful_left: int = 0, phase: int = 0):
        self.last = np.array([drift, float(careful_left), float(phase)])

    @classmethod
    def of(cls, start: MarchState | None) -> CarryTracker:
        """From the state ``start`` carried at its last node (a new march: nothing carried)."""
        return cls() if start is None else cls(start.drift, start.careful_left, start.phase)

    @classmethod
    def from_options(cls, session):
        """Every march's: ``session.carry``."""
        return session.carry

    def watch(self, nodes, first, advance):
        carry = advance.values.get("carry")
        if advance.count and carry is not None:
            self.last = carry[-1].copy()
        return None

    def state(self) -> dict:
        """``drift`` (exact: a float's repr reads back as the same float), ``careful_left``,
        ``phase``."""
        return {"drift": float(self.last[0]), "careful_left": int(self.last[1]),
                "phase": int(self.last[2])}

    def finish(self, solution, outcome):
        """``march.carried``, for `MarchState.of`."""
        solution.march.carried = self.state()


def check_resume(state: MarchState, problem, variable_steps: bool) -> None:
    """A continuation of ``state`` must ask for the same or a later ``t_end``, and its
    ``tau0`` must have made the first step; a fixed-step march keeps its ``t_end`` (its grid
    is ``t_end``'s)."""
    if not isinstance(state, MarchState):
        raise InputError(f"state must be a MarchState, got {type(state).__name__}")
    if problem.t_end < state.t_end:
        raise InputError(f"t_end must be at least the earlier run's t_end = {state.t_end!r}, "
                         f"got {problem.t_end!r}")
    if not variable_steps and problem.t_end != state.t_end:
        raise InputError(f"a fixed-step march cannot be extended (its steps are "
                         f"(t_end - t0) / N): t_end must stay {state.t_end!r}, got "
                         f"{problem.t_end!r}")
    if state.t.size > 1 and variable_steps and state.t[0] + problem.tau0 != state.t[1]:
        raise InputError(f"tau0 = {problem.tau0!r} did not make the run's first step "
                         f"(t_1 - t_0 = {state.t[1] - state.t[0]!r}): give the run's tau0")
    if not np.array_equal(state.z[0], np.concatenate([problem.q0, problem.p0])):
        raise InputError("the start (q0, p0) is not the run's first node")
