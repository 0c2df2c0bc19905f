"""Hill's lunar problem in the rotating frame (the limit of the restricted three-body problem near
the smaller primary, scaled so that the primary's mass and the frame's rate are 1)::

    H = (p_x^2 + p_y^2) / 2 + y p_x - x p_y - x^2 + y^2 / 2 - 1 / r,   r = sqrt(x^2 + y^2)

with ``p = v + omega x q``: Hamilton's equations give ``x'' - 2 y' = 3 x - x / r^3`` and
``y'' + 2 x' = -y / r^3`` (Hill 1878; Henon 1969, "Numerical exploration of the restricted problem.
V. Hill's case"). The libration points are at ``x = +-3^(-1/3)``, ``y = 0``, ``p = (0, x)``, at the
energy ``-3^(4/3) / 2 = -2.1633``; each is a saddle times a centre in the plane, and the planar
Lyapunov orbits about them are strongly unstable (a multiplier of about 2000 per period at
``E = -2.14``, where their period is 3.0396555).

Periodic orbits (``ddvp periodic hill``): the Lyapunov family about the libration point at
``x > 0`` on the section ``y = 0``, started from the linearised orbit about it
(`ddvp_nlp.linearised_orbit`) at the prescribed energy.
"""

import casadi as ca

import ddvp_nlp
from ddvp_nlp import PeriodicSettings, Scene

LIBRATION = 3.0 ** (-1.0 / 3.0)


def hamiltonian(q, p, t):
    x, y = q[0], q[1]
    return (ca.sumsqr(p) / 2 + y * p[0] - x * p[1] - x ** 2 + y ** 2 / 2
            - 1 / ca.sqrt(x ** 2 + y ** 2))


def lyapunov_guess(energy_level):
    """The linearised Lyapunov orbit about the libration point at ``x > 0`` whose node 0 on
    ``y = 0`` has ``H = energy_level`` (``{"t", "q", "p"}``)."""
    # ddvp_nlp.linearised_orbit, not imported at the top: the periodic solvers (and scipy) load
    # when a guess is asked for, not when `ddvp scenes` lists this file
    return ddvp_nlp.linearised_orbit(scene.system, energy=energy_level,
                                     equilibrium=[LIBRATION, 0.0, 0.0, LIBRATION], section="q2=0")


scene = Scene(hamiltonian, n=2, q0=[LIBRATION + 0.01, 0.0], p0=[0.0, LIBRATION], tau0=0.01,
              t_end=3.04,
              periodic=PeriodicSettings(section="q2=0", energy=-2.14, nodes=401,
                                        guess=lyapunov_guess))
