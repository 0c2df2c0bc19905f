"""The constrained march's step in the null-space form (``StepControl.constraint_method =
"null_space"``): the reduced rows of ``discrete/null_space.py`` solved by the march's Newton,
the multipliers recovered after it, and every step judged by the multiplier form's own residual
(``constrained_steps.py``), so both forms accept the same steps by the same test.

Unknowns of a step: ``[q_b, P]`` (fixed steps, ``2n``) or ``[q_b, P, tau]`` (the energy step
of ``vddvp``, ``2n + 1``), against ``2n + 2m`` (``+ 1``) of the multiplier form. Per step, once:
the null-space matrix of ``G(q_a, t_a)`` (Householder, ``discrete/null_space.py``) and, for
an energy step on constraints that move, ``(G_a G_a^T)^{-1} g_t(q_a, t_a)`` (the energy row's
work term, `_moving_work`); after the
Newton: ``lambda`` from ``G_a G_a^T lambda = -(2/tau) G_a (p_a^+ - p_a)`` and ``mu`` by
``HIDDEN_UPDATES`` Newton updates of the hidden constraint (``m x m`` sparse QR each). The
Newton updates a step reports are those of the reduced solve.
"""

from __future__ import annotations

import casadi as ca

from ...discrete.action import IntervalAction
from ...discrete.constrained import constraints_move, interval_momenta
from ...discrete.equations import action_for
from ...discrete.null_space import (
    null_space_basis,
    null_space_momenta,
    null_space_rows,
    projection_parts,
)
from ...errors import InputError
from ...physics.constraints import constraint_function
from ...physics.lagrangian import LagrangianSystem
from ..options import CONSTRAINT_METHODS
from .constrained_steps import DBL_MIN, SX_OPTIONS, ConstrainedChunk, newton_function

__all__ = ["CONSTRAINT_METHODS", "NullSpaceChunk", "check_constraint_method",
           "null_space_residual"]

# Newton updates of mu on the hidden constraint after the step's solve: the first is exact
# where H is quadratic in p (H_p linear), the second takes a general H on to round-off in most
# cases; a step whose hidden row is left above ``tol`` is refused by the acceptance test
HIDDEN_UPDATES = 2


def check_constraint_method(system, scheme, method: str) -> None:
    """``InputError`` naming ``constraint_method`` where the null-space form does not apply:
    ``lee`` (its energy row reads ``lambda``, which the reduced rows do not carry) and a
    Lagrangian system (its interval equations are the discrete Legendre transform)."""
    if method not in CONSTRAINT_METHODS:
        raise InputError(f"constraint_method must be one of {', '.join(CONSTRAINT_METHODS)}, "
                         f"got {method!r}")
    if method != "null_space":
        return
    if scheme.rule == "lee":
        raise InputError("constraint_method='null_space' supports scheme 'fixed' and 'vddvp', "
                         "got 'lee' (its energy row reads the multiplier lambda)")
    if isinstance(system, LagrangianSystem):
        raise InputError(f"constraint_method='null_space' needs a HamiltonianSystem; "
                         f"{system.name!r} is a LagrangianSystem (use 'multipliers')")


def null_space_residual(system, scheme, kind: str) -> ca.Function:
    """``R(x, w) -> (rows, scale)`` of the reduced step; ``w`` is the multiplier form's with the
    null-space matrix ``vec(N_a)`` appended, and for an energy step on constraints that move,
    ``y_a = (G_a G_a^T)^{-1} g_t(q_a, t_a)`` after it (`_moving_work`)."""
    n, m, theta = system.n, system.n_constraints, system.theta
    action: IntervalAction = action_for(system, scheme)
    z_a, q_b, P = ca.SX.sym("z_a", 2 * n), ca.SX.sym("q_b", n), ca.SX.sym("P", n)
    basis = ca.SX.sym("N", n, n - m)
    moving = kind == "energy" and constraints_move(system)
    y_a = ca.SX.sym("y_a", m if moving else 0)
    if kind == "fixed":
        t_a, t_b = ca.SX.sym("t_a"), ca.SX.sym("t_b")
        x, w = ca.vertcat(q_b, P), ca.vertcat(t_a, t_b, z_a, theta, ca.vec(basis))
    else:
        t_prev, t_a, tau = ca.SX.sym("t_prev"), ca.SX.sym("t_a"), ca.SX.sym("tau")
        z_prev, drift = ca.SX.sym("z_prev", 2 * n), ca.SX.sym("drift")
        lam0, mu0 = ca.SX.sym("lam_prev", m), ca.SX.sym("mu_prev", m)
        t_b = t_a + tau
        x = ca.vertcat(q_b, P, tau)
        w = ca.vertcat(t_prev, t_a, z_prev, z_a, lam0, mu0, theta, drift, ca.vec(basis), y_a)
    rows, plus, minus = null_space_rows(system, scheme, t_a, t_b, z_a[:n], z_a[n:], q_b, P,
                                        basis, theta)
    scale = ca.SX(1)
    if kind == "energy":
        plus0, minus1 = interval_momenta(system, t_prev, t_a, z_prev[:n], z_prev[n:], z_a[:n],
                                         z_a[n:], lam0, mu0, theta)
        _, _, s_prev, _ = action.arguments(t_prev, t_a, z_prev[:n], plus0, z_a[:n], minus1)
        energy = (action.energy_at(t_a, t_b, z_a[:n], plus, q_b, minus, s_prev, theta,
                                   varying=True)
                  - action.energy_at(t_prev, t_a, z_prev[:n], plus0, z_a[:n], minus1, s_prev,
                                     theta, varying=True))
        if moving:
            energy = energy - _moving_work(system, (t_prev, t_a), z_a, plus, mu0, y_a, theta)
        previous = action.interval_energy(t_prev, t_a, z_prev[:n], plus0, z_a[:n], minus1,
                                          theta)
        # the multiplier form's scale (constrained_steps.step_residual): no floor of 1
        scale = ca.fmax((t_a - t_prev) * ca.fabs(previous),
                        ca.fmax(ca.fabs(ca.dot(z_a[n:], z_a[:n] - z_prev[:n])), DBL_MIN))
        rows = ca.vertcat(rows, (energy + drift) / scale)
    return ca.Function(f"null_space_{kind}_residual", [x, w], [rows, scale], SX_OPTIONS)


def _moving_work(system, times, z_a, plus, mu0, y_a, theta):
    """The constraint's work ``W_k`` of the energy row (``discrete/constrained.py``,
    `constraint_work`) from the reduced unknowns: at the solution ``p_a^+ - p_a = -(tau / 2)
    G_a^T lambda``, so ``(tau / 2) lambda . g_t = -(p_a^+ - p_a) . G_a^T y_a`` with ``y_a =
    (G_a G_a^T)^{-1} g_t(q_a, t_a)`` (known once ``q_a`` is: solved once per step, as ``N_a``
    is made); ``mu_{k-1}`` is the previous step's."""
    n = system.n
    t_prev, t_a = times
    _, G_a, g_t = constraint_function(system)(z_a[:n], t_a, theta)
    return (-ca.dot(plus - z_a[n:], ca.mtimes(G_a.T, y_a))
            + (t_a - t_prev) / 2 * ca.dot(mu0, g_t))


class NullSpaceChunk(ConstrainedChunk):
    """`ConstrainedChunk` with the reduced solve (module docstring); the predictor, the
    acceptance test and the output rows are the multiplier form's."""

    def _build_newton(self, system, scheme, kind, residual) -> ca.Function:
        n, theta = system.n, system.theta
        self.scheme, self.n_theta = scheme, theta.numel()
        self.constraints = constraint_function(system)
        self.moving = constraints_move(system)
        self.projection = projection_parts(system)
        t_a, t_b = ca.SX.sym("t_a"), ca.SX.sym("t_b")
        q_a, q_b, P = ca.SX.sym("q_a", n), ca.SX.sym("q_b", n), ca.SX.sym("P", n)
        self.momenta = ca.Function("null_space_momenta", [t_a, t_b, q_a, q_b, P, theta],
                                   list(null_space_momenta(system, scheme, t_a, t_b, q_a, q_b,
                                                           P, theta)), SX_OPTIONS)
        reduced = null_space_residual(system, scheme, kind)
        return newton_function(reduced, 1 if kind == "energy" else 0, tolerance_input=True)

    def _solve(self, x0, w, tol, kind):
        n, m, k = self.n, self.m, self.n_theta
        if kind == "energy":
            t_a, z_a, theta = w[1], w[2 + 2 * n:2 + 4 * n], w[2 + 4 * n + 2 * m:-1]
        else:
            t_a, z_a, theta = w[0], w[2:2 + 2 * n], w[2 + 2 * n:2 + 2 * n + k]
        q_a, p_a = z_a[:n], z_a[n:]
        _, G_a, g_t = self.constraints(q_a, t_a, theta)
        basis = null_space_basis(G_a)
        extra = [ca.vec(basis)]
        if self.moving and kind == "energy":  # y_a of `_moving_work`
            extra.append(ca.solve(ca.mtimes(G_a, G_a.T), g_t, "qr"))
        P0 = self.scheme.alpha * x0[n:2 * n] + self.scheme.beta * p_a
        y0 = ca.vertcat(x0[:n], P0, x0[-1]) if kind == "energy" else ca.vertcat(x0[:n], P0)
        y, updates = self.newton(y0, ca.vertcat(w, *extra), tol)
        t_b = t_a + y[-1] if kind == "energy" else w[1]
        tau = t_b - t_a
        q_b = y[:n]
        plus, minus = self.momenta(t_a, t_b, q_a, q_b, y[n:2 * n], theta)
        lam = -2 / tau * ca.solve(ca.mtimes(G_a, G_a.T), ca.mtimes(G_a, plus - p_a), "qr")
        mu, p_b = ca.MX.zeros(m), minus
        for _ in range(HIDDEN_UPDATES):
            hidden, G_b, A = self.projection(q_b, p_b, t_b, theta)
            mu = mu + 2 / tau * ca.solve(A, hidden, "qr")
            p_b = minus - tau / 2 * ca.mtimes(G_b.T, mu)
        tail = [y[-1]] if kind == "energy" else []
        return ca.vertcat(q_b, p_b, lam, mu, *tail), updates
