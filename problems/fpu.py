"""Fermi-Pasta-Ulam chain with stiff springs (Hairer-Lubich-Wanner I.5), m = 3, stiffness omega.

H = sum p^2/2 + (omega^2/4) sum_i (q_2i - q_2i-1)^2 + sum_i (q_2i+1 - q_2i)^4, q_0 = q_7 = 0.
"""

import casadi as ca
import numpy as np

from ddvp_nlp import Scene

M = 3


def hamiltonian(q, p, t, omega):
    x = ca.vertcat(0, q, 0)  # fixed ends q_0 = q_{2m+1} = 0
    stiff = sum((x[2 * i] - x[2 * i - 1]) ** 2 for i in range(1, M + 1))
    soft = sum((x[2 * i + 1] - x[2 * i]) ** 4 for i in range(M + 1))
    return ca.sumsqr(p) / 2 + omega**2 / 4 * stiff + soft


def initial_q(omega):
    q = np.zeros(2 * M)
    q[0] = (1 - 1 / omega) / np.sqrt(2)
    q[1] = (1 + 1 / omega) / np.sqrt(2)
    return q


def initial_p(omega):
    p = np.zeros(2 * M)
    p[1] = np.sqrt(2)
    return p


# tau0 = 0.0002 (omega tau = 0.01): the trajectory stays within 1e-2 of the motion's size to
# t = 20 (largest 2.1e-3 against the reference flow). The stiff springs' phase error of the
# midpoint rule grows like t omega^3 tau^2 / 12: at the old 0.01 (omega tau = 0.5, the regime
# of Hairer-Lubich-Wanner's energy-exchange experiments) it passed 1e-2 at t = 0.07, every step
# accurate (a drifted run); set tau0=0.01 for those experiments.
scene = Scene(hamiltonian, n=2 * M, params={"omega": 50.0}, q0=initial_q, p0=initial_p,
              tau0=0.0002, t_end=20.0)
