"""The averaged vector field method's step (``discrete/avf.py``), for the compiled fixed-step
baseline of ``fixed_step.py``.

Each step solves the AVF equation for ``z_{k+1}`` by CasADi's ``fast_newton`` from the RK4
predictor, in the same compiled chunks as the explicit baselines; a step is kept while finite
and while its equation holds to ``fixed_step.RESIDUAL_TOL max(|z|, Z)``. Order 2,
symmetric, conserves autonomous ``H`` at the nodes (exactly, up to round-off, for polynomial
``H`` of degree at most 6; see ``discrete/avf.py`` for the others); not symplectic.
"""

from __future__ import annotations

from types import MappingProxyType

import casadi as ca

from ...cache import cached
from ...discrete.avf import avf_residual
from ...discrete.explicit import rk4_step
from ...physics.hamiltonian import HamiltonianSystem

# The AVF step's own Newton (an implicit fixed-step map, solved inside a baseline's chunk).
AVF_NEWTON = MappingProxyType({"abstol": 1e-15, "abstolStep": 1e-16, "max_iter": 12,
                               "error_on_fail": False, "show_eval_warnings": False})


def avf_step(system: HamiltonianSystem) -> ca.Function:
    """``(z, t, tau, theta) -> (z_next, |r|_inf)``: one AVF step by Newton from RK4."""
    def build():
        n = system.n
        equation = avf_residual(system)
        z_next, z = ca.SX.sym("z_next", 2 * n), ca.SX.sym("z", 2 * n)
        t, tau = ca.SX.sym("t"), ca.SX.sym("tau")
        w = ca.vertcat(z, t, tau, system.theta)
        parts = ca.vertsplit(w, [0, 2 * n, 2 * n + 1, 2 * n + 2, w.numel()])
        residual = ca.Function("g", [z_next, w], [equation(z_next, *parts)])
        newton = ca.rootfinder("avf_newton", "fast_newton", residual, dict(AVF_NEWTON))
        guess = rk4_step(system)(z, t, tau, system.theta)
        solved = newton(guess, w)
        return ca.Function("avf", [z, t, tau, system.theta],
                           [solved, ca.norm_inf(residual(solved, w))])
    return cached(system, "avf_step", build)
