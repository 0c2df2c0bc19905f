"""Spherical pendulum in Cartesian coordinates: a unit mass on a rod of length 1 under unit
gravity, held by g = x^2 + y^2 + z^2 - 1 = 0. H = |p|^2/2 + z.

The default start is the Hairer-Lubich-Wanner experiment, q0 = (0, sin 0.1, -cos 0.1),
p0 = (0.06, 0, 0). `ddvp periodic spherical_pendulum --energy E` finds the conical orbit at E
(-1 < E): the start below lies on the circle at polar angle 0.6 and is scaled to the energy
(docs/periodic/constrained.md); E = -0.632189265 is the cone at 0.6 itself.
"""

from math import cos, sin

from ddvp_nlp import PeriodicSettings, Scene


def hamiltonian(q, p, t):
    return (p[0] ** 2 + p[1] ** 2 + p[2] ** 2) / 2 + q[2]


def rod(q, t):
    return q[0] ** 2 + q[1] ** 2 + q[2] ** 2 - 1


scene = Scene(hamiltonian, n=3, q0=[0.0, sin(0.1), -cos(0.1)], p0=[0.06, 0.0, 0.0], tau0=0.01,
              t_end=20.0, scheme="fixed", constraints=rod,
              periodic=PeriodicSettings(section="q2=0", energy=-0.6321892651083592, nodes=81,
                                        start=([sin(0.6), 0.0, -cos(0.6)], [0.0, 1.0, 0.0])))
