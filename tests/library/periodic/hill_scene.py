"""Hill's lunar problem in the rotating frame (the test fixture of the periodic-orbit search).

With ``p = v + e_z x q`` (canonical momenta) the Hamiltonian is::

    H = (px^2 + py^2)/2 + y px - x py - x^2 + y^2/2 - 1/r,   r = sqrt(x^2 + y^2),

so that ``x'' - 2 y' = 3 x - x / r^3``, ``y'' + 2 x' = -y / r^3`` (Hill's equations) and
``H = (x'^2 + y'^2)/2 - 3 x^2 / 2 - 1/r`` (minus half the Jacobi constant). The libration points
sit at ``x = +-3^(-1/3)``, ``H = -(3/2) 3^(1/3) = -2.1634``. ``H`` is unchanged by the reversing
symmetry ``(x, y, px, py, t) -> (x, -y, -px, py, -t)``, whose fixed set on the section ``y = 0``
is the line ``px = 0`` (orbits crossing the x-axis at right angles).
"""

import casadi as ca

from ddvp_nlp import Scene


def hamiltonian(q, p, t):
    x, y = q[0], q[1]
    return (ca.sumsqr(p) / 2 + y * p[0] - x * p[1] - x ** 2 + y ** 2 / 2
            - 1 / ca.sqrt(x ** 2 + y ** 2))


scene = Scene(hamiltonian, n=2, q0=[0.3, 0.0], p0=[0.0, 2.3], tau0=1e-3, t_end=1.0)
