"""The exact flow of a Hamiltonian system with its derivatives: the variational equations
integrated by scipy's DOP853, the reference every check of a discrete orbit or transfer against
the exact motion uses (``solvers/exact/closure.py``, ``solvers/bvp/at_energy.py``).

Along ``z' = f(z) + sum_i u_i grad I_i(z)`` (``f = J grad H``; ``I_0 = H`` and the ``I_i`` given
first integrals; the ``u_i`` are unfolding parameters, zero on a motion of the Hamiltonian flow)
the derivatives of the flow ``phi_t(z_0; u)`` obey::

    Y' = Df(z) Y,         Y(0) = I        (Y = d phi_t / d z_0, 2n x 2n)
    Y_u' = Df(z) Y_u + [grad I_0, ..., grad I_r],   Y_u(0) = 0

with ``Df = J Hess H + sum_i u_i Hess I_i``. They are integrated together with ``z`` by DOP853
(``rtol``, ``atol = rtol`` times the start's size, at least ``rtol``), the right-hand side one
CasADi function of the stacked state. Only autonomous ``H``.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.integrate import solve_ivp

from ...cache import cached

# DOP853's relative tolerance for the references.
RTOL = 1e-12


def _variational_function(system, integrals) -> ca.Function:
    """``(w, u, theta) -> w'`` for ``w = (z, vec Y, vec Y_u)`` (module docstring)."""
    def build():
        n, r = system.n, len(integrals)
        k = 2 * n
        q, p = system.q, system.p
        z = ca.vertcat(q, p)
        functions = [system.H] + [integral(q, p) for integral in integrals]
        gradients = ca.horzcat(*[ca.gradient(h, z) for h in functions])
        u = ca.SX.sym("u", 1 + r)
        J = ca.blockcat([[ca.SX(n, n), ca.SX.eye(n)], [-ca.SX.eye(n), ca.SX(n, n)]])
        field = ca.mtimes(J, gradients[:, 0]) + ca.mtimes(gradients, u)
        Df = ca.jacobian(field, z)
        w = ca.SX.sym("w", k + k * k + k * (1 + r))
        Y = ca.reshape(w[k:k + k * k], k, k)
        Yu = ca.reshape(w[k + k * k:], k, 1 + r)
        Df_w, field_w, gradients_w = ca.substitute([Df, field, gradients], [z], [w[:k]])
        derivative = ca.vertcat(field_w, ca.vec(ca.mtimes(Df_w, Y)),
                                ca.vec(ca.mtimes(Df_w, Yu) + gradients_w))
        return ca.Function("variational", [w, u, system.theta], [derivative])
    return cached(system, ("exact_variational", tuple(integrals)), build)


@dataclass
class Flow:
    """The end of an integration of the variational equations: ``z(T)``, ``Y(T)`` (the
    monodromy on a periodic orbit), ``Y_u(T)`` and ``f(z(T))`` (the unfolded field), with
    DOP853's counts, and the states at the times asked for (``path``)."""

    z: np.ndarray
    monodromy: np.ndarray
    unfolding: np.ndarray
    field: np.ndarray
    evaluations: int
    success: bool
    message: str
    path: np.ndarray | None = None


def flow_with_derivatives(system, theta, z0, period: float, *, integrals=(), unfolding=None,
                          rtol: float = RTOL, times=None) -> Flow:
    """``phi_T(z_0; u)`` with its derivatives (module docstring) by DOP853 at ``rtol`` (and
    ``atol = rtol`` times the largest ``|z_0|``, at least ``rtol``); with ``times`` (in ``[0,
    T]``) also the states there (``path``, from DOP853's dense output)."""
    integrals = tuple(integrals)
    k, r = 2 * system.n, len(integrals)
    rhs = _variational_function(system, integrals)
    u = np.zeros(1 + r) if unfolding is None else np.asarray(unfolding, float)
    theta = np.asarray(theta, float)
    w0 = np.concatenate([np.asarray(z0, float), np.eye(k).ravel(order="F"),
                         np.zeros(k * (1 + r))])
    scale = max(float(np.max(np.abs(z0))), 1.0)

    def derivative(_, w):
        return np.asarray(rhs(w, u, theta)).ravel()
    with np.errstate(all="ignore"):  # a diverging shooting iterate: non-finite, then refused
        run = solve_ivp(derivative, (0.0, float(period)), w0, method="DOP853", rtol=rtol,
                        atol=rtol * scale, dense_output=times is not None)
    path = None if times is None else run.sol(np.asarray(times, float))[:k].T
    w = run.y[:, -1]
    z = w[:k]
    field = np.asarray(rhs(np.concatenate([z, np.zeros(w0.size - k)]), u, theta)).ravel()[:k]
    return Flow(z=z, monodromy=w[k:k + k * k].reshape(k, k, order="F"),
                unfolding=w[k + k * k:].reshape(k, 1 + r, order="F"), field=field,
                evaluations=int(run.nfev), success=bool(run.success), message=run.message,
                path=path)



