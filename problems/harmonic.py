"""Harmonic oscillator H = (p^2 + w^2 q^2)/2, with its exact solution."""

import numpy as np

from ddvp_nlp import PeriodicSettings, Scene


def hamiltonian(q, p, t, w):
    return (p[0] ** 2 + w**2 * q[0] ** 2) / 2


def exact(t, q0, p0, t0, w):
    elapsed = np.asarray(t) - t0
    phase = w * elapsed
    # sin(w t)/w, which is t at w = 0 (a free particle)
    q = q0[0] * np.cos(phase) + p0[0] * (np.sin(phase) / w if w != 0 else elapsed)
    p = -q0[0] * w * np.sin(phase) + p0[0] * np.cos(phase)
    return q[:, None], p[:, None]


def period(energy, w):
    """The exact period 2 pi / w, the same at every energy."""
    return np.full(np.shape(energy), 2 * np.pi / w)


# Periodic orbits (ddvp periodic): period 2 pi / w at every energy.
scene = Scene(hamiltonian, n=1, params={"w": 1.0}, q0=[1.0], p0=[0.0], tau0=0.1, t_end=20.0,
              exact=exact,
              periodic=PeriodicSettings(section="p1=0", energy=0.5, nodes=201, period=period))
