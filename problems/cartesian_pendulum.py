"""Planar pendulum in Cartesian coordinates: a unit mass on a rod of length 1 under unit gravity,
held by the constraint g = x^2 + y^2 - 1 = 0 (docs/constraints.md).

H = (px^2 + py^2)/2 + y. The default start rotates (speed 3 at the bottom, E = 3.5): the
energy-determined steps of vddvp keep a positive root on rotations with E > 2; a libration
needs --scheme fixed (docs/theory.md, constrained steps).
"""

from ddvp_nlp import PeriodicSettings, Scene


def hamiltonian(q, p, t):
    return (p[0] ** 2 + p[1] ** 2) / 2 + q[1]


def rod(q, t):
    return q[0] ** 2 + q[1] ** 2 - 1


# `ddvp periodic cartesian_pendulum --energy E` (-1 < E < 0): the libration through the bottom,
# closed on the turning point p1 = 0 (docs/periodic/constrained.md)
scene = Scene(hamiltonian, n=2, q0=[0.0, -1.0], p0=[3.0, 0.0], tau0=0.01, t_end=20.0,
              constraints=rod,
              periodic=PeriodicSettings(section="p1=0", energy=-0.5, nodes=161,
                                        start=([0.0, -1.0], [1.0, 0.0])))
