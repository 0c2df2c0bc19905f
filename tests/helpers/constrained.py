"""Constrained systems for the tests of the constrained exact flow and RATTLE/SHAKE.

STAND-IN until ``HamiltonianSystem(..., constraints=g)`` lands (branch constraints-core):
`with_constraints` attaches ``constraints``, ``n_constraints`` and ``G`` (the CasADi column
``g(q, t, theta)`` in the system's own symbols) to an existing `HamiltonianSystem`, the
interface the core adds. After the merge, replace each call by the real constructor.
"""

import casadi as ca
import numpy as np

from ddvp_nlp import HamiltonianSystem


def with_constraints(system, constraints):
    """``system`` with ``g = constraints(q, t, **params)`` attached (the core's interface)."""
    symbols = {name: system.theta[i] for i, name in enumerate(system.params)}
    G = ca.vec(ca.SX(constraints(system.q, system.t, **symbols)))
    system.constraints, system.n_constraints, system.G = constraints, int(G.numel()), G
    return system


def cartesian_pendulum(length=1.0, mass=1.0, gravity=1.0):
    """``H = |p|^2 / (2 m) + m g y`` on ``x^2 + y^2 = L^2`` (pivot at the origin)."""
    def H(q, p, t, m, grav):
        return (p[0] ** 2 + p[1] ** 2) / (2 * m) + m * grav * q[1]

    def g(q, t, m, grav):
        return q[0] ** 2 + q[1] ** 2 - length ** 2
    system = HamiltonianSystem(H, 2, params={"m": mass, "grav": gravity},
                               name="cartesian_pendulum")
    return with_constraints(system, g)


def pendulum_start(angle, length=1.0, mass=1.0, omega=0.0):
    """``z0`` at angle ``angle`` from the downward vertical, angular velocity ``omega``."""
    s, c = np.sin(angle), np.cos(angle)
    q = np.array([length * s, -length * c])
    v = length * omega * np.array([c, s])
    return np.concatenate([q, mass * v])


def spherical_pendulum():
    """``H = |p|^2 / 2 + z`` on ``|q|^2 = 1`` (Hairer, Lubich, Wanner)."""
    def H(q, p, t):
        return (p[0] ** 2 + p[1] ** 2 + p[2] ** 2) / 2 + q[2]

    def g(q, t):
        return q[0] ** 2 + q[1] ** 2 + q[2] ** 2 - 1
    return with_constraints(HamiltonianSystem(H, 3, name="spherical_pendulum"), g)


def spherical_start():
    """The HLW experiment: ``q0 = (0, sin 0.1, -cos 0.1)``, ``p0 = (0.06, 0, 0)``."""
    return np.array([0.0, np.sin(0.1), -np.cos(0.1), 0.06, 0.0, 0.0])
