"""The accuracy check: a verdict on a trajectory that does not trust the scheme's own equations.

A march can satisfy every one of its equations and still not follow the motion: the energy
equation holds on a wrong energy level just as well as on the right one. So every trajectory is
judged against the exact flow ``z' = f(z, t) = (H_p, -H_q)`` (``exact/``: one adaptive
order-8 Runge-Kutta flow per system, compiled once, with dense output; its own error is measured
by a second run at a tenth of the tolerance, never assumed), and gets one of three verdicts:

- ``accurate``: the trajectory error stays within ``global_tol`` of the motion's size over the
  whole run;
- ``drifted``: every step follows the flow and the energy is right, but the trajectory error
  passes ``global_tol`` from ``t_drift`` on (a phase error: over long horizons every scheme's
  phase error outgrows every tolerance while the orbit stays right);
- ``inaccurate``: a step does not follow the flow, or the energy level is wrong.

**Scales come from the motion, never from 1.** ``S_i``, the size of component ``i`` of
``z = (q, p)``, is its range over the run (the nodes and the reference's states), at least a
tenth of the largest range of its block (``q`` or ``p``; `motion_scales`). A cyclic coordinate
(one ``H`` does not depend on: an azimuth that winds) keeps its own range but sets no floor for
the others, and its conserved momentum does not enter the energy scale; an angle that winds
(``H`` is ``2 pi``-periodic in it, its range passes a turn) counts at most one turn, for itself
and for the others (`winding_angles`; not for a streamed check). Periodic means free of units:
a ``2 pi`` shift changes ``H`` by its round-off alone where a non-periodic ``H`` would change by
far more (`periodic_in`; a position in metres is never an angle). The energy
scale ``E_s`` is the time average of ``|S * grad H(z_k, t_k)|_2``, how much ``H`` changes when
the state moves by ``S`` (`energy_scale`): an energy error ``dE`` puts some node at least
``dE / E_s`` (in units of ``S``) off the exact level set. Every figure below is relative to
these, so a verdict does not change when ``q``, ``p``, ``t`` and ``H`` are rescaled
consistently, when a constant is added to ``H`` or when a translation-invariant system is
translated (the metamorphic tests).

The tests, in the order the verdict reads them:

1. **Local error** of every step: ``d_k = z_{k+1} - Phi_{tau_k}(z_k)`` with ``Phi`` the exact
   flow over the accepted step (``exact/short_flows.py``: every step at once, each with its own
   error held below a tenth of the bound); the step fails when ``|d_k,i| > rtol S_i (+ atol)``
   for some ``i``. For a second-order scheme (``screen``) one RK4 step of the exact flow is
   measured first, over all nodes in compiled blocks (``node_values.py``); the steps below half
   the bound pass, only the others go to the exact flow.
2. **Energy level of the first step** (energy rules, which keep it for the whole march): the
   first interval's energy against ``H`` of the exact motion at the first interval's clock
   (for autonomous ``H`` simply ``H(z_0)``; for a time-dependent one the explicit change of
   ``H`` over half a step is motion, not error). Fails above ``energy_tol``.
3. **Nodal energy drift** (autonomous ``H`` and constraints, `energy_varies`):
   ``max_k |H(z_k) - H(z_0)| / E_s`` against ``energy_tol``.
4. **Trajectory error**: ``max_i |z_k,i - z_ref,i(t_k)| / S_i`` at every node, ``z_ref`` the
   exact solution where the caller gives one (a fixed-endpoint solve passes its shooting
   solution), else the exact flow from ``z_0`` read at the nodes by its dense output. The flow
   is integrated a compiled call (1024 attempted steps) at a time from ``t_0`` and stops at the
   first piece where the error passes ``global_tol`` (``t_drift``): a run that drifts early is
   never integrated to its end (the paper's pendulum drifts at ``t = 2`` of ``10^4``). Where the
   reference's own error passes a tenth of ``global_tol`` before ``t_drift`` it is integrated
   again 100 times tighter; where even the tightest cannot hold it (a chaotic orbit past its
   horizon) the run is ``drifted`` from that time, and the report says the error could not be
   measured further. ``error_max`` of a drifted run is thus the error at ``t_drift``, not the
   run's largest (`describe` says so); against an exact solution given at every node the whole
   run is measured (`whole_run`). A solution with both ends fixed cannot drift: its trajectory
   error past ``global_tol`` is a failed test (`fixed_ends_report`).

``inaccurate`` if test 1, 2 or 3 fails (the first failure is reported with its step, time,
value and limit), else ``drifted`` if test 4 found a ``t_drift``, else ``accurate``. Why the
defaults (``rtol = global_tol = 1e-2``, ``energy_tol = 0.1``) keep an ``inaccurate`` verdict
honest: a local error above ``rtol S`` moves the trajectory by about that much at once, and an
energy error above ``energy_tol E_s`` puts some node at least ``energy_tol / sqrt(2n)`` of the
motion's size off the exact level set; both are trajectory errors above ``global_tol``.

The check runs once, on the finished trajectory (`Judgement.report`), never inside the step
loop: the scales are those of the whole run. `assess` does the same for the trajectory of any
method, a fixed-endpoint or a periodic solution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from ...cache import cached
from ...physics.constraints import constraint_function
from ...solution import Status, Verdict
from ..columns import WIDE as COLUMNS_WIDE
from ..columns import (
    column_argmax,
    column_extremes,
    column_span,
    row_max,
    row_max_abs,
    row_max_ratio,
    row_norm,
)
from ..exact.flow import exact_flow
from ..exact.kernel import kernel as check_kernel
from ..exact.reference import FACTOR, FIRST_SLOTS, FLOOR_RTOL, GrowingReference
from ..exact.short_flows import short_flows
from ..options import EXACT_TOLERANCE, Tolerance
from .node_values import NodeValues

ADVICE = ("try a smaller tau0, fixed steps (--scheme fixed), or the least-squares step "
          "(--least-squares); --accept-inaccurate (Tolerance(stop=False)) records the verdict "
          "and keeps the status")
# A component's scale is at least this fraction of the largest range of its block (q or p).
BLOCK_FLOOR = 0.1
# ... and at least this fraction of its own magnitude (a block that does not move at all).
ROUND_OFF = 1e-12
TINY = np.finfo(float).tiny  # the least a scale is (a constant: np.finfo took 2-5 us a call)
# Steps whose first look is below this fraction of the local bound pass without a second look.
CANDIDATE = 0.5
# The reference's own error may use this fraction of global_tol (and the short flows' of the
# local bound).
REFERENCE_SHARE = 0.1
# The smallest global_tol the trajectory error can be judged against: the finest reference's
# own error (DOP853 at FLOOR_RTOL) must stay within its share of it.
SMALLEST_GLOBAL_TOL = FLOOR_RTOL / REFERENCE_SHARE
# The exact flow's tolerance to the first interval's clock (a fraction of a step).
LEVEL_RTOL = EXACT_TOLERANCE.flow_rtol
# The reference's first piece covers the first this many nodes (then a compiled call of
# attempts a piece): a run that drifts within them is integrated that far only (the paper's
# pendulum drifts at its 4th node; the first call took 1024 attempts of each run, to t = 218).
FIRST_NODES = 64
# The reference's first tolerance (the coarse run's; the reference is the run at a tenth of it):
# tighter by 100 while its own error passes its share before t_drift.
REFERENCE_RTOL = EXACT_TOLERANCE.reference_rtol


def finite_or_none(value) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


# -- the scales of a motion -------------------------------------------------------------------

def verdict_report(failure, trajectory: dict, scale, energy: float, local_max: float,
                   figures: dict, steps: int, tol: Tolerance) -> dict:
    """The report of a verdict (`judge` makes it ``Solution.verdict``), the same for a whole
    run and a streamed one: ``failure`` the first failed test or ``None``, ``trajectory`` the scan's
    findings (drift, largest error, the reference's reach and error)."""
    drift = trajectory["drift"]
    verdict = "inaccurate" if failure else ("drifted" if drift is not None else "accurate")
    return {
        "verdict": verdict, "first_failure": failure,
        "t_drift": None if drift is None else trajectory["drift_t"],
        "drift_step": drift, "error_max": trajectory["error_max"],
        "error_max_t": trajectory["error_max_t"], "estimate": trajectory["estimate"],
        "reference_until": trajectory["until"],
        "reference_error": trajectory["reference_error"],
        "reference_lost": trajectory["lost"],
        "scale": scale.tolist(), "energy_scale": energy, "local_error_max": local_max,
        **figures, "steps": steps,
        "rtol": tol.rtol, "atol": tol.atol, "energy_tol": tol.energy_tol,
        "global_tol": tol.global_tol, "require_accurate": tol.require_accurate}


def exact_states(system, z0, t: np.ndarray, theta, *, rtol: float) -> np.ndarray:
    """The exact flow of ``system`` from ``z0`` at the times ``t`` (increasing, ``z0`` at
    ``t[0]``), from the reference this check judges by (a pair of runs, the finer at
    ``rtol / FACTOR``): the independent reference for a caller outside this package, such as
    the pilot of ``march(..., target_error=E)``."""
    from ..exact.reference import exact_reference

    t = np.asarray(t, float)
    return exact_reference(system, z0, float(t[0]), float(t[-1]), theta, rtol=rtol).states(t)


def exact_nodes(system, z0, t0: float, t_end: float, theta, *, rtol: float, attempts: int,
                compiler=None, cache_dir=None) -> tuple[np.ndarray, np.ndarray]:
    """The accepted steps ``(t, z)`` of the exact flow from ``z0`` at ``t0`` towards
    ``t_end``, ended after ``attempts`` attempted steps if it has not arrived: the motion over a
    stretch set by its own time scale, for a caller outside this package that needs the orbit's
    scales before it runs (the step density of ``verlet_adaptive``)."""
    flow = exact_flow(system, dense=False, compiler=compiler, cache_dir=cache_dir)
    return flow.run(np.asarray(z0, float), t0, t_end, theta, rtol=rtol,
                    max_attempts=attempts).nodes()


def motion_scales(low: np.ndarray, high: np.ndarray, largest: np.ndarray, n: int,
                  free: np.ndarray | None = None,
                  turns: np.ndarray | None = None) -> np.ndarray:
    """``S_i`` of each component of ``z = (q, p)`` from its least and greatest values over the
    motion and its largest magnitude: its range ``high - low``, at least ``BLOCK_FLOOR`` times
    the largest range of its block (``q`` or ``p``: a coordinate that barely moves is measured
    against the motion of the others, not against round-off) and at least ``ROUND_OFF`` times
    its magnitude (a block that does not move at all). A component marked in ``free`` (a
    cyclic coordinate, `free_components`) keeps its own range but sets no floor for the others:
    a winding angle's secular growth says nothing of how far the other coordinates move. A
    component marked in ``turns`` (an angle ``H`` is ``2 pi``-periodic in, `winding_angles`)
    counts at most one turn, for itself and for the others: an angle that winds is judged by
    how far it is off within a turn, not against the turns it made."""
    span = np.asarray(high, float) - np.asarray(low, float)
    if turns is not None:
        span = np.where(turns, np.minimum(span, 2 * np.pi), span)
    scale = span.copy()
    feeding = span if free is None else np.where(free, 0.0, span)
    for block in (slice(0, n), slice(n, 2 * n)):
        np.maximum(scale[block], BLOCK_FLOOR * feeding[block].max(), out=scale[block])
    np.maximum(scale, ROUND_OFF * np.asarray(largest, float), out=scale)
    return np.maximum(scale, TINY, out=scale)


def free_components(system) -> np.ndarray | None:
    """The components of ``z = (q, p)`` whose range sets no floor for the others (see
    `motion_scales`): the cyclic coordinates, those ``H`` does not depend on (found on its
    symbols, so exactly and whatever the units: an azimuth, a polar angle of a central force,
    a free direction). Their range grows without bound on a long run while the rest of the
    motion stays put. ``None`` for a system without a Hamiltonian expression."""
    H, q = getattr(system, "H", None), getattr(system, "q", None)
    if H is None or q is None:
        return None

    def build():  # one pass over H's symbols (n calls of depends_on were n passes over H)
        # a coordinate the constraints hold is not free (the Cartesian pendulum's x)
        held = ca.vertcat(H, ca.vec(system.G)) if getattr(system, "n_constraints", 0) else H
        present = {symbol.element_hash() for symbol in ca.symvar(held)}
        n = int(system.n)
        cyclic = [q[i].element_hash() not in present for i in range(n)]
        return np.array(cyclic + [False] * n, dtype=bool) if any(cyclic) else None
    return cached(system, "cyclic_components", build)


# H's round-off, in units of eps times the sum of its inputs' contributions (`winding_angles`).
ROUND_OFF_ULPS = 1000.0
# A node decides a 2 pi shift when the change it would make to a non-periodic H (first order)
# is this many times H's round-off there.
DECISIVE = 100.0
# The nodes at which H is shifted by a turn (spread over the run).
ANGLE_NODES = 16


def winding_angles(values: NodeValues, n: int, t: np.ndarray, z: np.ndarray,
                   free: np.ndarray | None, span: np.ndarray | None = None
                   ) -> np.ndarray | None:
    """The coordinates that wind as angles over the run: their range passes a turn, and they
    are declared angles (``HamiltonianSystem(angles=...)``, a scene's ``periodic`` angles) or
    ``H`` is ``2 pi``-periodic in them (`periodic_in`). An undeclared cyclic coordinate
    (``free``: an azimuth, but as well a free direction in any units) is left to
    `motion_scales`' own rule. ``None`` if there is none."""
    span = column_span(z[:, :n]) if span is None else span  # ``span``: the range of q
    if not np.any(span > 2 * np.pi):  # no coordinate passes a turn: H is not evaluated
        return None
    # not np.unique: its first call imports numpy.ma (30-70 ms of a short march's process)
    picks = np.array(sorted({int(k) for k in np.linspace(0, t.size - 1, ANGLE_NODES)}))
    rows = z[picks]
    field, H = values.at_nodes(t[picks], rows)
    turns = np.zeros(2 * n, dtype=bool)
    declared = getattr(values.system, "angle_indices", ())
    for j in range(n):
        if span[j] <= 2 * np.pi:
            continue
        if j in declared:  # the user's word: an angle (a cyclic azimuth too)
            turns[j] = True
            continue
        if free is not None and free[j]:
            continue
        shifted = rows.copy()
        shifted[:, j] += 2 * np.pi
        _, moved = values.at_nodes(t[picks], shifted)
        turns[j] = periodic_in(j, n, rows, field, H, moved) and \
            constraints_periodic_in(values, t[picks], rows, shifted)
    return turns if np.any(turns) else None


def constraints_periodic_in(values: NodeValues, t: np.ndarray, rows: np.ndarray,
                            shifted: np.ndarray) -> bool:
    """Whether a system's constraints ``g(q, t)`` are unchanged by the shift of ``rows`` to
    ``shifted`` to their round-off (``ROUND_OFF_ULPS`` eps times ``|g|`` and each position's
    contribution ``|q_i dg/dq_i|``); ``True`` for a system without constraints. A coordinate
    ``H`` does not depend on passes `periodic_in` by the constrained field's forces (the
    Cartesian pendulum's ``x`` in lengths of ``1e4``, whose span passes a turn, was taken for a
    winding angle and its scale cut to one turn: a local error of 1.3e-2 of the motion where
    in lengths of 1 it was 1.6e-3), but the rod ``x^2 + y^2 = L^2`` is no function of an
    angle ``x``."""
    system = values.system
    if not getattr(system, "n_constraints", 0):
        return True
    n = system.n
    function = constraint_function(system)
    theta = values.theta[0]  # the parameters, one row per node of a block
    for k in range(rows.shape[0]):
        g, G, _ = (np.asarray(v, float) for v in function(rows[k, :n], t[k], theta))
        moved = np.asarray(function(shifted[k, :n], t[k], theta)[0], float)
        round_off = ROUND_OFF_ULPS * np.finfo(float).eps * (
            np.abs(g).ravel() + np.abs(moved).ravel() + np.abs(G) @ np.abs(rows[k, :n]))
        if not np.all(np.abs(moved - g).ravel() <= round_off):
            return False
    return True


def periodic_in(j: int, n: int, rows: np.ndarray, field: np.ndarray, H: np.ndarray,
                moved: np.ndarray) -> bool:
    """Whether ``H`` is ``2 pi``-periodic in ``q_j``, from ``H`` at the nodes ``rows`` (their
    vector field ``field = (H_p, -H_q)``) and at the nodes shifted by ``2 pi e_j``
    (``moved``), free of units: the shift changes ``H`` by its round-off alone at every node
    (``ROUND_OFF_ULPS`` eps times ``|H|`` and each input's contribution ``|z_i dH/dz_i|``,
    ``q_j``'s rounding among them), and at some node a non-periodic ``H`` would have changed by
    far more (``|dH/dq_j| 2 pi`` at least ``DECISIVE`` times that round-off). A coordinate in
    metres on a planet's orbit fails the first (the shift moves ``H`` by its first-order change,
    some 1e-11 of ``|H|``, far above round-off); where the shift is itself below round-off
    (a coordinate far larger than a turn) nothing decides, and the coordinate is not an
    angle."""
    gradient = np.hstack([-field[:, n:], field[:, :n]])  # (H_q, H_p)
    contributions = np.sum(np.abs(rows * gradient), axis=1)
    round_off = ROUND_OFF_ULPS * np.finfo(float).eps * (
        np.abs(H) + np.abs(moved) + contributions)
    change = np.abs(moved - H)
    first_order = 2 * np.pi * np.abs(gradient[:, j])
    if not (np.all(np.isfinite(change)) and np.all(np.isfinite(round_off))):
        return False
    return bool(np.all(change <= round_off) and np.any(first_order > DECISIVE * round_off))


def run_extent(values: NodeValues, n: int, t, z, free, kernel=None) -> Extent:
    """The `Extent` of a whole run's nodes with its winding angles (`winding_angles`), from one
    pass over the nodes: every node's, whichever window is then measured (``kernel``: in one
    compiled pass, ``exact/kernel.py``, the same numbers)."""
    extremes = kernel.column_extremes(z) if kernel is not None and \
        kernel.table_readable(z) else column_extremes(z)
    turns = winding_angles(values, n, t, z, free, span=extremes[1][:n] - extremes[0][:n])
    return Extent(z, free, turns, extremes=extremes)


class Extent:
    """The least and greatest value and the largest magnitude of each component over the rows
    seen so far (the march's nodes, then the reference's, block by block)."""

    def __init__(self, rows: np.ndarray, free: np.ndarray | None = None,
                 turns: np.ndarray | None = None, extremes=None):
        # ``extremes``: `column_extremes` of ``rows``, where the caller has them
        self.low, self.high, self.largest = column_extremes(rows) if extremes is None else \
            (extremes[0].copy(), extremes[1].copy(), extremes[2].copy())
        self.free = free  # components that set no floor (`motion_scales`)
        self.turns = turns  # winding angles, counted at most one turn

    def scales(self, n: int) -> np.ndarray:
        return motion_scales(self.low, self.high, self.largest, n, self.free, self.turns)


def gradient_weights(scale: np.ndarray, n: int, free: np.ndarray | None = None) -> np.ndarray:
    """The weights of the columns of the vector field ``f = (H_p, -H_q)`` in ``|S * grad H|``:
    ``grad H = (H_q, H_p) = (-f_p, f_q)``, so column ``j`` of ``f`` weighs with ``S`` of the
    other block. The momentum of a cyclic coordinate (``free``) weighs nothing: it is
    conserved by the motion and by the schemes alike, so no energy error can move a node
    along it, and ``H_p`` there (a winding rate) says nothing of how far off the level set a
    node lies."""
    weights = np.concatenate([scale[n:], scale[:n]])
    if free is not None:
        weights[:n][free[:n]] = 0.0
    return weights


def gradient_sizes(t: np.ndarray, field: np.ndarray, scale: np.ndarray, n: int,
                   free: np.ndarray | None = None, kernel=None) -> tuple[np.ndarray, np.ndarray]:
    """``(weights, |S * grad H|)`` at the nodes: each node's share of the time (half of each
    step beside it) and how much ``H`` changes there when the state moves by ``S``
    (`gradient_weights`); `energy_scale` averages the one over the other, for a whole run or
    window by window (``streaming.py``). ``kernel``: the compiled pass (``exact/kernel.py``,
    the same numbers; up to ``columns.WIDE`` columns, where ``row_norm`` sums in order)."""
    if kernel is not None and field.shape[1] <= COLUMNS_WIDE and t.size == field.shape[0] \
            and kernel.table_readable(field):
        return kernel.gradient_sizes(t, field, gradient_weights(scale, n, free))
    norm = row_norm(field * gradient_weights(scale, n, free))
    weights = np.zeros(t.size)
    weights[:-1] += np.diff(t) / 2
    weights[1:] += np.diff(t) / 2
    return weights, norm


def energy_scale(t: np.ndarray, field: np.ndarray, H: np.ndarray, scale: np.ndarray,
                 n: int, free: np.ndarray | None = None, kernel=None) -> float:
    """``E_s``, the time average over the run of ``|S * grad H(z_k, t_k)|_2`` (from the vector
    field ``f = (H_p, -H_q)`` at the nodes, rows, and ``H`` there; `gradient_weights`): how
    much ``H`` changes when the state moves by the motion's own size ``S`` in each component,
    typically over the motion. An energy error ``dE`` puts the nodes ``dE / |S * grad H|`` (in
    units of ``S``) off the exact level set, so wherever the gradient is at most its average
    (somewhere it is) at least ``dE / E_s``: a displacement, free of units and of constants
    added to ``H``. At least ``ROUND_OFF`` times ``max |H|`` (a motion at rest)."""
    weights, norm = gradient_sizes(t, field, scale, n, free, kernel)
    typical = float(np.sum(weights * norm) / np.sum(weights)) if t.size > 1 else \
        float(norm[0]) if norm.size else 0.0
    if not math.isfinite(typical):
        return math.inf
    return max(typical, ROUND_OFF * float(np.max(np.abs(H), initial=0.0)),
               np.finfo(float).tiny)


# -- the verdict ----------------------------------------------------------------------------

def first_flow(system, compiler, cache_dir):
    """The exact flow with `FIRST_SLOTS` attempts a call, for the reference's first piece
    (`GrowingReference`), or ``None`` (the full flow then): from the second check of the system
    in this process on (its build, 15-20 ms, is not paid by a one-shot march), compiled once
    the full flow is (whose rent the system's checks have paid)."""
    checks = cached(system, ("accuracy", "checks", compiler, str(cache_dir)), lambda: [0])
    checks[0] += 1
    if checks[0] < 2:
        return None
    small = exact_flow(system, slots=FIRST_SLOTS, compiler=compiler, cache_dir=cache_dir)
    if not small.compiled and exact_flow(system, compiler=compiler,
                                         cache_dir=cache_dir).compiled:
        small.buy()
    return small


class CheckStopped(Exception):
    """A check given ``stop`` (`Judgement.report`) was asked to stop: no report."""


@dataclass
class Level:
    """The energy level a scheme keeps, set by its first step: ``value`` (``H`` of the first
    interval) at the first interval's clock ``clock``."""

    value: float
    clock: float


def unjudged(t, z, tol: Tolerance) -> dict:
    """The report of a run without a step, with a non-finite node, or whose node times do not
    run one way (a grid solver's point with a step of length 0 or of the wrong sign is not a
    trajectory): nothing to measure, and in the last two cases ``inaccurate``."""
    finite = bool(np.all(np.isfinite(z))) and bool(np.all(np.isfinite(t)))
    failure = None if finite else {"step": 0, "t": float(t[0]) if t.size else 0.0,
                                   "test": "finite nodes", "value": math.inf, "limit": 0.0}
    wrong = _wrong_step(t) if finite else None
    if wrong is not None:
        failure = {"step": wrong, "t": float(t[wrong]), "test": "node times run one way",
                   "value": float(t[wrong + 1] - t[wrong]), "limit": 0.0}
    return {"verdict": "accurate" if failure is None else "inaccurate", "first_failure": failure,
            "t_drift": None, "drift_step": None, "error_max": 0.0, "error_max_t": None,
            "estimate": "none (no step)", "reference_until": None, "reference_error": None,
            "reference_lost": None, "scale": None, "energy_scale": None,
            "local_error_max": 0.0, "level": None, "level_reference": None,
            "level_error": None, "level_round_off": None, "energy_drift": None,
            "steps": max(t.size - 1, 0), "rtol": tol.rtol, "atol": tol.atol,
            "energy_tol": tol.energy_tol, "global_tol": tol.global_tol,
            "require_accurate": tol.require_accurate}


def _wrong_step(t) -> int | None:
    """The first step of ``t`` of length 0 or of the other sign than the first step's (the
    times of a march run either way), or ``None``."""
    steps = np.diff(np.asarray(t, float))
    if not steps.size:
        return None
    wrong = np.flatnonzero(~(steps * np.sign(steps[0]) > 0))
    return int(wrong[0]) if wrong.size else None


class Judgement:
    """The accuracy check of one trajectory ``t`` (N+1,), ``z`` (N+1, 2n) against the exact
    flow, made once (`report`); see the module docstring for the tests and the verdict."""

    def __init__(self, system, theta, tolerance: Tolerance, *, compiler=None, cache_dir=None):
        self.system, self.theta, self.tolerance = system, np.asarray(theta, float), tolerance
        self.compiler, self.cache_dir = compiler, cache_dir
        self.values = NodeValues(system, theta, compiler=compiler, cache_dir=cache_dir)
        self.free = free_components(system)

    def flow(self):
        """The exact flow (``exact/flow.py``), compiled once per system."""
        self.asked_flow = exact_flow(self.system, compiler=self.compiler, cache_dir=self.cache_dir)
        return self.asked_flow

    def kernel(self):
        """`check_passes` of this check."""
        return check_passes(self)

    def report(self, t, z, *, level: Level | None = None, screen: bool = False,
               exact=None, stop=None) -> tuple[dict, np.ndarray]:
        """The report (`judge` makes it ``Solution.verdict``) and the local error of every step,
        ``|z_{k+1} - Phi(z_k)|_inf``. ``screen``: the steps whose error against one RK4 step
        of the exact flow is below ``CANDIDATE`` times the local bound pass without the exact
        flow (a second-order scheme's steps; RK4's own error, ``O(tau^5)``, is far below a
        second-order scheme's ``O(tau^3)``; a method of order 4 or more must be measured with
        the exact flow)."""
        t, z = np.asarray(t, float), np.asarray(z, float)
        steps = t.size - 1
        if steps < 1 or not np.all(np.isfinite(z)) or not np.all(np.isfinite(t)) or \
                _wrong_step(t) is not None:
            return unjudged(t, z, self.tolerance), np.zeros(max(steps, 0))
        self.stop = stop
        trajectory = self._trajectory(t, z, exact)
        n = self.system.n
        scale = trajectory["scale"]
        self._poll()
        look = self.values.first_look(t, z) if screen else None
        self._poll()
        field, H = look[1:] if look is not None else self.values.at_nodes(t, z)
        energy = energy_scale(t, field, H, scale, n, self.free, self.kernel())
        local, local_error, local_max = self._local(t, z, scale, look)
        energies = self.energies(t, z, H, energy, level, scale)
        failures = [f for f in (local, *energies["failures"]) if f is not None]
        failure = min(failures, key=lambda f: f["step"]) if failures else None
        report = verdict_report(failure, trajectory, scale, energy, local_max,
                                energies["figures"], steps, self.tolerance)
        return report, local_error

    stop = None  # report(stop=...): asked between the parts of a check
    small = asked_flow = None  # the first piece's flow (`first_flow`), the flow, once asked

    def _poll(self) -> None:
        if self.stop is not None and self.stop():
            raise CheckStopped

    def constant_terms(self, z0, t0) -> float:
        """The terms of ``H`` that depend on none of the state and the clock (``H + c``: ``c``),
        which the node values leave out (`physics.hamiltonian.varying_part`)."""
        system = self.system
        varying = getattr(system, "H_varying_function", None)
        if varying is None or varying is system.H_function:
            return 0.0
        n = system.n
        return float(system.H_function(z0[:n], z0[n:], t0, self.theta)) - float(
            varying(z0[:n], z0[n:], t0, self.theta))

    # -- the trajectory's error ---------------------------------------------------------------
    def _trajectory(self, t, z, exact) -> dict:
        """The trajectory error at every node against the reference states: the exact solution
        if given, else the exact flow from ``z_0`` (``exact/reference.py``: two adaptive runs,
        the finer read at the nodes by its dense output, its own error bounded by their
        difference and held below ``REFERENCE_SHARE * global_tol``). The reference grows a
        compiled call at a time (`GrowingReference`), each piece measured at the nodes it
        covers, until the error drifts or the run ends: a drifted run is measured up to
        ``t_drift`` and integrated one call past it (the paper's pendulum drifts at ``t = 2``
        of ``10^4``)."""
        tol = self.tolerance.global_tol
        extent = run_extent(self.values, self.system.n, t, z, self.free, self.kernel())
        if exact is not None:
            scan = Scan(extent, self.system.n, tol, self.kernel())
            states = np.asarray(exact(t), float).reshape(t.size, -1)  # node 0 too: p_0 of
            scan.measure(t, z, -1, t.size - 1, states, np.zeros(t.size))  # fixed ends is free
            return whole_run(scan, t, z, states)
        scale, last = extent.scales(self.system.n), t.size - 1
        rtol = REFERENCE_RTOL
        small = self.small = first_flow(self.system, self.compiler, self.cache_dir)
        while True:
            scan = Scan(extent, self.system.n, tol, self.kernel())
            growing = GrowingReference(self.flow(), z[0], t[0], t[-1], self.theta, scale,
                                       rtol=rtol, first=t[min(FIRST_NODES, last)],
                                       first_flow=small)
            start = 0
            while True:
                piece = growing.advance()
                end = last if growing.done else \
                    int(np.searchsorted(t, growing.reached, side="right")) - 1
                if growing.failed:  # the first node past where the flow stopped is lost
                    end = min(end + 1, last)
                if end > start:
                    with np.errstate(invalid="ignore", over="ignore"):
                        states, claim = growing.at(piece, t[start + 1:end + 1])
                        scan.measure(t, z, start, end, states, claim)
                    start = end
                if scan.stopped or start == last:
                    break
                self._poll()
            if scan.lost is not None and rtol / 100 >= FLOOR_RTOL * FACTOR:
                rtol /= 100  # its own error passed its share before t_drift: tighter
                continue
            break
        found = scan.figures(t[0], "")
        found["estimate"] = (f"reference flow (adaptive order-8 Runge-Kutta, DOP853 at rtol "
                             f"{rtol / FACTOR:.0e}, {growing.steps} steps; its own error at most "
                             f"{found['reference_error']:.1e} of the motion's size)")
        return found

    # -- the steps ----------------------------------------------------------------------------
    def _local(self, t, z, scale, look):
        """The local error test: ``|z_{k+1} - Phi_{tau_k}(z_k)|_i <= rtol S_i (+ atol)`` for every
        step (`screened_errors`). Returns the first failure (or None), ``|d_k|_inf`` and the
        largest ``max_i |d_k,i| / S_i``."""
        tol = self.tolerance
        local, relative_max, steps, relative, ratio = screened_errors(self, t, z, scale, look)
        bad = np.flatnonzero(~(ratio <= 1.0))
        failure = None
        if bad.size:
            k = int(steps[bad[0]])
            failure = {"step": k, "t": float(t[k]), "test": "local error",
                       "value": float(relative[bad[0]]), "limit": tol.rtol}
        return failure, local, relative_max

    def step_errors(self, t, z, scale, look=None):
        """Every step's local error against the exact flow (``exact/short_flows.py``, its own
        error held below a tenth of the bound ``rtol S_i (+ atol)``): ``|d_k|_inf``,
        ``max_i |d_k,i| / S_i`` and ``max_i |d_k,i| / bound_i``. With a first look (a
        second-order march's RK4 screen, `NodeValues.first_look`), the steps whose screen is
        below ``CANDIDATE`` times the bound in every component pass without the exact flow."""
        return step_differences(self, t, z, scale, look)[1:]

    def energies(self, t, z, H, energy: float, level: Level | None, scale) -> dict:
        """The energy tests, relative to the energy scale: the level the first step sets
        against ``H`` of the exact flow at the first interval's clock, and (autonomous ``H``)
        the nodal ``H`` against ``H(z_0, t_0)``."""
        system, tol = self.system, self.tolerance
        H0 = float(H[0])  # H here is without its constant terms (`NodeValues`)
        figures = {"level": None, "level_reference": None, "level_error": None,
                   "level_round_off": None, "energy_drift": None}
        failures = []
        if level is not None:
            reference = H0
            if energy_varies(system):  # H of the exact motion at the level's own clock
                # (on the first piece's flow where there is one: the same attempts)
                run = (self.small or self.flow()).run(z[0], t[0], level.clock, self.theta,
                                                      rtol=LEVEL_RTOL, atol=LEVEL_RTOL * scale)
                _, at_clock = self.values.at_nodes(np.array([level.clock]), run.z_end[None, :])
                reference = float(at_clock[0])
            # the level is a value of the whole H (a march's first interval, a prescribed
            # energy): its constant terms come back in, and with them their round-off, stated
            constant = self.constant_terms(z[0], t[0])
            reference += constant
            error = abs(level.value - reference) / energy
            round_off = 2 * np.finfo(float).eps * max(abs(level.value), abs(reference)) / energy
            figures.update(level=float(level.value), level_reference=reference,
                           level_error=finite_or_none(error),
                           level_round_off=finite_or_none(round_off))
            if not error <= tol.energy_tol:
                failures.append({"step": 0, "t": float(t[0]),
                                 "test": "energy level of the first step",
                                 "value": float(error), "limit": tol.energy_tol})
        if not energy_varies(system):
            drift = np.abs(H - H0) / energy
            figures["energy_drift"] = finite_or_none(float(np.max(drift)))
            over = np.flatnonzero(~(drift <= tol.energy_tol))
            if over.size:
                k = int(over[0])
                failures.append({"step": max(k - 1, 0), "t": float(t[k]),
                                 "test": "nodal energy drift", "value": float(drift[k]),
                                 "limit": tol.energy_tol})
        return {"figures": figures, "failures": failures}


def check_passes(check: Judgement):
    """The check's compiled passes (``exact/kernel.py``): loaded if in the cache, built once
    the exact flow the check asked for is compiled (its rent paid), else ``None`` (numpy, the
    same numbers). Never builds the flow itself (an early verdict, a check against an exact
    solution need none)."""
    found = check_kernel(check.compiler, check.cache_dir)
    return found if found is not None or check.asked_flow is None else \
        check.asked_flow.kernel()


def step_differences(check: Judgement, t, z, scale, look=None):
    """`Judgement.step_errors` and, first, ``|d_k,i|`` of every step and component (rows; the
    screen's where it passed)."""
    tol = check.tolerance
    limit = tol.rtol * scale + (tol.atol or 0.0)
    steps = t.size - 1
    if look is not None:
        d = np.abs(look[0])
        d_all = d
        local = row_max(d)
        relative = row_max_ratio(d, scale)
        ratio = row_max_ratio(d, limit)
    else:
        local, relative, ratio = np.full(steps, np.inf), np.zeros(steps), np.zeros(steps)
        d_all = np.full((steps, z.shape[1]), np.inf)
    todo = np.flatnonzero(~(ratio <= CANDIDATE)) if look is not None else \
        np.arange(steps)
    if todo.size:
        flows = short_flows(check.system, compiler=check.compiler, cache_dir=check.cache_dir)
        phi, _, _ = flows(t[todo], z[todo], t[todo + 1] - t[todo], check.theta,
                          REFERENCE_SHARE * limit)
        d = np.abs(z[todo + 1] - phi)
        d_all = d_all.copy() if look is not None else d_all
        d_all[todo] = d
        with np.errstate(invalid="ignore"):
            local[todo] = row_max(d)
            relative[todo] = row_max_ratio(d, scale)
            ratio[todo] = row_max_ratio(d, limit)
    return d_all, local, relative, ratio


def screened_errors(check: Judgement, t, z, scale, look=None):
    """`Judgement.step_errors` as its callers read it: ``(local, relative_max, steps, relative,
    ratio)``, ``local`` every step's ``|d_k|_inf``, ``relative_max`` the largest
    ``max_i |d_k,i| / S_i`` and ``relative``, ``ratio`` those of the ``steps`` (indices)
    whose ratio may pass ``CANDIDATE`` times the bound; every other step's ratio is at
    most ``CANDIDATE`` (it passes any test against a bound at or above it). With the
    compiled pass (``exact/kernel.py``) the screen is read without a division per entry:
    ``|d| <= CANDIDATE * bound`` (a step past it is measured as `step_errors` measures
    it), and the largest ratio to ``S`` is the largest column maximum over ``S``
    (rounding is monotone: the same number, whichever order); the same figures."""
    kernel = check.kernel() if look is not None else None
    if kernel is None or not kernel.table_readable(look[0]):
        local, relative, ratio = check.step_errors(t, z, scale, look)
        return local, float(np.max(relative, initial=0.0)), np.arange(ratio.size), \
            relative, ratio
    tol = check.tolerance
    limit = tol.rtol * scale + (tol.atol or 0.0)
    # a step within it has ratio <= CANDIDATE (one ulp below: never a step past it)
    local, colmax, steps = kernel.screen_steps(look[0], np.nextafter(CANDIDATE * limit, 0))
    if not steps.size:  # every step within the screen's bound (the usual case)
        return local, float(np.max(colmax / scale, initial=0.0)), steps, \
            np.zeros(0), np.zeros(0)
    d = np.abs(look[0][steps])
    with np.errstate(invalid="ignore"):
        relative, ratio = row_max_ratio(d, scale), row_max_ratio(d, limit)
    todo = np.flatnonzero(~(ratio <= CANDIDATE))
    if todo.size:  # past the screen: against the exact flow, as `step_differences`
        k = steps[todo]
        flows = short_flows(check.system, compiler=check.compiler, cache_dir=check.cache_dir)
        phi, _, _ = flows(t[k], z[k], t[k + 1] - t[k], check.theta,
                          REFERENCE_SHARE * limit)
        d = np.abs(z[k + 1] - phi)
        with np.errstate(invalid="ignore"):
            local[k] = row_max(d)
            relative[todo] = row_max_ratio(d, scale)
            ratio[todo] = row_max_ratio(d, limit)
    relative_max = float(np.max(np.concatenate([colmax / scale, relative]), initial=0.0))
    return local, relative_max, steps, relative, ratio


def table_extremes(check: Judgement, values):
    """`columns.column_extremes` of a table, in one compiled pass where there is one."""
    kernel = check.kernel()
    if kernel is not None and kernel.table_readable(values):
        return kernel.column_extremes(values)
    return column_extremes(values)


def energy_varies(system) -> bool:
    """Whether ``H`` changes along the exact motion: it depends on ``t``, or the constraints
    do (then they do work on the system); the nodal drift test is for the others."""
    return bool(getattr(system, "energy_varies", system.time_dependent))


class Scan:
    """The trajectory error's scan over windows of nodes, in order: each window's nodes
    against the reference's states there and the reference's own claimed error (units of the
    nodes' scales), until the first node whose error passes ``tol`` (the drift) or whose
    reference is lost (non-finite, or its claim above ``REFERENCE_SHARE * tol``).

    The scales are those of every node of the run (``extent``) and of the reference's states
    up to the drift (an orbit the reference follows off to infinity after the drift must not
    shrink the error). They only grow as states are seen, so a window that passed stays
    passed; within the window that drifts they are found by a few passes (the first node past
    ``tol`` only moves later as they grow). Per component, the largest difference and its node
    are kept, so the largest error in the final scales needs no second look at the nodes."""

    def __init__(self, extent: Extent, n: int, tol: float, kernel=None):
        self.extent, self.n, self.tol = extent, n, tol
        self.kernel = kernel  # the compiled passes (``exact/kernel.py``), or None: numpy
        d = extent.low.size
        self.low, self.high = extent.low.copy(), extent.high.copy()
        self.largest = extent.largest.copy()
        self.column_max, self.column_node = np.zeros(d), np.ones(d, dtype=int)
        self.claim_max = 0.0
        self.drift: int | None = None  # node indices
        self.lost: int | None = None
        self.until = 0
        # their times (a streamed scan no longer holds the nodes, `streaming.py`)
        self.column_t = np.zeros(d)
        self.times = {"drift": None, "lost": None, "until": None}

    @property
    def stopped(self) -> bool:
        return self.drift is not None or self.lost is not None

    def scales(self) -> np.ndarray:
        return motion_scales(self.low, self.high, self.largest, self.n, self.extent.free,
                             self.extent.turns)

    def measure(self, t, z, start: int, end: int, states, claim, offset: int = 0) -> None:
        """Nodes ``start + 1 .. end`` against ``states`` (rows) with the claim ``claim``
        (``offset``: the index in the run of row 0 of ``t`` and ``z``)."""
        rows = z[start + 1:end + 1]
        # one pass over every entry where all are finite (as a row maximum: 2d passes)
        finite = np.True_ if np.isfinite(states).all() else np.isfinite(row_max_abs(states))
        lost = np.flatnonzero(~finite | ~(claim <= REFERENCE_SHARE * self.tol))
        lost_at = int(lost[0]) if lost.size else None
        kernel = self.kernel if self.kernel is not None and \
            self.kernel.rows_readable(rows, states) else None
        difference = None
        if kernel is None:
            with np.errstate(invalid="ignore", over="ignore"):
                difference = np.abs(rows - states)
        over_at, stop, seen, peak = self._over(rows, states, difference, lost_at, kernel)
        if lost_at is not None and (over_at is None or lost_at <= over_at):
            stop, self.lost = lost_at, offset + start + 1 + lost_at
            self.times["lost"] = float(t[start + 1 + lost_at])
        else:
            self.drift = None if over_at is None else offset + start + 1 + over_at
            if over_at is not None:
                self.times["drift"] = float(t[start + 1 + over_at])
        if stop:
            np.minimum(self.low, seen[0], out=self.low)
            np.maximum(self.high, seen[1], out=self.high)
            np.maximum(self.largest, seen[2], out=self.largest)
            if peak is not None:  # the compiled pass's, over the same rows
                node, value = peak
            else:
                node = column_argmax(difference[:stop])
                value = difference[node, np.arange(difference.shape[1])]
            better = value > self.column_max
            self.column_max[better] = value[better]
            self.column_node[better] = offset + start + 1 + node[better]
            self.column_t[better] = t[start + 1 + node[better]]
            self.claim_max = max(self.claim_max, float(np.max(claim[:stop])))
        self.until = offset + start + stop  # the last node measured
        self.times["until"] = float(t[start + stop])

    def _over(self, rows, states, difference, lost_at, kernel):
        """``(over_at, stop, seen, peak)``: the first row whose error passes ``tol`` in the
        scales grown by the states up to it (or ``None``), the rows measured (to it, or to the
        lost one), `column_extremes` of their states and, from the compiled pass
        (``exact/kernel.py``, the same numbers; ``None`` from numpy's), `column_argmax` of
        their ``|rows - states|`` with its values. The scales are found by a few passes (the
        first row past ``tol`` only moves later as they grow); the compiled pass reads the
        rows only up to the first over, the numpy one (``difference``: ``|rows - states|``)
        all of them."""
        scale, over_at, seen, stop, peak = self.scales(), None, None, rows.shape[0], None
        limit = rows.shape[0] if lost_at is None else lost_at
        for _ in range(8):
            if kernel is not None:
                over_at, extremes = kernel.scan_rows(rows, states, scale, self.tol, limit)
                stop = limit if over_at is None else over_at + 1
                if stop == 0:
                    break
                low, high, *peak = extremes
                seen = (low, high, np.maximum(np.abs(low), np.abs(high)))
            else:
                with np.errstate(invalid="ignore"):
                    error = row_max_ratio(difference, scale)
                over = np.flatnonzero(~(error <= self.tol))
                over_at = int(over[0]) if over.size else None
                stop = min(over_at + 1 if over_at is not None else error.size, limit)
                if stop == 0:
                    break
                seen = column_extremes(states[:stop])  # finite: the rows before a lost one
            if over_at is None:
                # no row over: the grown scales (never smaller, `motion_scales`) make every
                # error smaller or equal (rounding is monotone), so another pass finds the
                # same rows and the same extremes
                break
            new = motion_scales(np.minimum(self.low, seen[0]), np.maximum(self.high, seen[1]),
                                np.maximum(self.largest, seen[2]), self.n, self.extent.free,
                                self.extent.turns)
            if np.array_equal(new, scale):
                break
            scale = new
        return over_at, stop, seen, peak

    def figures(self, t0: float, estimate: str) -> dict:
        """The scan's figures (``t0``: the time of node 0); ``drift`` is a node index, with
        its time ``drift_t``."""
        scale = self.scales()
        relative = self.column_max / scale
        i = int(np.argmax(relative))
        measured = self.until > 0
        lost = self.lost is not None
        # a lost reference: the run is drifted from there (its error cannot be measured on)
        return {"scale": scale, "drift": self.lost if lost else self.drift,
                "drift_t": self.times["lost"] if lost else self.times["drift"],
                "lost": self.times["lost"],
                "error_max": float(relative[i]) if measured else 0.0,
                "error_max_t": float(self.column_t[i]) if measured else None,
                "reference_error": self.claim_max,
                "until": self.times["until"] if measured else float(t0),
                "estimate": estimate}


def whole_run(scan: Scan, t, z, states) -> dict:
    """The figures of a scan against an exact solution known at every node (``states``, rows
    from node 0): where it drifted the scan stopped there, but the largest error over the whole
    run costs one more pass over the nodes, so ``error_max`` is that (in the scan's scales) and
    the error is measured to the run's end."""
    found = scan.figures(t[0], "exact solution")
    if scan.drift is None:
        return found
    with np.errstate(invalid="ignore", over="ignore"):
        error = row_max_ratio(np.abs(z - states), found["scale"])
    if not np.all(np.isfinite(error)):
        return found
    k = int(np.argmax(error))
    if error[k] > found["error_max"]:
        found.update(error_max=float(error[k]), error_max_t=float(t[k]))
    found["until"] = float(t[-1])
    return found


def measured_past_drift(verdict: Verdict) -> bool:
    """Whether a drifted verdict's ``error_max`` is the largest over the whole run (an exact
    solution known at every node, a higher-order run's reference) rather than the error where
    the scan stopped, at ``t_drift`` (a reference flow is integrated only that far)."""
    return verdict.reference_until is not None and verdict.t_drift is not None and \
        verdict.reference_until != verdict.t_drift


def describe(verdict: Verdict) -> str:
    """The verdict in words, with the figure that decided it."""
    if verdict.inaccurate:
        failure = verdict.first_failure
        if failure.detail:
            return f"{failure.test}: {failure.detail}"
        return (f"the {failure.test} of step {failure.step} (from t = "
                f"{failure.t:.10g}) is {failure.value:.3e} > {failure.limit:.3e}")
    if verdict.drifted:
        if verdict.reference_lost is not None:
            return (f"the trajectory error cannot be measured past t = "
                    f"{verdict.reference_lost:.6g} (the reference flow's own error passed "
                    f"its share of the tolerance there: the motion is too sensitive)")
        figure = (f"largest {verdict.error_max:.3e}, at t = {verdict.error_max_t:.6g}"
                  if measured_past_drift(verdict) else
                  f"{verdict.error_max:.3e} there; not measured past it")
        return (f"the trajectory error passes {verdict.global_tol:g} of the motion's size at "
                f"t = {verdict.t_drift:.6g} ({figure})")
    return (f"the trajectory error stays within {verdict.global_tol:g} of the motion's size "
            f"(largest {verdict.error_max:.3e})")


def judge(solution, report: dict | Verdict | None, tolerance: Tolerance, *,
          local_error: np.ndarray | None = None, advice: str = ADVICE) -> Verdict | None:
    """The one place a solve's verdict is set (every family calls it once per solve): the
    check's ``report`` (`Judgement.report`, `StreamingJudgement.report`, ``judge_higher``;
    ``None``: no check was made) as ``solution.verdict``, the steps' ``local_error``, and the
    status of a solve that reached its end: ``inaccurate`` ends it as ``Status.INACCURATE``
    (unless ``tolerance.stop`` is off), ``drifted`` as ``Status.DRIFTED`` when
    ``tolerance.require_accurate`` asks for an accurate trajectory; either way the message says
    what the check found (and, for a failed test, ``advice``)."""
    verdict = report if report is None or isinstance(report, Verdict) else Verdict.of(report)
    if verdict is not None and verdict.steps == 0 and verdict.first_failure is None:
        # a run stopped before its first step (interrupted, a failed first step): nothing was
        # judged, and "accurate" would be a verdict on work not done
        solution.verdict = None
        solution.accuracy_skipped = "the run made no step: there is nothing to judge"
        return None
    if verdict is not None and not solution.success:  # on the steps kept, said so
        verdict = replace(verdict, partial=True)
    solution.verdict = verdict
    if local_error is not None:
        solution.local_error = local_error
    if verdict is None or not solution.success or verdict.accurate:
        return verdict
    words = describe(verdict)
    if verdict.inaccurate and tolerance.stop:
        solution.status = Status.INACCURATE
        detailed = bool(verdict.first_failure.detail)
        solution.message = f"{Status.INACCURATE.value}: {words}" + \
            ("" if detailed or not advice else f"; {advice}")
    elif verdict.drifted and tolerance.require_accurate:
        solution.status = Status.DRIFTED
        solution.message = f"{Status.DRIFTED.value}: {words}"
    else:
        solution.message = f"{solution.message}; {verdict.name}: {words}"
    return verdict


def fixed_ends_report(report: dict | None, t, advice: str = "try more nodes") -> dict | None:
    """The report of a solution with both ends fixed (a boundary-value grid, a transfer, a
    higher-order solve through fixed end nodes) judged against the continuous solution through
    the same ends: a trajectory error past ``global_tol`` is not a phase lost over a long run
    (nothing drifts between two fixed ends) but the grid off that solution, so ``drifted``
    becomes ``inaccurate`` with the test ``trajectory error`` failed at the first step into the
    first node past the tolerance; ``t`` the grid's times."""
    if report is None or report["verdict"] != "drifted":
        return report
    node = int(report["drift_step"])
    step = max(node - 1, 0)
    where = ("" if report.get("error_max_t") is None else
             f", largest at t = {report['error_max_t']:.6g}")
    detail = (f"the grid is {report['error_max']:.3e} of the motion's size off the continuous "
              f"solution through its ends{where} (limit {report['global_tol']:g}, passed from "
              f"t = {report['t_drift']:.6g}): with both ends fixed nothing drifts, the grid is "
              f"too coarse for the motion; {advice}")
    return {**report, "verdict": "inaccurate", "first_failure": {
        "step": step, "t": float(np.asarray(t, float)[step]), "test": "trajectory error",
        "value": float(report["error_max"]), "limit": float(report["global_tol"]),
        "detail": detail}}


def assess(system, t, z, theta, tolerance: Tolerance, *, level=None, compiler=None,
           cache_dir=None, exact=None) -> tuple[dict, np.ndarray]:
    """The accuracy check on a finished trajectory of any method (``t`` (N,), ``z`` (N, 2n)):
    the report of `Judgement.report` and the local error of every step. ``level`` is the
    energy level the method keeps, if it keeps one (a `Level`); ``exact``, the motion's
    exact states at given times, if known (``exact(t) -> (N, 2n)``)."""
    return Judgement(system, theta, tolerance, compiler=compiler, cache_dir=cache_dir).report(
        t, z, level=level, exact=exact)
