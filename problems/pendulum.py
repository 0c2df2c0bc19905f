"""Autonomous pendulum H = p^2/2 + 1 - cos q (separatrix at H = 2)."""

import casadi as ca

from ddvp_nlp import Scene


def hamiltonian(q, p, t):
    return p[0] ** 2 / 2 + 1 - ca.cos(q[0])


# Periodic orbits (ddvp periodic): librations through the turning point p = 0; exact period
# 4 K(k), k = sin(theta_max / 2), cos(theta_max) = 1 - E, for 0 < E < 2. q is an angle
# ("angles"): above the separatrix (E > 2) the rotations close with q_N = q_0 + 2 pi, on the
# section q1=0 (p = 0 is never reached there); exact period 4 K(2 / E) / sqrt(2 E) (scipy's
# parameter m = k^2).

# Fixed-endpoint data: about where the motion from (0.5, 0.5) is at t = 9 (1.4 swings), where
# q(9) depends strongly on p(0) (at t = 10 it has a fold near p(0) = 0.5).
scene = Scene(hamiltonian, n=1, q0=[0.5], p0=[0.5], tau0=0.05, t_end=100.0,
              boundary={"q_start": [0.5], "q_end": [-0.036], "t_span": (0.0, 9.0),
                        "nodes": 181},
              periodic={"section": "p1=0", "energy": 0.5, "nodes": 200, "angles": ("q1",)})
