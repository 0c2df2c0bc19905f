"""Spherical pendulum in Cartesian coordinates: a unit mass on a rod of length 1 under unit
gravity, held by g = x^2 + y^2 + z^2 - 1 = 0. H = |p|^2/2 + z.

The default start is the Hairer-Lubich-Wanner experiment, q0 = (0, sin 0.1, -cos 0.1),
p0 = (0.06, 0, 0). `ddvp periodic spherical_pendulum --energy E` (E > -1) finds the conical
orbit at E: `cone` gives its polar angle theta0 (E = sin^2 theta0 / (2 cos theta0) - cos theta0,
w^2 = 1 / cos theta0) and one period of it as the guess (docs/periodic/constrained.md).
"""

import numpy as np

from ddvp_nlp import PeriodicSettings, Scene


def hamiltonian(q, p, t):
    return (p[0] ** 2 + p[1] ** 2 + p[2] ** 2) / 2 + q[2]


def rod(q, t):
    return q[0] ** 2 + q[1] ** 2 + q[2] ** 2 - 1


def cone(energy):
    """One period of the conical orbit at ``energy`` (41 points), starting on ``y = 0``."""
    if not energy > -1.0:
        raise ValueError(f"no conical orbit at E = {energy!r}: the least energy is -1, the "
                         "pendulum at rest at the bottom; a cone needs E > -1")
    from scipy.optimize import brentq  # here, not at the top: `ddvp scenes` loads this file

    theta0 = brentq(lambda a: np.sin(a) ** 2 / (2 * np.cos(a)) - np.cos(a) - energy,
                    0.0, np.pi / 2 - 1e-9)
    w = 1 / np.sqrt(np.cos(theta0))
    t = np.linspace(0.0, 2 * np.pi / w, 41)
    s, c = np.sin(theta0), np.cos(theta0)
    q = np.column_stack([s * np.cos(w * t), s * np.sin(w * t), -c * np.ones_like(t)])
    p = np.column_stack([-s * w * np.sin(w * t), s * w * np.cos(w * t), np.zeros_like(t)])
    return {"t": t, "q": q, "p": p}


scene = Scene(hamiltonian, n=3, q0=[0.0, np.sin(0.1), -np.cos(0.1)], p0=[0.06, 0.0, 0.0],
              tau0=0.01, t_end=20.0, scheme="fixed", constraints=rod,
              periodic=PeriodicSettings(section="q2=0", energy=-0.6321892651083592, nodes=81,
                                        guess=cone))
