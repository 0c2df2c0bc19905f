"""The averaged vector field (AVF) equation (Quispel and McLaren 2008), written once.

For ``z = (q, p)`` and ``J = [[0, I], [-I, 0]]`` the step from ``z_k`` to ``z_{k+1}`` solves::

    z_{k+1} - z_k = tau J int_0^1 grad H(z_k + s (z_{k+1} - z_k), s_k) ds,   s_k = t_k + tau/2.

For autonomous ``H`` the exact integral gives ``H(z_{k+1}) = H(z_k)`` at every node (the chain
rule along the segment). The integral here is Gauss-Legendre quadrature with
`GAUSS_NODES` = 3 nodes, exact for polynomials of degree 5 in ``s``: so for polynomial
``H`` of degree at most 6 (``grad H`` of degree at most 5) the scheme is the AVF method exactly
and keeps ``H`` at the nodes to round-off (``harmonic``, ``henon_heiles`` (cubic), ``fpu``
(quartic)). Otherwise (``pendulum``, ``kepler``) the quadrature error of the segment integral
is ``O(|z_{k+1} - z_k|^6)``, so ``H`` changes by ``O(tau^7)`` per step: no longer exactly
conserved, but far below the method's own ``O(tau^2)`` error (the drift is reported as the
energy error like any other method's). For time-dependent ``H`` the gradient is taken at the
interval's midpoint time ``s_k``. Order 2, symmetric; conserves ``H``, is not symplectic.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..cache import cached
from ..physics.hamiltonian import HamiltonianSystem, derivatives_function

GAUSS_NODES = 3


def gauss_legendre(count: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes in ``[0, 1]`` and weights (summing to 1) of ``count``-point Gauss-Legendre."""
    x, w = np.polynomial.legendre.leggauss(count)
    return (x + 1) / 2, w / 2


def avf_residual(system: HamiltonianSystem) -> ca.Function:
    """``(z_next, z, t, tau, theta) -> r``: the AVF equation above, ``r = 0`` on a step."""
    def build():
        n = system.n
        z, z_next = ca.SX.sym("z", 2 * n), ca.SX.sym("z_next", 2 * n)
        t, tau = ca.SX.sym("t"), ca.SX.sym("tau")
        derivatives = derivatives_function(system)
        H_q_mean, H_p_mean = 0, 0
        for s, weight in zip(*gauss_legendre(GAUSS_NODES), strict=True):
            point = z + s * (z_next - z)
            _, H_q, H_p, _ = derivatives(point[:n], point[n:], t + tau / 2, system.theta)
            H_q_mean, H_p_mean = H_q_mean + weight * H_q, H_p_mean + weight * H_p
        residual = z_next - z - tau * ca.vertcat(H_p_mean, -H_q_mean)
        return ca.Function("avf_residual", [z_next, z, t, tau, system.theta], [residual],
                           ["z_next", "z", "t", "tau", "theta"], ["r"])
    return cached(system, "avf_residual", build)
