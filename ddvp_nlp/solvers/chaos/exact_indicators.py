"""The chaos indicators of the exact flow: the reference the march's indicators are judged
against, integrated by the one exact flow (``exact/flow.py``, adaptive DOP853 with its error
controlled on every component below).

MEGNO, FLI and the largest exponent: the flow ``z' = f(z)`` with one tangent vector
renormalised continuously and the MEGNO integrals as extra components::

    v' = Df(z) v - r v,    r = v . Df(z) v        (|v| = 1 is kept: v(0) unit)
    L' = r                 (L = ln|delta(t)|, delta the unrenormalised tangent)
    S' = t r               (Y = 2 S / t)
    M' = 2 S / t           (<Y> = M / t)

with ``Df = J Hess H`` (``f = J grad H``), times from ``t_0 = 0``. The error control sees
``L``, ``S`` and ``M`` like ``z``, so the indicators carry the flow's tolerance. FLI is the
largest ``L`` at the accepted steps' ends (an under-estimate by at most one step's growth).

The spectrum: ``2n`` tangent columns of the exact variational equations (``exact_flow`` with
its tangent), QR-orthonormalised every ``segment`` time units in the frame's order from
``[f, t_2, ..., t_{2n-1}, grad H]`` (the flow direction, the energy surface's tangents, the
energy). ``span(f)`` and ``{dH = 0}`` are invariant, but round-off along the unstable direction
grows like ``exp(lambda t)`` and breaks both by ``t ~ ln(1e12) / lambda``; so after every
segment the flow column is set to its exact image ``f(z(t)) / |f(z(t_old))|`` and the middle
columns are moved back into ``{dH = 0}`` along the last one. The first and the last exponent are
then the trivial pair (flow, energy; both zero in the limit) and the middle ones the reduced
spectrum, whose pairs sum to round-off.
"""

from __future__ import annotations

import math
import time

import casadi as ca
import numpy as np

from ...cache import cached
from ...physics import vector_field_function
from ...physics.hamiltonian import symplectic_weights
from ...solution import Status
from ..exact.flow import AdaptiveFlow, exact_flow
from ..exact.tolerance import EXACT_TOLERANCE
from .indicators import ChaosIndicators
from .spectrum import Spectrum
from .tangent_march import start_tangent

RTOL = EXACT_TOLERANCE.flow_rtol


def megno_field(system) -> ca.Function:
    """``(w, t, theta) -> w'`` for ``w = (z, v, L, S, M, W)`` (module docstring): ``v`` the
    tangent in the weighted coordinates ``W dz`` (the march's norm,
    ``physics.hamiltonian.symplectic_weights``), ``W`` carried unchanged."""
    n2 = 2 * system.n
    w, t = ca.SX.sym("w", 3 * n2 + 3), ca.SX.sym("t")
    theta = ca.SX.sym("theta", system.theta.numel())
    z, v, S, W = w[:n2], w[n2:2 * n2], w[2 * n2 + 1], w[2 * n2 + 3:]
    f = vector_field_function(system)(z, t, theta)
    Dv = W * ca.jtimes(f, z, v / W)
    r = ca.dot(v, Dv) / ca.dot(v, v)
    mean = ca.if_else(t > 0, 2 * S / t, 0)
    return ca.Function("megno_field", [w, t, theta],
                       [ca.vertcat(f, Dv - r * v, r, t * r, mean, ca.SX.zeros(n2))],
                       ["w", "t", "theta"], ["dw"])


def state_sizes(z0: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Each component's size for the flow's absolute tolerance, in its own units: the state's
    largest magnitude in the weighted coordinates ``W z`` taken back to each (``1 / W_i``
    where the state is 0); ``max(1, |z|)`` made the tolerance absolute in small units."""
    largest = float(np.max(np.abs(weights * z0)))
    return (largest if largest > 0 else 1.0) / weights


def megno_flow(system, compiler="auto", cache_dir=None) -> AdaptiveFlow:
    """The `AdaptiveFlow` of `megno_field`, compiled once per system."""
    return cached(system, ("chaos_megno_flow", compiler, str(cache_dir)),
                  lambda: AdaptiveFlow(megno_field(system), dense=False, compiler=compiler,
                                       cache_dir=cache_dir))


def exact_indicators(system, q0, p0, t_end: float, *, params=None, tangent0=None,
                     snapshots=(), rtol: float = RTOL, compiler="auto",
                     cache_dir=None) -> ChaosIndicators:
    """MEGNO, FLI and the largest exponent of the exact flow from ``(q0, p0)`` at ``t = 0`` to
    ``t_end`` (module docstring), and at each of ``snapshots`` (times in ``(0, t_end]``): the
    same definitions as `chaos_indicators`, integrated at ``rtol``."""
    started = time.process_time()
    n2 = 2 * system.n
    theta = system.parameter_vector(params)
    z0 = np.concatenate([np.asarray(q0, float), np.asarray(p0, float)])
    weights = symplectic_weights(system, z0, 0.0, theta)
    v0 = weights * start_tangent(system.n, tangent0, weights)[:, 0]  # unit in |W dz|
    flow = megno_flow(system, compiler, cache_dir)
    w = np.concatenate([z0, v0, np.zeros(3), weights])
    atol = np.concatenate([rtol * state_sizes(z0, weights), np.full(n2 + 3, rtol),
                           rtol * weights])
    marks = sorted({float(s) for s in snapshots if 0 < s < t_end}) + [float(t_end)]
    t, fli, rows, status = 0.0, 0.0, [], Status.SUCCESS
    message = f"reached t_end = {t_end:.12g}"
    for mark in marks:
        run = flow.run(w, t, mark, theta, rtol=rtol, atol=atol)
        if not run.success:
            status, message = Status.NEWTON_FAILED, f"the exact flow stopped: {run.status}"
            break
        if run.steps:
            fli = max(fli, float(np.max(run.w_old[:, 2 * n2])))
        w, t = run.w_end.copy(), mark
        fli = max(fli, float(w[2 * n2]))
        L, S, M = w[2 * n2:2 * n2 + 3]
        rows.append((t, M / t, 2 * S / t, fli, L / t))
    keys = ("t", "megno", "megno_instant", "fli", "lyapunov")
    table = np.array(rows) if rows else np.full((1, 5), math.nan)
    last = dict(zip(keys, table[-1], strict=True))
    wanted = np.sort(np.asarray(snapshots, float).reshape(-1))
    kept = {key: np.full(wanted.size, math.nan) for key in keys}
    for i, when in enumerate(wanted):
        j = np.flatnonzero(np.isclose(table[:, 0], min(when, t_end)))
        if j.size:
            for c, key in enumerate(keys):
                kept[key][i] = table[j[0], c]
    return ChaosIndicators(megno=last["megno"], megno_instant=last["megno_instant"],
                           fli=last["fli"], lyapunov=last["lyapunov"], t=last["t"], steps=0,
                           status=status, message=message, snapshots=kept,
                           seconds=time.process_time() - started)


def exact_spectrum(system, q0, p0, t_end: float, *, params=None, segment: float = 1.0,
                   rtol: float = RTOL, compiler="auto", cache_dir=None) -> Spectrum:
    """The Lyapunov spectrum of the exact flow from ``(q0, p0)`` at ``t = 0`` to ``t_end`` by
    QR every ``segment`` time units, the flow and the energy surface re-imposed (module
    docstring)."""
    started = time.process_time()
    n2 = 2 * system.n
    theta = system.parameter_vector(params)
    z = np.concatenate([np.asarray(q0, float), np.asarray(p0, float)])
    flow = exact_flow(system, tangent=n2, dense=False, compiler=compiler, cache_dir=cache_dir)
    field = vector_field_function(system)
    zs = ca.SX.sym("z", n2)
    gradient = ca.Function("grad_H", [zs, system.theta], [ca.gradient(
        system.H_function(zs[:n2 // 2], zs[n2 // 2:], 0.0, system.theta), zs)])

    def f(point):
        return np.asarray(field(point, 0.0, theta)).ravel()

    def g(point):
        return np.asarray(gradient(point, theta)).ravel()

    weights = symplectic_weights(system, z, 0.0, theta)
    # the frame orthonormal in the weighted coordinates W dz (the march's norm), a covector
    # (grad H) taking 1 / W there
    Q = _energy_frame(weights * f(z), g(z) / weights) / weights[:, None]
    size = state_sizes(z, weights)
    total, t, status, message = np.zeros(n2), 0.0, Status.SUCCESS, f"reached t_end = {t_end:.12g}"
    while t < t_end:
        h = min(segment, t_end - t)
        run = flow.run(z, t, t + h, theta, rtol=rtol, atol=rtol * size, Y0=Q)
        if not run.success:
            status, message = Status.NEWTON_FAILED, f"the exact flow stopped: {run.status}"
            break
        z_new, V = run.z_end.copy(), run.Y_end.copy()
        V[:, 0] = f(z_new) / np.linalg.norm(weights * f(z))
        dH = g(z_new) @ V
        for j in range(1, n2 - 1):
            V[:, j] -= dH[j] / dH[-1] * V[:, -1]
        Q, R = np.linalg.qr(weights[:, None] * V)
        total += np.log(np.abs(np.diag(R)))
        Q = Q * np.sign(np.diag(R)) / weights[:, None]
        z, t = z_new, t + h
    exponents = total / t if t > 0 else np.full(n2, np.nan)
    half = n2 // 2
    return Spectrum(exponents=exponents, reduced=exponents[1:-1].copy(),
                    trivial=exponents[[0, -1]].copy(),
                    pair_sums=exponents[:half] + exponents[::-1][:half], t=t, steps=0,
                    status=status, message=message, seconds=time.process_time() - started)


def _energy_frame(f: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Orthonormal ``[f, t_2, ..., t_{2n-1}, e]``: ``t_j`` in ``{dH = 0}`` and orthogonal to
    ``f``, ``e`` completing it (on the side of ``grad H``)."""
    _, _, Vt = np.linalg.svd(np.vstack([f, g]))
    middle = Vt[2:]
    first = f / np.linalg.norm(f)
    _, _, Wt = np.linalg.svd(np.vstack([first, middle]))
    last = Wt[-1] if Wt[-1] @ g >= 0 else -Wt[-1]
    return np.column_stack([first, *middle, last])
