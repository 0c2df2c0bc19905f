"""Dense output: the exact vector field a solution interpolates with, states at asked-for times
(``t_eval``) and events located on the interpolant.

``Solution.at`` interpolates each interval by the cubic Hermite polynomial through the nodes
``z_k``, ``z_k+1`` with the slopes ``f(t_k, z_k) = (H_p, -H_q)`` (docs/theory.md section 10);
the solvers hand it this field (`DenseField`), evaluated on all nodes in one mapped CasADi
call. The field pickles as CasADi's own serialization of the same expression graph, so a copy
in another process (an ensemble's worker, a file) interpolates with the same slopes and gives
the same numbers, never finite differences.

Events (scipy's ``solve_ivp`` convention): a function ``g(t, q, p)`` with optional attributes
``direction`` (``> 0``: only where ``g`` goes from negative to non-negative; ``< 0``: from
positive to non-positive; ``0``: both), ``terminal`` (``True`` or a count of occurrences that
ends the march) and ``vectorized`` (``g`` takes ``t`` ``(M,)`` and ``q``, ``p`` ``(M, n)`` and
returns ``(M,)``). An interval whose end values change sign in the event's direction holds a
crossing; its time is located by bisection in ``t`` on the Hermite interpolant until the bracket
is two adjacent floating-point numbers (round-off), and the reported time is the bracket's end
where the sign has changed, with the state ``Solution.at`` gives there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..errors import InputError
from ..physics.hamiltonian import vector_field_function
from ..solution import Solution, Status, hermite


class DenseField:
    """``f(t, z) -> z'`` on rows (``(M,)``, ``(M, 2n)``) and ``H(q, p, t)`` of a solved system at
    its parameter values ``theta``: what a `Solution` needs for ``at`` and ``energy``.

    Pickles as the serialized CasADi functions (a few kB): evaluated after unpickling it runs
    the same expression graph on the same virtual machine, so the slopes are the same bits."""

    portable = True  # Solution.__getstate__ keeps it

    def __init__(self, field: ca.Function, energy: ca.Function, theta, name: str = ""):
        self.field, self.energy_function = field, energy
        self.theta = np.asarray(theta, dtype=float)
        self.name = name

    @classmethod
    def of(cls, system, theta) -> DenseField:
        return cls(vector_field_function(system), system.H_function, theta, system.name)

    def __call__(self, t, z) -> np.ndarray:
        t, z = np.atleast_1d(np.asarray(t, float)), np.atleast_2d(np.asarray(z, float))
        mapped = self.field.map(t.size)
        return np.asarray(mapped(z.T, t[None, :], self.theta[:, None])).T

    def energy(self, q, p, t) -> np.ndarray:
        """``H(q_k, p_k, t_k)`` on rows."""
        q, p, t = np.atleast_2d(q), np.atleast_2d(p), np.atleast_1d(np.asarray(t, float))
        mapped = self.energy_function.map(t.size)
        return np.asarray(mapped(q.T, p.T, t[None, :], self.theta[:, None])).ravel()

    def __getstate__(self):
        return {"field": self.field.serialize(), "energy": self.energy_function.serialize(),
                "theta": self.theta, "name": self.name}

    def __setstate__(self, state):
        self.__init__(ca.Function.deserialize(state["field"]),
                      ca.Function.deserialize(state["energy"]), state["theta"], state["name"])


def attach(solution: Solution, system, theta, t_end: float | None) -> Solution:
    """Give ``solution`` the requested ``t_end``, the ``system`` it solved and its dense field
    at ``theta`` (for ``Solution.at`` and ``energy``); returns it."""
    solution.t_end = None if t_end is None else float(t_end)
    solution.vector_field = DenseField.of(system, theta)
    solution.system = system
    return solution


# --- states at asked-for times ---------------------------------------------------------------

def evaluate_at(solution: Solution, t_eval: np.ndarray | None) -> None:
    """``solution.t_eval`` and ``z_eval``: the asked-for times up to the last node (a march
    that stopped early has none after it) and ``(q, p)`` there from ``Solution.at``."""
    if t_eval is None or solution.t.size == 0:
        return
    kept = t_eval[t_eval <= solution.t[-1]]
    q, p = solution.at(kept) if kept.size else (np.zeros((0, solution.q.shape[1])),) * 2
    solution.t_eval, solution.z_eval = kept, np.hstack([q, p])


# --- events ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class Event:
    """One checked event: ``g``, its ``direction`` (-1, 0, 1), ``terminal`` (occurrences that
    end the run; 0: never) and whether ``g`` takes arrays."""

    g: object
    direction: int
    terminal: int
    vectorized: bool

    def values(self, t: np.ndarray, z: np.ndarray) -> np.ndarray:
        """``g`` on rows ``(t_k, q_k, p_k)``."""
        n = z.shape[1] // 2
        if self.vectorized:
            out = np.asarray(self.g(t, z[:, :n], z[:, n:]), dtype=float).reshape(t.size)
        else:
            out = np.array([float(self.g(t[k], z[k, :n], z[k, n:])) for k in range(t.size)])
        return out

    def crossed(self, before: np.ndarray, after: np.ndarray) -> np.ndarray:
        """Where ``g`` changes sign from ``before`` to ``after`` in the event's direction."""
        up = (before < 0) & (after >= 0)
        down = (before > 0) & (after <= 0)
        return up if self.direction > 0 else down if self.direction < 0 else up | down


def check_events(events) -> tuple[Event, ...]:
    """``events`` (a function, or a list of them) as `Event` records; an
    `InputError` names the event and the attribute that is wrong."""
    if events is None:
        return ()
    listed = list(events) if isinstance(events, (list, tuple)) else [events]
    checked = []
    for i, g in enumerate(listed):
        if not callable(g):
            raise InputError(f"events[{i}] must be a function g(t, q, p), got {g!r}")
        direction = getattr(g, "direction", 0)
        terminal = getattr(g, "terminal", False)
        if not isinstance(direction, (int, float)) or not math.isfinite(direction):
            raise InputError(f"events[{i}].direction must be a number, got {direction!r}")
        if isinstance(terminal, bool):
            terminal = int(terminal)
        elif not isinstance(terminal, int) or terminal < 0:
            raise InputError(f"events[{i}].terminal must be True, False or a count of "
                             f"occurrences >= 0, got {terminal!r}")
        checked.append(Event(g, int(np.sign(direction)), terminal,
                             bool(getattr(g, "vectorized", False))))
    return tuple(checked)


def locate(event: Event, t: np.ndarray, z: np.ndarray, slopes: np.ndarray,
           intervals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Times ``(K,)`` and states ``(K, 2n)`` of the crossings of ``event`` in ``intervals``
    (indices ``k`` of intervals ``[t_k, t_k+1]`` whose end values crossed): bisection in ``t``
    on the interval's Hermite interpolant (``slopes`` at every node of ``t``) until the bracket
    is two adjacent numbers; the end past the crossing is returned."""
    if intervals.size == 0:
        return np.zeros(0), np.zeros((0, z.shape[1]))
    lo, hi = t[intervals].copy(), t[intervals + 1].copy()
    g_lo = event.values(lo, z[intervals])
    for _ in range(2200):  # 64 halvings reach round-off from any interval; the loop's guard
        mid = lo + (hi - lo) / 2
        open_ = (mid > lo) & (mid < hi)
        if not open_.any():
            break
        g_mid = event.values(mid[open_], hermite(t, z, slopes, mid[open_]))
        before = np.zeros(lo.size, dtype=bool)
        before[open_] = ~event.crossed(g_lo[open_], g_mid)  # the crossing lies after mid
        lo, g_lo = np.where(before, mid, lo), np.where(before, _spread(g_mid, open_, g_lo), g_lo)
        hi = np.where(open_ & ~before, mid, hi)
    return hi, hermite(t, z, slopes, hi)


def _spread(values, mask, fallback):
    out = fallback.copy()
    out[mask] = values
    return out


class EventMonitor:
    """A march monitor (driver rule 5): ``g`` of every event at every new node, crossings
    located on the dense output (`locate`), and the run ended, status ``EVENT``, at the
    node that closes the interval of a terminal event's last counted occurrence. Crossings past
    ``t_end`` are not reported (the last node may lie past it)."""

    def __init__(self, events: tuple[Event, ...], field, t_end: float, t0, z0):
        self.events, self.field, self.t_end = events, field, t_end
        self.last = [event.values(np.atleast_1d(t0), np.atleast_2d(z0))[0] for event in events]
        self.times = [[] for _ in events]
        self.states = [[] for _ in events]
        self.counts = [0] * len(events)

    def watch(self, nodes, first, advance):
        if not advance.count:
            return None
        t, z = nodes.t[first - 1:nodes.count], nodes.z[first - 1:nodes.count]
        found = []
        for i, event in enumerate(self.events):
            values = event.values(t[1:], z[1:])
            where = np.flatnonzero(event.crossed(np.concatenate([[self.last[i]], values[:-1]]),
                                                 values))
            self.last[i] = values[-1]
            if where.size:
                found.append((i, where))
        if not found:
            return None
        slopes = self.field(t, z)
        stop = None  # (time, interval, event) of the first terminal occurrence
        located = []
        for i, where in found:
            times, states = locate(self.events[i], t, z, slopes, where)
            keep = times <= self.t_end
            located.append((i, where[keep], times[keep], states[keep]))
            terminal = self.events[i].terminal
            if terminal and self.counts[i] + keep.sum() >= terminal:
                j = terminal - self.counts[i] - 1
                if stop is None or times[keep][j] < stop[0]:
                    stop = (times[keep][j], int(where[keep][j]), i)
        for i, _, times, states in located:
            if stop is not None:
                within = times <= stop[0]
                times, states = times[within], states[within]
            self.times[i].append(times)
            self.states[i].append(states)
            self.counts[i] += times.size
        if stop is None:
            return None
        return (Status.EVENT, f"event {stop[2]} at t = {stop[0]:.17g}", stop[1] + 1)

    def report(self, solution: Solution) -> None:
        """``solution.t_events`` and ``z_events``: one array per event, in time order."""
        width = 2 * solution.q.shape[1]
        solution.t_events = [np.concatenate(times) if times else np.zeros(0)
                             for times in self.times]
        solution.z_events = [np.vstack(states) if states else np.zeros((0, width))
                             for states in self.states]
