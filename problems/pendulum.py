"""Autonomous pendulum H = p^2/2 + 1 - cos q (separatrix at H = 2)."""

import casadi as ca

from ddvp_nlp import Scene


def hamiltonian(q, p, t):
    return p[0] ** 2 / 2 + 1 - ca.cos(q[0])


scene = Scene(hamiltonian, n=1, q0=[0.5], p0=[0.5], tau0=0.05, t_end=100.0)
