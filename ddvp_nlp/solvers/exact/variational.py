"""The exact flow of a Hamiltonian system with its derivatives: the variational equations on the
same adaptive flow (``flow.py``), the reference every check of a discrete orbit or transfer
against the exact motion uses (``closure.py``, ``bvp/at_energy.py``, the Floquet checks).

Along ``z' = f(z) + sum_i u_i grad I_i(z)`` (``f = J grad H``; ``I_0 = H`` and the ``I_i`` given
first integrals; the ``u_i`` are unfolding parameters, zero on a motion of the Hamiltonian flow)
the derivatives of the flow ``phi_t(z_0; u)`` obey::

    Y' = Df(z) Y,         Y(0) = I        (Y = d phi_t / d z_0, 2n x 2n)
    Y_u' = Df(z) Y_u + [grad I_0, ..., grad I_r],   Y_u(0) = 0

with ``Df = J Hess H + sum_i u_i Hess I_i``. They are integrated as the tangent of the extended
state ``(z, u)`` with ``u' = 0``: its tangent's columns for ``z`` are ``Y`` and those for ``u``
are ``Y_u``, one adaptive run with its error controlled on ``z`` (the tangent takes the steps
that resolve ``z``). Only autonomous ``H``.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...cache import cached
from ...physics.hamiltonian import flow_jacobian_function, symplectic_weights
from .flow import AdaptiveFlow
from .tolerance import EXACT_TOLERANCE

# The references' relative tolerance (absolute: this times each coordinate's `flow_scales`).
RTOL = EXACT_TOLERANCE.flow_rtol


def flow_scales(system, theta, z0, duration: float) -> np.ndarray:
    """Each coordinate's size on the motion through ``z0`` over ``duration`` (an orbit's
    period, a transfer's time), ``(2n,)``: what the exact flow's absolute tolerances, an orbit's
    closure and the unfolding's test are measured against. ``s / W_i``, with ``W`` the
    symplectic weights (`physics.hamiltonian.symplectic_weights`: in ``W z`` every coordinate
    has one unit) and ``s = |W f(z_0)|_inf |T| / (2 pi)`` (an oscillation of amplitude ``A``
    moves at ``A omega`` and has period ``2 pi / omega``). Nothing is read off ``|z_0|`` (an
    origin far away) and there is no floor of 1: the same sizes, each in its own units, in any
    units of length, momentum or time and with the origin moved."""
    z0 = np.asarray(z0, float)
    theta = np.asarray(theta, float)
    weights = symplectic_weights(system, z0, 0.0, theta)
    f = np.asarray(flow_jacobian_function(system)(z0, 0.0, theta)[0], float).ravel()
    with np.errstate(all="ignore"):
        s = float(np.max(np.abs(weights * f))) * abs(float(duration)) / (2 * np.pi)
    if not (np.isfinite(s) and s > 0):  # an equilibrium or a zero duration: relative alone
        return np.full(z0.size, np.finfo(float).tiny)
    return s / weights


def _extended_field(system, integrals) -> ca.Function:
    """``(w, t, theta) -> w'`` for ``w = (z, u)``: the unfolded field and ``u' = 0``."""
    n, r = system.n, len(integrals)
    k = 2 * n
    q, p = system.q, system.p
    z = ca.vertcat(q, p)
    functions = [system.H] + [integral(q, p) for integral in integrals]
    gradients = ca.horzcat(*[ca.gradient(h, z) for h in functions])
    u = ca.SX.sym("u", 1 + r)
    J = ca.blockcat([[ca.SX(n, n), ca.SX.eye(n)], [-ca.SX.eye(n), ca.SX(n, n)]])
    field = ca.mtimes(J, gradients[:, 0]) + ca.mtimes(gradients, u)
    w, t = ca.SX.sym("w", k + 1 + r), ca.SX.sym("t")
    theta = ca.SX.sym("theta", system.theta.numel())
    field_w = ca.substitute(ca.substitute(field, z, w[:k]), u, w[k:])
    field_w = ca.substitute(field_w, system.theta, theta)
    return ca.Function("unfolded_field", [w, t, theta],
                       [ca.vertcat(field_w, ca.SX.zeros(1 + r))], ["w", "t", "theta"], ["dw"])


def variational_flow(system, integrals=(), *, dense: bool = False) -> AdaptiveFlow:
    """The adaptive flow of the extended state with all its tangent columns, compiled once per
    system, integrals and shape (kept with the system)."""
    integrals = tuple(integrals)

    def build():
        field = _extended_field(system, integrals)
        size = field.size1_in(0)
        return AdaptiveFlow(field, tangent=size, dense=dense, slots=256)
    return cached(system, ("exact_variational", integrals, dense), build)


@dataclass
class Flow:
    """The end of an integration of the variational equations: ``z(T)``, ``Y(T)`` (the
    monodromy on a periodic orbit), ``Y_u(T)`` and ``f(z(T))`` (the unfolded field), with the
    run's counts, and the states at the times asked for (``path``)."""

    z: np.ndarray
    monodromy: np.ndarray
    unfolding: np.ndarray
    field: np.ndarray
    evaluations: int
    success: bool
    message: str
    path: np.ndarray | None = None


def flow_with_derivatives(system, theta, z0, period: float, *, integrals=(), unfolding=None,
                          rtol: float = RTOL, times=None, sizes=None) -> Flow:
    """``phi_T(z_0; u)`` with its derivatives (module docstring) at ``rtol`` (and ``atol =
    rtol`` times each coordinate's size, ``sizes``, default `flow_scales` of ``z_0`` over
    ``T``); with ``times`` (in ``[0, T]``) also the states there (``path``, from the run's
    dense output)."""
    integrals = tuple(integrals)
    k, r = 2 * system.n, len(integrals)
    flow = variational_flow(system, integrals, dense=times is not None)
    u = np.zeros(1 + r) if unfolding is None else np.asarray(unfolding, float)
    z0 = np.asarray(z0, float)
    w0 = np.concatenate([z0, u])
    if sizes is None:
        sizes = flow_scales(system, theta, z0, period)
    atol = np.concatenate([rtol * np.asarray(sizes, float), np.full(1 + r, rtol)])
    with np.errstate(all="ignore"):  # a diverging shooting iterate: non-finite, then refused
        run = flow.run(w0, 0.0, float(period), np.asarray(theta, float), rtol=rtol, atol=atol)
    path = None if times is None else run.z(np.asarray(times, float))[:, :k]
    Y = run.Y_end
    w_end = run.z_end
    field = np.asarray(flow.field(w_end, run.t_reached, np.asarray(theta, float))).ravel()[:k]
    return Flow(z=w_end[:k].copy(), monodromy=Y[:k, :k].copy(), unfolding=Y[:k, k:].copy(),
                field=field, evaluations=int(13 * run.attempts), success=run.success,
                message=run.status, path=path)
