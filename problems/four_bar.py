"""Closed four-bar linkage in Cartesian coordinates, lying on a table: a crank of length 1 and a
rocker of 2.5 pinned to the ground at (0, 0) and (3, 0), joined by a coupler of 3; unit masses at
the two moving joints B = (q0, q1) and C = (q2, q3), held by three rods (docs/constraints.md).

H = |p|^2 / 2 with g = (|B|^2 - 1, |C - B|^2 - 9, |C - (3, 0)|^2 - 6.25): a Grashof crank-rocker
(shortest + longest = 4 <= 5.5 = the other two), so the crank turns all the way round and the
three rods' Jacobian keeps rank 3 along the motion. The start: crank upright, turning at 2 rad/s,
C on the upper branch with the velocity the rods allow. Without gravity the energy row's c =
|G'nu|^2 / 8 stays positive (measured 1.2 to 30 along the motion), so vddvp marches it.
"""

import numpy as np

from ddvp_nlp import Scene

CRANK, COUPLER, ROCKER, GROUND = 1.0, 3.0, 2.5, 3.0


def hamiltonian(q, p, t):
    return (p[0] ** 2 + p[1] ** 2 + p[2] ** 2 + p[3] ** 2) / 2


def rods(q, t):
    return [q[0] ** 2 + q[1] ** 2 - CRANK ** 2,
            (q[2] - q[0]) ** 2 + (q[3] - q[1]) ** 2 - COUPLER ** 2,
            (q[2] - GROUND) ** 2 + q[3] ** 2 - ROCKER ** 2]


def start(angle, omega):
    """``(q0, p0)`` with the crank at ``angle`` turning at ``omega``: C where the coupler's and
    the rocker's circles meet (the branch above the line B-D), its velocity from the two rods'
    velocity constraints."""
    B = CRANK * np.array([np.cos(angle), np.sin(angle)])
    D = np.array([GROUND, 0.0])
    e = D - B
    length = np.linalg.norm(e)
    along = (COUPLER ** 2 - ROCKER ** 2 + length ** 2) / (2 * length)
    normal = np.array([-e[1], e[0]]) / length
    C = B + along * e / length + np.sqrt(COUPLER ** 2 - along ** 2) * normal
    vB = CRANK * omega * np.array([-np.sin(angle), np.cos(angle)])
    vC = np.linalg.solve(np.array([C - B, C - D]), np.array([(C - B) @ vB, 0.0]))
    return np.concatenate([B, C]).tolist(), np.concatenate([vB, vC]).tolist()


Q0, P0 = start(np.pi / 2, 2.0)

scene = Scene(hamiltonian, n=4, q0=Q0, p0=P0, tau0=0.01, t_end=20.0, constraints=rods)
