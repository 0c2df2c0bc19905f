"""Segments of a periodic orbit for multiple shooting, chosen by the flow's growth, and the exact
orbit read at any times from its segments.

Single shooting asks Newton to close ``phi_T(z_0) = z_0``: on an orbit whose monodromy has a
multiplier ``mu`` its start must be within about ``1/mu`` of the orbit's size times the flow's
accuracy budget, and a discrete orbit's ``O(N^-2)`` error at node 0 is amplified ``mu`` times
before the return (Hill's Lyapunov orbit, ``mu ~ 2000``: the flow from the N = 400 orbit's first
node leaves it by 1e-2 of its size before a fifth of the period). Cut where the flow has grown:
a pilot run of the variational equations from the start over the period gives ``Y(t)`` at every
accepted step; a segment ends at the first step where the flow's Jacobian since its start,
``Y(t) Y(t_c)^-1`` (``Y^-1 = -J Y^T J``: ``Y`` is symplectic), passes ``GROWTH`` in norm. An
orbit whose flow never grows that much (a stable one) is one segment: single shooting, as
before. Each segment's start is the discrete orbit read at its cut (a cubic through its nodes),
not the pilot's state there, which has left the orbit by the growth before it.

The cuts are fractions ``s_j`` of the period, so that the segments scale with the period when
Newton moves it.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from ...physics.hamiltonian import symplectic_weights
from .flow import exact_flow
from .trajectory import concatenate
from .variational import flow_scales, variational_flow

# A segment ends where the flow has stretched something this much since its start.
GROWTH = 10.0
# At most this many segments (a flow growing faster is cut every 1/MAX_SEGMENTS of the period).
MAX_SEGMENTS = 64


def growth_cuts(system, theta, z0, period: float, *, integrals=(), rtol: float,
                growth: float = GROWTH, sizes=None) -> np.ndarray:
    """The cuts ``0 = s_0 < ... < s_S = 1`` (fractions of ``period``) of the orbit through
    ``z0`` where the flow has grown ``growth`` times since the last (module docstring);
    ``[0, 1]`` where the pilot run fails or ``growth`` is infinite. The growth is measured in
    the norm ``|W dz|`` (`physics.hamiltonian.symplectic_weights`), the same in any units of
    length, momentum and time (in the plain norm, ``Y``'s blocks between positions and momenta
    carry the time unit: Hill's Lyapunov orbit was cut into 5 segments in time units of 1 and
    into 25 in time units of ``1e4``); ``sizes``: each coordinate's size for the pilot run's
    tolerance (default `variational.flow_scales`)."""
    integrals = tuple(integrals)
    k, r = 2 * system.n, len(integrals)
    flow = variational_flow(system, integrals)
    z0 = np.asarray(z0, float)
    if sizes is None:
        sizes = flow_scales(system, theta, z0, period)
    weights = symplectic_weights(system, z0, 0.0, np.asarray(theta, float))
    atol = np.concatenate([rtol * np.asarray(sizes, float), np.full(1 + r, rtol)])
    with np.errstate(all="ignore"):
        run = flow.run(np.concatenate([z0, np.zeros(1 + r)]), 0.0, float(period),
                       np.asarray(theta, float), rtol=rtol, atol=atol)
    if not run.success or run.steps < 2 or not np.isfinite(growth):
        return np.array([0.0, 1.0])
    d = k + 1 + r
    times = np.r_[run.t_old, run.t_end]
    states = np.vstack([run.w_old, run.w_end[None, :]])
    n = system.n
    J = np.block([[np.zeros((n, n)), np.eye(n)], [-np.eye(n), np.zeros((n, n))]])
    cuts, inverse = [0.0], np.eye(k)
    for t, w in zip(times[1:-1], states[1:-1], strict=True):
        Y = w[d:].reshape(d, d).T[:k, :k]
        if not np.all(np.isfinite(Y)):
            break
        if np.linalg.norm(weights[:, None] * (Y @ inverse) / weights[None, :], 2) >= growth:
            cuts.append(float(t) / float(period))
            inverse = -J @ Y.T @ J
    cuts = _spaced(np.asarray(cuts + [1.0]))
    return cuts


def _spaced(cuts: np.ndarray) -> np.ndarray:
    """At most ``MAX_SEGMENTS`` segments, none shorter than a quarter of ``1/MAX_SEGMENTS``
    (a sliver merges into its neighbour)."""
    if cuts.size - 1 > MAX_SEGMENTS:
        cuts = np.linspace(0.0, 1.0, MAX_SEGMENTS + 1)
    keep = [0.0]
    for s in cuts[1:-1]:
        if s - keep[-1] >= 0.25 / MAX_SEGMENTS and 1.0 - s >= 0.25 / MAX_SEGMENTS:
            keep.append(float(s))
    return np.asarray(keep + [1.0])


def starts_from_path(t, z, cuts: np.ndarray) -> np.ndarray:
    """The segments' starts ``(S, 2n)`` read from a discrete orbit's nodes ``t``, ``z`` (one
    period, the last node the first shifted) at the cuts' fractions of its period (a cubic
    in time through the nodes); row 0 is node 0 itself."""
    t = np.asarray(t, float) - float(t[0])
    z = np.asarray(z, float)
    times = cuts[:-1] * t[-1]
    states = CubicSpline(t, z, axis=0)(times) if t.size >= 4 else np.column_stack(
        [np.interp(times, t, z[:, j]) for j in range(z.shape[1])])
    states[0] = z[0]
    return states


def exact_path(system, theta, starts: np.ndarray, cuts: np.ndarray, period: float, times,
               *, rtol: float, sizes=None) -> np.ndarray:
    """The exact orbit from its segments' ``starts`` at ``times`` (from node 0's time, in
    ``[0, max(times)]``; the last segment runs on past the period where asked): rows
    ``(q, p)``, from each segment's dense output, at ``rtol`` and ``atol = rtol sizes``
    (default `variational.flow_scales` of the first start over the period)."""
    flow = exact_flow(system)
    times = np.asarray(times, float)
    ends = cuts * float(period)
    ends[-1] = max(ends[-1], float(np.max(times, initial=0.0)))
    if sizes is None:
        sizes = flow_scales(system, theta, starts[0], period)
    atol = rtol * np.asarray(sizes, float)
    parts = [flow.run(start, ends[j], ends[j + 1], np.asarray(theta, float), rtol=rtol,
                      atol=atol) for j, start in enumerate(starts)]
    return concatenate(parts).z(times)
