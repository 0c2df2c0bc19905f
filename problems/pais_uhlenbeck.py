"""Pais-Uhlenbeck oscillator L = (q'^2 - w^2 q^2)/2 - g q''^2/2, exact solution known.

Its Euler-Lagrange equation g q'''' + q'' + w^2 q = 0 has the frequencies
w_1,2^2 = (1 -/+ sqrt(1 - 4 g w^2)) / (2 g); the scene follows cos(w_1 t) + cos(w_2 t)/10.
"""

import numpy as np

from ddvp_nlp import Endpoints, HigherOrderScene


def lagrangian(q, v, t, w, g):
    return (v[0][0] ** 2 - w**2 * q[0] ** 2) / 2 - g * v[1][0] ** 2 / 2


def frequencies(w, g):
    root = np.sqrt(1 - 4 * g * w**2)
    return np.sqrt((1 - root) / (2 * g)), np.sqrt((1 + root) / (2 * g))


def exact(t, w, g):
    w1, w2 = frequencies(w, g)
    return (np.cos(w1 * t) + np.cos(w2 * t) / 10)[:, None]


# fixed by default: the vddvp march finds no positive step at step 2 (Newton gives
# tau = -0.65); fixed steps follow the exact motion.
scene = HigherOrderScene(lagrangian, n=1, order=2, exact=exact, params={"w": 1.0, "g": 0.1},
                         tau0=0.02, t_end=10.0,
                         boundary=Endpoints(t_span=(0.0, 2.0), nodes=41),
                         scheme="fixed", ranges={"g": "(0, inf)"})
