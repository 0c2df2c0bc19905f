"""The pendulum declared by its Lagrangian L = v^2/2 - (1 - cos q): the paper's case 2.

Same motion as `pendulum` (L = v^2/2 - V gives the same discrete trajectory as H = p^2/2 + V for
every alpha), so the two scenes check each other.
"""

import casadi as ca

from ddvp_nlp import Endpoints, Lagrangian, Scene


def lagrangian(q, v, t):
    return v[0] ** 2 / 2 - (1 - ca.cos(q[0]))


scene = Scene(Lagrangian(lagrangian), n=1, q0=[0.5], p0=[0.5], tau0=0.05, t_end=100.0,
              boundary=Endpoints(q_start=[0.5], q_end=[-0.036], t_span=(0.0, 9.0),
                        nodes=181))
