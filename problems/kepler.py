"""Kepler problem H = |p|^2/2 - 1/|q| with eccentricity e (period 2 pi), over ten periods."""

import casadi as ca
import numpy as np

from ddvp_nlp import Scene


def hamiltonian(q, p, t, e):
    return ca.sumsqr(p) / 2 - 1 / ca.norm_2(q)


def angular_momentum(q, p, e):
    return q[:, 0] * p[:, 1] - q[:, 1] * p[:, 0]


scene = Scene(hamiltonian, n=2, params={"e": 0.5},
              q0=lambda e: [1 - e, 0.0], p0=lambda e: [0.0, np.sqrt((1 + e) / (1 - e))],
              tau0=0.01, t_end=20 * np.pi, invariants={"angular_momentum": angular_momentum})
