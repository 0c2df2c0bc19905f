"""Henon-Heiles H = |p|^2/2 + (q1^2 + q2^2)/2 + q1^2 q2 - q2^3/3 (escape energy 1/6)."""

import casadi as ca

from ddvp_nlp import PeriodicSettings, Scene


def hamiltonian(q, p, t):
    return ca.sumsqr(p) / 2 + ca.sumsqr(q) / 2 + q[0] ** 2 * q[1] - q[1] ** 3 / 3


# Periodic orbits (ddvp periodic): the family on the axis x = p_x = 0 (an invariant plane),
# through its turning point p_y = 0, up to the escape energy 1/6. "families" (read by
# scripts/pages/periodic_page.py; `ddvp periodic henon_heiles --section q1=0` takes the section, not
# the start) names two two-dimensional families through the section x = 0, each by the start
# direction along which the section's point at E is looked for: the loop orbit (born from the
# circular motion of the linearised 1:1 oscillator, crossing x = 0 at y > 0 moving in -x) and
# the orbit across the axis x = 0 (born from the normal mode along x, crossing x = 0 at y < 0).
# tau0 = 0.02: the trajectory stays within 1e-2 of the motion's size to t = 200 (the accuracy
# check against the reference flow); at the old 0.05 it passed 1e-2 at t = 78.
scene = Scene(hamiltonian, n=2, q0=[0.0, 0.1], p0=[0.35, 0.0], tau0=0.02, t_end=200.0,
              periodic=PeriodicSettings(
                  section="p2=0", energy=0.1, nodes=201, start=([0.0, 1.0], [0.0, 0.0]),
                  families={
                      "loop": PeriodicSettings(section="q1=0", start=([0.0, 1.0], [-1.0, 0.0])),
                      "across": PeriodicSettings(section="q1=0",
                                                 start=([0.0, -0.1], [1.0, 0.0]))}))
