"""Pendulum with a slow periodic perturbation: the paper's section 5 example, exactly.

H = l^2/2 + (1 - cos th)(1 - eps sin(omega t)), th0 = l0 = 0.5, t0 = 0, tau0 = 0.5, to t = 10000.
"""

import casadi as ca

from ddvp_nlp import Scene


def hamiltonian(q, p, t, eps, omega):
    return p[0] ** 2 / 2 + (1 - ca.cos(q[0])) * (1 - eps * ca.sin(omega * t))


scene = Scene(hamiltonian, n=1, params={"eps": 0.1, "omega": 0.02},
              q0=[0.5], p0=[0.5], t0=0.0, tau0=0.5, t_end=10000.0)
