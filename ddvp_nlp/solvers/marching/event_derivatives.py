"""Derivatives of a march's event times (issue 47): ``march(..., output=Output(events=g),
derivatives=...)`` puts on ``Solution.derivatives.events`` one `EventDerivatives` per event
function, the derivative of every located crossing time ``t*`` in the inputs.

What is differentiated: the crossing the march located, the root ``t*`` of ``g(t, z(t)) = 0``
on its dense output ``z(t)`` (``Solution.at``'s cubic Hermite interpolant, ``dense.locate``),
as a function of ``q0``, ``p0`` and the parameters. The implicit-function theorem on
``G(t*, inputs) = g(t*, z(t*; inputs)) = 0``:

    dt*/dx = -(g_z . D(t*)) / (dg/dt),    dg/dt = g_t + g_z . z'(t*),

with ``D(t*) = dz(T)/dx`` at the fixed time ``T = t*`` (the forward derivative of
``derivatives.py``, step lengths included) and ``z'`` the interpolant's slope there. The
crossing state's derivative follows: ``dz(t*)/dx = D(t*) + z'(t*) dt*/dx``.

``g`` is the user's function of numbers (scipy's convention), not a CasADi expression, so its
partial derivatives ``g_t``, ``g_z`` are fourth-order central differences, each component's
step ``EVENT_STEP`` times its size in the problem (a time by the span, a position by the
largest ``|q_i|`` the march reached, a momentum by the largest ``|p_i|``): truncation
``h^4 |g^(5)| / 30`` about 1e-12 of ``g``'s scale, round-off ``1e-16 / 1e-3``.

Ill-conditioned: a crossing at a tangency, where ``dg/dt`` is small against its parts:
``transversality = |dg/dt| / (|g_t| + |s g_z| |z' / s|)``, ``s`` the state's scales above (so
that it does not depend on the units of ``q`` and ``p``); at most 1 (Cauchy-Schwarz), 0 at a
tangency, where ``dt*`` has no finite value (``g = q_0 - c`` crossed near a turning point of
``q_0``: there ``q_0'`` is small and ``p_0'`` is not). Below ``TANGENCY`` the crossing's derivatives
are ``nan`` and ``ill_conditioned`` says so: no number is passed off there. Between
``TANGENCY`` and ``GRAZING`` the numbers are kept and flagged: near a tangency ``t*`` moves like
the square root of the inputs' distance to it, so in scaled units its first derivative grows
like ``1 / transversality`` and its third like the fifth power of that, and a difference
quotient of relative step ``h`` is off by ``h^2 / transversality^4`` of the derivative: at the
check's ``h = 1e-6`` (``derivative_check.STEP``) that passes the check's allowance ``1e-4``
below ``GRAZING = 1e-2``. A state component whose scale is zero (it never moved from 0) enters
the transversality's size by its own ``|g_z_j z'_j|``, not by a made-up unit scale.

Reverse mode (``gradient(sol, {"event_times": ...})``, ``gradient.py``): ``dt* = w . D(t*)``
with ``w = -g_z / (dg/dt)`` (`EventDerivatives.weights`), so a cotangent ``c`` on the crossing
times is the cotangent ``c w`` on the states at the fixed times ``t*``: the adjoint sweep of
``adjoint.py`` at those times, nothing else. The record keeps ``w`` and the `Solution` keeps
``t_events``: the event functions are not needed again.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...solution import hermite
from .derivatives import march_derivatives

__all__ = ["EVENT_STEP", "GRAZING", "TANGENCY", "EventDerivatives", "event_derivatives",
           "event_partials", "hermite_slope", "transversality_of"]

# The relative step of g's fourth-order differences, and the transversality below which a
# crossing's derivative is refused (module docstring): 1e-3 amplifies the partials' 1e-12
# error to 1e-9 of dt*, at most.
EVENT_STEP = 1e-3
TANGENCY = 1e-3
# The transversality below which a crossing's derivative is flagged (kept): module docstring.
GRAZING = 1e-2


@dataclass
class EventDerivatives:
    """The derivatives of one event function's crossings (module docstring).

    Attributes:
        times: ``dt*/d(input)`` by input name: ``"q0"``, ``"p0"`` ``(K, n)``, ``"params"``
            ``(K, m)``, rows in the order of ``Solution.t_events[i]``.
        states: ``dz(t*)/d(input)``, ``(K, 2n, n)`` / ``(K, 2n, m)``, rows ``(q, p)``.
        transversality: ``(K,)``, ``|dg/dt| / (|g_t| + |s g_z| |z' / s|)`` (module docstring).
        ill_conditioned: ``(K,)``, where ``transversality < GRAZING`` (below ``TANGENCY``
            those rows are ``nan``) or the march's derivative was flagged on the nodes the
            crossing reads.
        weights: ``(K, 2n)``, ``dt*/dz(T)`` at the fixed time ``T = t*``: ``-g_z / (dg/dt)``
            (``nan`` where refused); reverse mode's cotangent on the states (module docstring).
        check: the crossing times' own `DerivativeCheck` (``derivative_check.py``: the two
            perturbed marches of the states' check, their crossings located again), or
            ``None`` where none was made.
    """

    times: dict
    states: dict
    transversality: np.ndarray
    ill_conditioned: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    weights: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    check: object = None


def hermite_slope(t: np.ndarray, z: np.ndarray, f: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``z'(times)`` ``(K, 2n)`` of the cubic Hermite interpolant on nodes ``t``, ``z`` with
    slopes ``f`` (``Solution.at``'s), on the interval ``searchsorted(side="right") - 1``."""
    k = np.clip(np.searchsorted(t, times, side="right") - 1, 0, t.size - 2)
    tau = t[k + 1] - t[k]
    s = ((times - t[k]) / tau)[:, None]
    return ((6 * s**2 - 6 * s) * z[k] + (3 * s**2 - 4 * s + 1) * tau[:, None] * f[k]
            + (6 * s - 6 * s**2) * z[k + 1] + (3 * s**2 - 2 * s) * tau[:, None] * f[k + 1]
            ) / tau[:, None]


def event_partials(event, times: np.ndarray, states: np.ndarray, scales: np.ndarray):
    """``(g_t (K,), g_z (K, 2n))`` of ``event`` (a ``dense.Event``) at the rows ``(times,
    states)``: fourth-order central differences, component ``j`` (0 the time, then ``z``) with
    the step ``EVENT_STEP * scales[j]`` (module docstring)."""
    width = states.shape[1] + 1
    rows = np.hstack([times[:, None], states])
    partials = np.zeros((times.size, width))
    for j in range(width):
        h = EVENT_STEP * scales[j]
        if h == 0.0:
            continue
        values = []
        for shift in (2.0, 1.0, -1.0, -2.0):
            moved = rows.copy()
            moved[:, j] += shift * h
            values.append(event.values(moved[:, 0], moved[:, 1:]))
        partials[:, j] = (8 * (values[1] - values[2]) - (values[0] - values[3])) / (12 * h)
    return partials[:, 0], partials[:, 1:]


def event_derivatives(system, scheme, theta, t, z, f, events, t_events, names,
                      conditioned=None) -> list[EventDerivatives]:
    """One `EventDerivatives` per event of ``events`` (``dense.Event`` records) whose
    crossings are at ``t_events`` (one array each) on the march ``t`` (N,), ``z`` (N, 2n) with
    node slopes ``f`` (N, 2n), at parameters ``theta``, in the inputs ``names``;
    ``conditioned(last) -> bool``: whether the march's derivative is ill-conditioned on the
    nodes ``0..last`` (``derivative_check.conditioning``), ``None``: never."""
    n2 = z.shape[1]
    scales = np.concatenate([[abs(t[-1] - t[0])], np.max(np.abs(z), axis=0)])
    found = []
    for event, times in zip(events, t_events, strict=True):
        times = np.asarray(times, float).ravel()
        D = march_derivatives(system, scheme, theta, t, z, times, names)
        states = _states(t, z, f, times)
        slope = hermite_slope(t, z, f, times) if times.size and t.size > 1 else \
            np.zeros((times.size, n2))
        g_t, g_z = event_partials(event, times, states, scales)
        rate = g_t + np.einsum("kj,kj->k", g_z, slope)
        transversality = transversality_of(g_t, g_z, slope, rate, scales[1:])
        refused = ~(transversality >= TANGENCY)
        weights = -g_z / np.where(refused, 1.0, rate)[:, None]
        weights[refused] = np.nan
        time_rows, state_rows = {}, {}
        for name in names:
            dt = np.einsum("kj,kjd->kd", np.where(refused[:, None], 0.0, weights), D[name])
            dz = D[name] + slope[:, :, None] * dt[:, None, :]
            dt[refused], dz[refused] = np.nan, np.nan
            time_rows[name], state_rows[name] = dt, dz
        flagged = ~(transversality >= GRAZING)
        if conditioned is not None and t.size > 1:
            reads = np.clip(np.searchsorted(t, times, side="right"), 1, t.size - 1)
            flagged |= np.array([bool(conditioned(int(last))) for last in reads], bool)
        found.append(EventDerivatives(time_rows, state_rows, transversality, flagged, weights))
    return found


def transversality_of(g_t, g_z, slope, rate, scales):
    """``|dg/dt| / (|g_t| + |s g_z| |z' / s|)`` over the components with a scale, plus
    ``|g_z_j z'_j|`` for each one without (module docstring); 0 where every part is 0."""
    sized = scales > 0
    s = scales[sized]
    size = (np.abs(g_t)
            + np.linalg.norm(g_z[:, sized] * s, axis=1)
            * np.linalg.norm(slope[:, sized] / s, axis=1)
            + np.sum(np.abs(g_z[:, ~sized] * slope[:, ~sized]), axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(size > 0, np.abs(rate) / size, 0.0)


def _states(t, z, f, times):
    """The dense output at ``times`` (``Solution.at``'s interpolant)."""
    if t.size < 2:
        return np.repeat(z[:1], times.size, axis=0)
    return hermite(t, z, f, np.clip(times, t[0], t[-1]))
