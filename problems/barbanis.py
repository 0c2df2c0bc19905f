"""Barbanis-type potential H = |p|^2/2 + (wx^2 q1^2 + wy^2 q2^2)/2 - eps q1 q2^2.

The generalised Henon-Heiles family ``(x^2 + y^2)/2 + eps (x y^2 + alpha x^3)`` at ``alpha = 0``
(Barbanis's galactic model; Contopoulos, Tzemos and Zanias 2025 write it so), with the two
frequencies free. The defaults ``wx = wy = eps = 1`` lose nothing for ``eps`` (``q -> q / eps``
scales it out); the saddles at ``x = wy^2 / (2 eps)``, ``y = +-wx wy / (eps sqrt 2)`` set the escape
energy ``wx^2 wy^4 / (8 eps^2)``, 1/8 at the defaults. ``H`` is even in ``y`` but not in ``x``: the
section ``x = 0`` has no reversing symmetry, so a search there shoots the whole return map.

Periodic orbits (``ddvp periodic barbanis``): the motion on the x axis (``y = p_y = 0`` is an
invariant plane), a harmonic oscillation of period ``2 pi / wx`` at every energy, through its
turning point ``p_x = 0``.
"""

import casadi as ca
import numpy as np

from ddvp_nlp import PeriodicSettings, Scene


def hamiltonian(q, p, t, wx, wy, eps):
    return (ca.sumsqr(p) / 2 + (wx ** 2 * q[0] ** 2 + wy ** 2 * q[1] ** 2) / 2
            - eps * q[0] * q[1] ** 2)


def axis_period(energy, wx, wy, eps):
    """The period of the motion on the x axis: ``2 pi / wx`` wherever it exists (``E > 0``)."""
    energy = np.asarray(energy, float)
    return np.where(energy > 0, 2 * np.pi / wx, np.nan)


scene = Scene(hamiltonian, n=2, params={"wx": 1.0, "wy": 1.0, "eps": 1.0}, q0=[0.0, 0.2],
              p0=[0.25, 0.0], tau0=0.02, t_end=100.0,
              periodic=PeriodicSettings(section="p1=0", energy=0.1, nodes=201,
                                        start=([1.0, 0.0], [0.0, 0.0]), period=axis_period))
