"""The size of a motion in each coordinate's own units, for limits that must follow the units.

A coordinate's span over the nodes is its size, except on a coordinate that does not move: an
orbit in an invariant plane (Henon-Heiles along ``q1 = p1 = 0``) carries in the other
coordinates only the round-off of the linear solves, ``1e-46`` on that orbit, and a limit of
``tol`` times that span refuses every point. Such a coordinate's size is read off the others
through the two facts that hold in any units: every pair ``(q_i, p_i)`` carries action (``q_i
p_i`` has the units of ``H`` times time for every ``i``), and the flow converts a momentum into
a position over time (``dq_i/dt = dH/dp_i``). The motion's action ``S = max_j span(q_j)
span(p_j)`` and the ratio ``r_i = T |d2H/dp_i2|`` (units ``q_i / p_i``; ``T`` the motion's time
scale) give the sizes ``sqrt(S r_i)`` and ``sqrt(S / r_i)`` that pair ``i`` would have with the
motion's action; a coordinate's size is the larger of its span and that. Under a change of units
of any coordinate, of time, or a shift of the origin, every size follows its coordinate.
"""

from __future__ import annotations

import numpy as np

from ...physics.hamiltonian import flow_jacobian_function


def motion_sizes(system, theta, t: np.ndarray, z: np.ndarray, time_scale: float) -> np.ndarray:
    """``(2n,)``: the size of the motion ``(t, z)`` (nodes ``z = (q, p)``, ``(M, 2n)``) in
    each coordinate (module docstring); ``time_scale``: the motion's own (a period over
    ``2 pi``, a horizon)."""
    z = np.asarray(z, float)
    n = z.shape[1] // 2
    span = np.ptp(z, axis=0)
    action = float(np.max(span[:n] * span[n:]))
    if not action > 0 or not np.isfinite(action):
        return span
    f_A = flow_jacobian_function(system)
    picks = np.unique(np.linspace(0, z.shape[0] - 1, min(z.shape[0], 9)).astype(int))
    # |d2H/dp_i2| = |dq_i'/dp_i|, the median over a few nodes
    with np.errstate(all="ignore"):
        samples = [np.abs(np.diagonal(np.asarray(f_A(z[k], float(np.asarray(t)[k]), theta)[1],
                                                 float)[:n, n:])) for k in picks]
    samples = np.asarray(samples)
    samples[~np.isfinite(samples)] = 0.0
    mobility = np.median(samples, axis=0)
    ratio = time_scale * mobility  # q_i per p_i
    bridged = np.zeros(2 * n)
    live = ratio > 0
    bridged[:n][live] = np.sqrt(action * ratio[live])
    bridged[n:][live] = np.sqrt(action / ratio[live])
    return np.maximum(span, bridged)


def orbit_sizes(system, theta, t: np.ndarray, z: np.ndarray) -> np.ndarray:
    """`motion_sizes` of one period of an orbit, on the time scale of its period over
    ``2 pi``."""
    return motion_sizes(system, theta, t, z, float(t[-1] - t[0]) / (2 * np.pi))


def energy_rate(t: np.ndarray, z: np.ndarray) -> float:
    """The rate at which a motion ``(t, z)`` (nodes ``z = (q, p)``) trades energy: ``sum_i max
    |dq_i/dt| max |dp_i/dt|``, read off the nodes' differences; in the units of ``H`` per time
    whatever the coordinates' (an offset of ``H`` or of the origin leaves it as it is)."""
    t, z = np.asarray(t, float), np.asarray(z, float)
    n = z.shape[1] // 2
    tau = np.diff(t)
    step = np.where(tau != 0, np.abs(tau), np.inf)[:, None]
    rates = np.max(np.abs(np.diff(z, axis=0)) / step, axis=0)
    return float(np.sum(rates[:n] * rates[n:]))


def energy_traded(t: np.ndarray, z: np.ndarray, time_scale: float) -> float:
    """The energy a motion ``(t, z)`` trades over ``time_scale`` (`energy_rate` times it)."""
    return energy_rate(t, z) * time_scale
