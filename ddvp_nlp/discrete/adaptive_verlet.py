"""Reversible adaptive Stormer-Verlet: a Sundman time transformation ``dt/dsigma = g(q, t)``
realised by Hairer and Soderlind's explicit, reversible step-density control (SIAM J. Sci.
Comput. 26, 2005), for separable ``H = T(p) + V(q, t)``.

The step density is ``rho = 1/g``; with ``dt/dsigma = 1/rho``, along the flow
``d rho/dsigma = (d rho/dt)/rho = G(q, p, t) = (rho_q . T_p(p) + rho_t) / rho``, the rate of
``log rho`` in ``t``. With a fixed step ``eps`` in ``sigma``, one step is::

    h_k = eps / rho_{k+1/2},   z_{k+1} = SV_{h_k}(z_k, t_k),   t_{k+1} = t_k + h_k,
    rho_{k+3/2} = rho_{k+1/2} + eps G(z_{k+1}, t_{k+1}),

from ``rho_{1/2} = rho(q_0, t_0) + eps/2 G(z_0, t_0)``, with ``SV`` the kick-drift-kick
Stormer-Verlet step. The map ``(z_k, rho_{k+1/2}) -> (z_{k+1}, rho_{k+3/2})`` is symmetric
(time-reversible) and explicit; order 2 in ``eps``.

``g(q, t)`` here is the local time scale of the force: with ``kappa(q, t) = |V_qq|_F`` (the
Frobenius norm of the force's Jacobian, a squared frequency),
``rho = ((kappa^2 + c^2) / (kappa_0^2 + c^2))^{1/4}``, ``kappa_0 = kappa(q_0, t_0)``,
``c`` the orbit's own curvature scale (the time-weighted geometric mean of ``kappa`` along the
exact motion, ``solvers/baselines/verlet_adaptive.py``), so that ``rho`` stays positive and
varies on the motion's time scale where the force is flat (an inflection point of a well, where
``kappa`` vanishes). Then ``rho(q_0) = 1``, the first step is ``eps`` (the knob ``tau0``), and
where ``kappa >> c`` the step scales like ``1/sqrt(kappa)``:
``r^{3/2}`` for Kepler (the density Hairer, Lubich and Wanner recommend for Verlet on Kepler,
GNI VIII.3), constant (plain Stormer-Verlet) for a harmonic force.
"""

from __future__ import annotations

import casadi as ca

from ..cache import cached
from ..physics.hamiltonian import HamiltonianSystem
from .explicit import separable_or_raise, stormer_verlet_step


def density_parts(system: HamiltonianSystem) -> ca.Function:
    """``(q, p, t, theta, c2, norm) -> (kappa2, rho, G)`` with ``kappa2 = |V_qq|_F^2``,
    ``rho = ((kappa2 + c2)/norm)^{1/4}`` and ``G = d(log rho)/dt`` along the flow."""
    def build():
        T_p, V_q = separable_or_raise(system, "verlet_adaptive")
        n = system.n
        q, p, t = ca.SX.sym("q", n), ca.SX.sym("p", n), ca.SX.sym("t")
        c2, norm = ca.SX.sym("c2"), ca.SX.sym("norm")
        kappa2 = ca.sumsqr(ca.jacobian(V_q(q, t, system.theta), q))
        rho = ((kappa2 + c2) / norm) ** 0.25
        log_rho = ca.log((kappa2 + c2) / norm) / 4
        G = ca.dot(ca.gradient(log_rho, q), T_p(p, system.theta)) + ca.gradient(log_rho, t)
        return ca.Function("density", [q, p, t, system.theta, c2, norm], [kappa2, rho, G],
                           ["q", "p", "t", "theta", "c2", "norm"], ["kappa2", "rho", "G"])
    return cached(system, "verlet_density", build)


def adaptive_verlet_step(system: HamiltonianSystem) -> ca.Function:
    """``(z, t, rho_half, eps, t_end, theta, c2, norm) -> (z_next, t_next, rho_next)``: one step
    above; a step that would pass ``t_end`` is cut to end on it (plain Stormer-Verlet)."""
    def build():
        n = system.n
        z, t, rho_half = ca.SX.sym("z", 2 * n), ca.SX.sym("t"), ca.SX.sym("rho_half")
        eps, t_end = ca.SX.sym("eps"), ca.SX.sym("t_end")
        c2, norm = ca.SX.sym("c2"), ca.SX.sym("norm")
        h_free = eps / rho_half
        last = t + h_free >= t_end
        h = ca.if_else(last, t_end - t, h_free)
        z_next = stormer_verlet_step(system)(z, t, h, system.theta)
        t_next = ca.if_else(last, t_end, t + h)
        _, _, G = density_parts(system)(z_next[:n], z_next[n:], t_next, system.theta, c2, norm)
        return ca.Function("verlet_adaptive", [z, t, rho_half, eps, t_end, system.theta, c2,
                                               norm],
                           [z_next, t_next, rho_half + eps * G])
    return cached(system, "verlet_adaptive_step", build)
