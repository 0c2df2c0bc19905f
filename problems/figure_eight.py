"""Figure-eight orbit of three equal masses in the plane (G = m = 1; Chenciner-Montgomery 2000).

``H = sum_i |p_i|^2 / 2 - sum_{i<j} 1 / |q_i - q_j|`` with ``q = (x_1, y_1, x_2, y_2, x_3, y_3)``.
Simo's initial data: ``x_1 = -x_2 = (0.97000436, -0.24308753)``, ``x_3 = 0``,
``v_3 = -2 v_1 = -2 v_2 = (-0.93240737, -0.86473146)``; energy -1.287144, period 6.32591398.
"""

import casadi as ca
import numpy as np

from ddvp_nlp import PeriodicSettings, Scene

POSITION = np.array([0.97000436, -0.24308753])
VELOCITY_3 = np.array([-0.93240737, -0.86473146])
ENERGY = -1.287144
PERIOD = 6.32591398


def hamiltonian(q, p, t):
    bodies = [q[2 * i:2 * i + 2] for i in range(3)]
    potential = sum(1 / ca.norm_2(bodies[i] - bodies[j]) for i in range(3)
                    for j in range(i + 1, 3))
    return ca.sumsqr(p) / 2 - potential


q0 = np.concatenate([POSITION, -POSITION, [0.0, 0.0]])
p0 = np.concatenate([-VELOCITY_3 / 2, -VELOCITY_3 / 2, VELOCITY_3])

def momentum_x(q, p):
    return p[0] + p[2] + p[4]


def momentum_y(q, p):
    return p[1] + p[3] + p[5]


def angular_momentum(q, p):
    return sum(q[2 * i] * p[2 * i + 1] - q[2 * i + 1] * p[2 * i] for i in range(3))


# Periodic orbits: body 3 crosses x = 0 at the centre of the eight once per period in each
# direction; the section point at E is looked for along Simo's state. Translations and rotations
# are symmetries (their integrals, conserved exactly by the midpoint rule, get phase conditions).
scene = Scene(hamiltonian, n=6, q0=q0, p0=p0, tau0=0.01, t_end=PERIOD,
              periodic=PeriodicSettings(section="q5=0", energy=ENERGY, nodes=601, start=(q0, p0),
                                        integrals=(momentum_x, momentum_y, angular_momentum)))
