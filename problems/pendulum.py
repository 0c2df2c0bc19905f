"""Autonomous pendulum H = p^2/2 + 1 - cos q (separatrix at H = 2), with its exact librations."""

import casadi as ca
import numpy as np
from scipy.special import ellipj, ellipk, ellipkinc

from ddvp_nlp import Endpoints, PeriodicSettings, Scene


def hamiltonian(q, p, t):
    return p[0] ** 2 / 2 + 1 - ca.cos(q[0])


def exact(t, q0, p0, t0):
    """The exact libration from (q0, p0) (0 < H < 2) by Jacobi's elliptic functions:
    ``sin(q/2) = k sn(u, k^2)``, ``p = 2 k cn(u, k^2)``, ``u = t - t0 + u0``, ``k^2 = H/2``.
    ``ValueError`` at or above the separatrix (the studies then use DOP853)."""
    q0, p0 = float(np.ravel(q0)[0]), float(np.ravel(p0)[0])
    energy = p0**2 / 2 + 1 - np.cos(q0)
    if not 0 < energy < 2 or abs(q0) >= np.pi:
        raise ValueError(f"the exact solution covers librations (0 < H < 2, |q| < pi); "
                         f"H = {energy:g}, q0 = {q0:g}")
    m = energy / 2
    k = np.sqrt(m)
    amplitude0 = np.arctan2(np.sin(q0 / 2) / k, p0 / (2 * k))  # am(u0): sn = sin, cn = cos
    quarter = ellipk(m)
    u = np.mod(ellipkinc(amplitude0, m) + np.asarray(t, float) - t0, 4 * quarter)
    sn, cn, _, _ = ellipj(u, m)
    return (2 * np.arcsin(np.clip(k * sn, -1, 1)))[:, None], (2 * k * cn)[:, None]


def libration_period(energy):
    """The exact period of the libration at energy E: ``4 K(k)``, ``k^2 = E / 2`` (scipy's
    parameter ``m = k^2``), for 0 < E < 2; NaN elsewhere (no libration)."""
    energy = np.asarray(energy, float)
    inside = (energy > 0) & (energy < 2)
    return np.where(inside, 4 * ellipk(np.where(inside, energy, 1.0) / 2), np.nan)


def rotation_period(energy):
    """The exact time of one turn at energy E > 2: ``int_0^{2 pi} dq / sqrt(2 (E - 1 + cos q))
    = 4 K(2 / E) / sqrt(2 E)``; NaN at E <= 2 (no rotation)."""
    energy = np.asarray(energy, float)
    inside = energy > 2
    safe = np.where(inside, energy, 4.0)
    return np.where(inside, 4 * ellipk(2 / safe) / np.sqrt(2 * safe), np.nan)


# Periodic orbits (ddvp periodic): librations through the turning point p = 0 (E < 2). q is an
# angle ("angles"): above the separatrix (E > 2) the rotations close with q_N = q_0 + 2 pi, on
# the section q1=0 (p = 0 is never reached there): the family "rotations".

# Fixed-endpoint data: about where the motion from (0.5, 0.5) is at t = 9 (1.4 swings), where
# q(9) depends strongly on p(0) (at t = 10 it has a fold near p(0) = 0.5).
scene = Scene(hamiltonian, n=1, q0=[0.5], p0=[0.5], tau0=0.05, t_end=100.0, exact=exact,
              boundary=Endpoints(q_start=[0.5], q_end=[-0.036], t_span=(0.0, 9.0),
                        nodes=181),
              periodic=PeriodicSettings(
                  section="p1=0", energy=0.5, nodes=201, angles=("q1",),
                  period=libration_period,
                  families={"rotations": PeriodicSettings(section="q1=0", energy=3.0,
                                                          angles=("q1",),
                                                          period=rotation_period)}))
