"""Pendulum with a slow periodic perturbation: the paper's section 5 example, exactly.

H = l^2/2 + (1 - cos th)(1 - eps sin(omega t)), th0 = l0 = 0.5, t0 = 0, tau0 = 0.5, to t = 10000.
"""

import casadi as ca

from ddvp_nlp import Endpoints, Scene


def hamiltonian(q, p, t, eps, omega):
    return p[0] ** 2 / 2 + (1 - ca.cos(q[0])) * (1 - eps * ca.sin(omega * t))


# Fixed-endpoint data: about where the motion from (0.5, 0.5) is at t = 9 (1.4 swings), where
# q(9) depends strongly on p(0).
scene = Scene(hamiltonian, n=1, params={"eps": 0.1, "omega": 0.02},
              q0=[0.5], p0=[0.5], t0=0.0, tau0=0.5, t_end=10000.0,
              boundary=Endpoints(q_start=[0.5], q_end=[-0.0065], t_span=(0.0, 9.0),
                        nodes=91))
