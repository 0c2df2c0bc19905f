"""A march's derivative carries its own check (issue 47): one directional finite difference of
the discrete map, and the solvability monitor's word on the energy row.

The check: a random direction ``v`` in the inputs differentiated (``q0``, ``p0``, the
parameters), each component scaled by its input's own size in the problem (a position by the
range of ``q_i`` the march covered, a momentum by that of ``p_i``, either by its largest
magnitude where the range is 0, a parameter by its value, a zero one by the largest
parameter's; an input with no size is left out of ``v`` and the record says so); the march run
again from ``x + h v`` and ``x - h v`` (``h = STEP``, no accuracy check, the same scheme, first
step, step control and compilation), and the central difference ``(z(x + h v) - z(x - h v)) /
2h`` at ``t_eval`` compared with the derivative along the moves as floating point made them
(`rounded_moves`). Cost: one pair of marches.

The verdict's tolerance, relative to the largest entry of the difference quotient: the
quotient's own error, which is not the derivative's. Truncation ``h^2 |z'''| / 6``: measured up
to 5e-5 of the derivative at ``h = 1e-6`` (Kepler, ``e = 0.9``, through the pericentre), so
``TRUNCATION = 1e-4``; round-off: each march's nodes solve their equations to Newton's
tolerance (1e-14 of the state's magnitude), ``N`` independent errors add like ``sqrt(N)``, and
the quotient divides by ``2h``: ``1e-14 r sqrt(N) / h``, ``r`` how far the magnitudes exceed
the sizes the steps are taken in (`offset_ratio`: 1 about the origin, ``1e6`` for a swing
offset by ``1e6``). A derivative wrong by more than both (the
frozen-step derivative is off by 1e-3 at ``tau0 = 0.25`` on the pendulum) ``disagrees``;
smaller errors pass this check (the test suite's fourth-order differences hold them to 1e-6).

Ill-conditioned: where the energy row is close to losing its root. The solvability monitor
(``monitors.py``) watches ``w = -8 c(z_k)`` at every node and warns where it changes sign or
``|ln(w_k / w_{k-1})|`` passes ``MONITOR_LIMIT`` (0.5; 0.6-0.9 measured in the steps before a
breakdown, 0.36 at most on a Kepler march at ``e = 0.7`` that runs). The derivative is flagged
where the march warned, or where the largest jump on the nodes the outputs depend on passes
``NEAR = 0.8`` of the limit: there ``dtau_k`` (the energy row's root's derivative) grows
without bound as the root is lost.

Event times (``event_derivatives.py``) have their own check on the same two marches: their
crossings located again, ``(t*(x + h v) - t*(x - h v)) / 2h`` against ``dt* . v`` crossing by
crossing (`event_check`; a crossing refused at a tangency is left out, a count of crossings
that changed is not checked). The quotient's round-off there: a node error ``delta z`` moves a
crossing by ``w . delta z`` (``w = -g_z / (dg/dt)``, the record's weights), at most
``1e-14 sqrt(N) |s w|`` with ``s`` the state's scales, and the bisection leaves a bracket of
adjacent numbers, ``eps |t*|``: both over ``h``, relative to the quotient. Ill-conditioned:
any crossing the record flags (grazing, ``event_derivatives.GRAZING``, or the march's own flag
on the nodes the crossing reads).

A march from ``v0`` is checked in ``v0`` (``velocity_start.py``): its direction's ``v0`` part
is scaled by the largest node-to-node velocity ``|q_{k+1} - q_k| / tau_k`` the march reached,
and the perturbed marches start from ``v0`` again.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..dense import DenseField
from ..options import Output
from .adjoint import reverse_derivatives
from .derivatives import choose_mode, march_derivatives
from .event_derivatives import event_derivatives
from .monitors import MONITOR_LIMIT, MarchMonitor
from .velocity_start import march_names, start_jacobians, to_velocity

__all__ = ["DerivativeCheck", "Derivatives", "Sensitivity", "check_record", "conditioning",
           "directional_check", "event_check", "input_scales", "random_direction",
           "remarch_function"]

# The finite difference's relative step, and the quotient's truncation allowance (docstring).
STEP = 1e-6
TRUNCATION = 1e-4
# Newton's relative tolerance on a node (step_newton.NEWTON_OPTIONS), for the round-off bound.
NEWTON_RELATIVE = 1e-14
# The fraction of the monitor's limit from which a derivative is flagged ill-conditioned.
NEAR = 0.8


@dataclass(frozen=True)
class DerivativeCheck:
    """The check of a derivative (module docstring).

    Attributes:
        verdict: ``"agrees"``, ``"disagrees"`` or ``"not checked"`` (``reason`` says why).
        error: ``max |D v - Q| / max |Q|``, ``D v`` the derivative along ``v``, ``Q`` the
            central difference quotient (``nan`` if not checked).
        tolerance: the quotient's own error bound the verdict uses.
        step: the relative step ``h``; ``direction``: ``v`` by input name.
        ill_conditioned: the energy row is close to losing its root (module docstring);
            ``solvability_jump`` the largest ``|ln(w_k / w_{k-1})|`` on the nodes used
            (``nan`` for the fixed rule, ``inf`` for a change of sign).
        reason: why not checked, or what was left out of the direction; else ``""``.
    """

    verdict: str
    error: float
    tolerance: float
    step: float
    direction: dict = field(repr=False)
    ill_conditioned: bool
    solvability_jump: float
    reason: str = ""


class Derivatives(dict):
    """``d(q, p)(t_eval) / d(input)`` by input name (``"q0"``, ``"p0"``, ``"params"``), as
    ``Solution.derivatives`` holds them; ``mode``: ``"forward"`` or ``"reverse"`` (how they
    were computed); ``check``: their `DerivativeCheck`; ``events``: one
    ``event_derivatives.EventDerivatives`` per event function of ``Output(events=...)`` (the
    crossing times' derivatives), ``None`` without events; ``event_functions``: the event
    functions themselves (``gradient``'s check locates their crossings again)."""

    def __init__(self, values, *, mode: str, check: DerivativeCheck | None = None,
                 events: list | None = None, event_functions: list | None = None):
        super().__init__(values)
        self.mode, self.check, self.events = mode, check, events
        self.event_functions = event_functions


def conditioning(solvability, last_node: int, warning) -> tuple[bool, float]:
    """``(ill_conditioned, largest |ln(w_k / w_{k-1})|)`` over the nodes ``0..last_node``
    (``warning``: the monitor's, counted where its step is one of them)."""
    c = np.asarray(solvability, float)[:last_node + 1]
    warned = warning is not None and int(warning.get("step", 0)) <= last_node
    if c.size < 2:
        return warned, math.nan
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = c[1:] / c[:-1]
        jump = float(np.max(np.where(ratio > 0, np.abs(np.log(np.where(ratio > 0, ratio, 1))),
                                     np.inf)))
    return warned or not jump <= NEAR * MONITOR_LIMIT, jump


def random_direction(inputs: dict, scales: dict, seed: int = 0) -> tuple[dict, str]:
    """A random ``v`` by input name, each component drawn from ``N(0, 1 / d)`` times its scale;
    components without a scale (zero) are left out, named in the returned note."""
    rng = np.random.default_rng(seed)
    d = sum(np.size(value) for value in inputs.values())
    direction, left = {}, []
    for name, value in inputs.items():
        scale = np.asarray(scales[name], float)
        direction[name] = rng.normal(size=np.shape(value)) / math.sqrt(d) * scale
        left += [f"{name}[{j}]" for j in np.flatnonzero(scale == 0)]
    note = f"left out of the direction (no size): {', '.join(left)}" if left else ""
    return direction, note


def input_scales(q, p, theta, t=None) -> dict:
    """Each input's size in the problem (module docstring): a position's and a momentum's the
    range the march covered in it (the largest ``|q_i|``, ``|p_i|`` where it covered none), a
    parameter's its value; ``"v0"`` too where the node times ``t`` are given (the largest
    node-to-node velocity). Ranges, not magnitudes: an origin offset by ``1e6`` made the step
    ``1e6`` times the swing's own ``1e-6``."""
    theta = np.abs(np.asarray(theta, float))
    largest = float(theta.max()) if theta.size else 0.0
    scales = {"q0": _ranges(q), "p0": _ranges(p),
              "params": np.where(theta > 0, theta, largest)}
    if t is not None:
        q = np.asarray(q, float)
        scales["v0"] = (np.max(np.abs(np.diff(q, axis=0) / np.diff(t)[:, None]), axis=0)
                        if len(t) > 1 else np.zeros(q.shape[1]))
    return scales


def _ranges(values) -> np.ndarray:
    values = np.asarray(values, float)
    return np.where(np.ptp(values, axis=0) > 0, np.ptp(values, axis=0),
                    np.max(np.abs(values), axis=0))


def offset_ratio(q, p, scales: dict) -> float:
    """How far the state's magnitudes exceed the sizes the check's steps are taken in,
    ``max_i |z_i| / s_i`` (at least 1): the nodes' round-off is relative to the magnitudes,
    the quotient to the sizes."""
    z = np.hstack([np.asarray(q, float), np.asarray(p, float)])
    size = np.concatenate([scales["q0"], scales["p0"]])
    magnitude = np.max(np.abs(z), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(size > 0, magnitude / size, 1.0)
    return float(max(1.0, np.max(ratio, initial=1.0)))


def rounded_moves(base: dict, direction: dict) -> dict:
    """The moves ``x +- h v`` are made of, per unit step, as floating point rounds them:
    ``((x + h v) - x - ((x - h v) - x)) / 2h``. The derivative predicts the quotient for
    these (``x + h v`` keeps only ``x``'s last place: an end at ``1e6`` rounds a move of
    ``1e-6`` by ``2e-4`` of itself)."""
    moves = {}
    for name, v in direction.items():
        x, v = np.asarray(base[name], float), np.asarray(v, float)
        moves[name] = ((x + STEP * v) - x - ((x - STEP * v) - x)) / (2 * STEP)
    return moves


def directional_check(remarch, inputs: dict, direction: dict, predicted: np.ndarray,
                      nodes: int, *, reduce=None, offset: float = 1.0
                      ) -> tuple[str, float, float, str]:
    """``(verdict, error, tolerance, reason)``: ``remarch(inputs) -> z_eval or None`` at ``x
    +- STEP v``; ``reduce`` maps ``z_eval`` to what ``predicted`` is (a cotangent's scalar);
    ``offset``: `offset_ratio`, which the nodes' round-off is multiplied by."""
    values = []
    for sign in (1.0, -1.0):
        moved = {name: np.asarray(inputs[name], float) + sign * STEP * direction[name]
                 for name in inputs}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            found = remarch(moved)
        if found is None:
            return "not checked", math.nan, math.nan, \
                "a perturbed march did not reach the output times"
        values.append(found if reduce is None else reduce(found))
    quotient = (values[0] - values[1]) / (2 * STEP)
    size = float(np.max(np.abs(quotient)))
    tolerance = TRUNCATION + NEWTON_RELATIVE * offset * math.sqrt(max(nodes, 1)) / STEP
    if size == 0.0:
        return "not checked", math.nan, tolerance, "the difference quotient is zero"
    error = float(np.max(np.abs(np.asarray(predicted) - quotient))) / size
    return ("agrees" if error <= tolerance else "disagrees"), error, tolerance, ""


def remarch_function(march, system, scheme, t_span, tau0: float, steps, compilation, t_eval,
                     events=None):
    """``inputs -> z_eval`` (``(M, 2n)``, ``None`` where the march does not reach the ``M``
    output times) of the march from ``inputs["q0"]``, ``["p0"]`` (or ``["v0"]``) at
    ``["params"]``, without the accuracy check (``march``: the function `march`, given by its
    caller: this module is below it). With ``events`` (the user's functions): ``inputs ->
    (z_eval or None, t_events)``, the crossings located again; each march run once for a given
    ``inputs`` (kept, so that the states' and the events' checks share the two marches)."""
    times = None if t_eval is None or np.size(t_eval) == 0 else t_eval
    done = {}

    def run(inputs):
        key = tuple((name, np.asarray(value, float).tobytes())
                    for name, value in sorted(inputs.items()))
        if key not in done:
            start = {"v0": inputs["v0"]} if "v0" in inputs else {"p0": inputs["p0"]}
            solution = march(system, inputs["q0"], t_span=t_span, tau0=tau0, scheme=scheme,
                             params=dict(zip(system.params, inputs["params"], strict=True)),
                             steps=steps, accuracy=None, compilation=compilation,
                             output=Output(t_eval=times, events=events or None), **start)
            z = solution.z_eval
            reached = z if z is not None and z.shape[0] == np.size(t_eval) else None
            if len(done) >= 2:  # two marches kept at most: the pair of one direction
                done.pop(next(iter(done)))
            done[key] = reached if events is None else (reached, solution.t_events)
        return done[key]
    return run


def check_record(remarch, base: dict, names, predicted_along, q, p, theta, nodes: int,
                 conditioned: tuple[bool, float], *, reduce=None, t=None) -> DerivativeCheck:
    """The `DerivativeCheck` of a derivative in the inputs ``names`` at ``base`` (all three
    inputs, ``v0`` in place of ``p0`` for a march from ``v0``, whose node times ``t`` then
    scale it): ``predicted_along(direction) -> D v``."""
    scales = input_scales(q, p, theta, t)
    direction, note = random_direction({name: base[name] for name in names}, scales)
    full = {name: direction.get(name, np.zeros_like(base[name])) for name in base}
    moves = rounded_moves(base, direction)
    verdict, error, tolerance, reason = directional_check(
        remarch, base, full, predicted_along(moves), nodes, reduce=reduce,
        offset=offset_ratio(q, p, scales))
    return DerivativeCheck(verdict, error, tolerance, STEP, direction, conditioned[0],
                           conditioned[1], "; ".join(part for part in (reason, note) if part))


def event_check(run, base: dict, direction: dict, record, index: int, times, t, scales,
                conditioned) -> DerivativeCheck:
    """The crossing times' `DerivativeCheck` of event ``index`` (module docstring): ``run(x)
    -> (z_eval, t_events)`` at ``x +- STEP v`` (``direction`` ``v`` by input name, the states'
    check's), ``record`` its `EventDerivatives` at the crossings ``times`` of the march with
    nodes ``t``, state scales ``scales`` (2n,); ``conditioned``: ``(flag, jump)`` on the nodes
    the crossings read."""
    moves = rounded_moves(base, direction)
    predicted = sum(record.times[name] @ moves[name] for name in record.times)
    predicted = np.zeros(np.size(times)) if np.isscalar(predicted) else predicted
    ill = bool(np.any(record.ill_conditioned)) or conditioned[0]

    def unchecked(reason, tolerance=math.nan):
        return DerivativeCheck("not checked", math.nan, tolerance, STEP, direction, ill,
                               conditioned[1], reason)
    rows = np.isfinite(predicted)
    if not rows.any():
        return unchecked("no crossing" if predicted.size == 0 else
                         "every crossing is at a tangency (its derivative is nan)")
    moved = []
    for sign in (1.0, -1.0):
        inputs = {name: np.asarray(base[name], float) + sign * STEP * direction.get(
            name, np.zeros(np.shape(base[name]))) for name in base}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            moved.append(np.asarray(run(inputs)[1][index], float))
    if any(found.size != predicted.size for found in moved):
        return unchecked(f"the perturbed marches crossed {moved[0].size} and "
                         f"{moved[1].size} times, against {predicted.size}")
    quotient = (moved[0] - moved[1])[rows] / (2 * STEP)
    size = float(np.max(np.abs(quotient)))
    nodes = np.clip(np.searchsorted(t, np.asarray(times)[rows], side="right") + 1, 1, None)
    moves = np.linalg.norm(record.weights[rows] * scales, axis=1)
    roundoff = NEWTON_RELATIVE * np.sqrt(nodes) * moves \
        + np.finfo(float).eps * np.abs(np.asarray(times)[rows])
    if size == 0.0:
        return unchecked("the difference quotient is zero")
    tolerance = TRUNCATION + float(np.max(roundoff)) / (STEP * size)
    error = float(np.max(np.abs(predicted[rows] - quotient))) / size
    return DerivativeCheck("agrees" if error <= tolerance else "disagrees", error, tolerance,
                           STEP, direction, ill, conditioned[1],
                           "" if rows.all() else f"{int((~rows).sum())} crossing(s) at a "
                                                 f"tangency left out")


class Sensitivity(MarchMonitor):
    """The monitor of ``march(..., derivatives=...)``: watches nothing while the loop runs and
    differentiates the kept nodes at the end (`march_derivatives` forward, or
    ``adjoint.reverse_derivatives``; `choose_mode`) into ``Solution.derivatives``, a
    `Derivatives` with its `DerivativeCheck` (and each event's, on the same two marches); a
    march from ``v0`` in ``v0`` (``velocity_start.py``)."""

    rewatch = False

    def __init__(self, problem, t_eval, names, mode="auto", compilation=None, march=None,
                 events=(), velocity=None):
        self.problem, self.names = problem, names
        self.t_eval = np.zeros(0) if t_eval is None else np.asarray(t_eval, float)
        self.mode, self.compilation, self.march = mode, compilation, march
        self.events = tuple(events or ())
        self.velocity = None if velocity is None else np.asarray(velocity, float)

    @classmethod
    def from_options(cls, session):
        names = getattr(session, "derivatives", ())
        if not names:
            return None
        return cls(session.problem, session.output.t_eval, names,
                   getattr(session, "derivatives_mode", "auto"), session.compilation,
                   getattr(session, "march", None), session.output.events,
                   getattr(session, "start_velocity", None))

    def finish(self, solution, outcome) -> None:
        problem = self.problem
        t, z = solution.t, np.hstack([solution.q, solution.p])
        kept = self.t_eval[self.t_eval <= t[-1]] if t.size else self.t_eval[:0]
        inner = march_names(self.names, self.velocity is not None)
        mode = choose_mode(self.mode, inner, problem.system, kept.size)
        differentiate = march_derivatives if mode == "forward" else reverse_derivatives
        values = differentiate(problem.system, problem.scheme, problem.theta, t, z, kept, inner)
        events = self._events(solution, t, z, inner)
        if self.velocity is not None:  # d/d(q0, v0, params) by the Legendre map's Jacobians
            jacobians = start_jacobians(problem.system, problem.scheme, problem.q0,
                                        self.velocity, problem.p0, t0=problem.t0,
                                        tau0=problem.tau0, theta=problem.theta)
            values = to_velocity(values, jacobians, self.names)
            for record in events or ():
                record.times = to_velocity(record.times, jacobians, self.names)
                record.states = to_velocity(record.states, jacobians, self.names)
        check = self._check(solution, values, kept, events)
        solution.derivatives = Derivatives(
            values, mode=mode, check=check, events=events,
            event_functions=[event.g for event in self.events] if events else None)

    def _events(self, solution, t, z, names):
        """The crossing times' derivatives (``event_derivatives.py``), or ``None``."""
        if not self.events or solution.t_events is None:
            return None
        problem = self.problem
        f = DenseField.of(problem.system, problem.theta)(t, z) if t.size else z.copy()
        warning = solution.march.solvability_warning if solution.march is not None else None
        return event_derivatives(
            problem.system, problem.scheme, problem.theta, t, z, f, self.events,
            solution.t_events, names,
            conditioned=lambda last: conditioning(solution.solvability, last, warning)[0])

    def _check(self, solution, values, kept, events):
        """The derivative's `DerivativeCheck`: one pair of marches (module docstring); each
        event's on the same pair, put on its record."""
        problem, t = self.problem, solution.t
        interval = np.clip(np.searchsorted(t, kept, side="right") - 1, 0, max(t.size - 2, 0))
        last = int(interval.max()) + 1 if kept.size and t.size > 1 else 0
        conditioned = conditioning(solution.solvability, last,
                                   solution.march.solvability_warning)
        start = {"v0": self.velocity} if self.velocity is not None else {"p0": problem.p0}
        base = {"q0": problem.q0, **start, "params": problem.theta}
        if self.march is None:
            return DerivativeCheck("not checked", np.nan, np.nan, 0.0, {}, *conditioned,
                                   "no march to run again (a session without march)")
        run = remarch_function(self.march, problem.system, problem.scheme,
                               (problem.t0, problem.t_end), problem.tau0, problem.steps,
                               self.compilation, kept,
                               [event.g for event in self.events] if events else None)
        remarch = run if not events else (lambda inputs: run(inputs)[0])
        velocity_t = t if self.velocity is not None else None
        if kept.size == 0:
            scales = input_scales(solution.q, solution.p, problem.theta, velocity_t)
            direction, note = random_direction({name: base[name] for name in self.names},
                                               scales)
            check = DerivativeCheck("not checked", np.nan, np.nan, 0.0, direction,
                                    *conditioned, "no output time was reached")
        else:
            check = check_record(
                remarch, base, self.names,
                lambda v: sum(values[name] @ v[name] for name in self.names),
                solution.q[:last + 1], solution.p[:last + 1], problem.theta, last + 1,
                conditioned, t=None if velocity_t is None else t[:last + 1])
        for index, record in enumerate(events or ()):
            record.check = self._event_check(solution, run, base, check.direction, record,
                                             index)
        return check

    def _event_check(self, solution, run, base, direction, record, index):
        """Event ``index``'s `DerivativeCheck` (`event_check`) on the march's two marches."""
        t, times = solution.t, np.asarray(solution.t_events[index], float)
        reads = int(np.searchsorted(t, times[-1], side="right")) if times.size else 0
        conditioned = conditioning(solution.solvability, min(reads, t.size - 1),
                                   solution.march.solvability_warning)
        scales = np.concatenate([np.max(np.abs(solution.q), axis=0),
                                 np.max(np.abs(solution.p), axis=0)])
        full = {name: direction.get(name, np.zeros(np.shape(base[name]))) for name in base}
        return event_check(run, base, full, record, index, times, t, scales, conditioned)
