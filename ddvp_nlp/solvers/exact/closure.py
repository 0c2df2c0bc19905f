"""The exact flow's side of a periodic orbit: its monodromy and the exact orbit near a discrete
one, both from the variational equations integrated by the one exact flow (``variational.py``,
compiled DOP853 with the tangent carried along; no equation of the scheme is used here).
``Y(T)`` of ``flow_with_derivatives`` on a periodic orbit is its monodromy matrix.

Closing the exact flow (`close_exact`): Newton's method on the shooting equations::

    phi_T(z_0; u) - z_0 - shift = 0      (2n)
    H(z_0) - E = 0,  z_0[section] - value = 0,  g_i . (z_0 - z_ref) = 0   (2 + r)

in ``(z_0, T, u)`` (``2n + 2 + r`` unknowns): the unfolding parameters make the count square as
they do for the discrete orbit (``periodic/orbit.py``), and come out at the integrator's
accuracy on an orbit of the Hamiltonian flow. Started from a discrete orbit's node 0 and period, its
convergence shows that an exact orbit is there; the distance between the two is the discrete
orbit's error at node 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ...cache import cached
from .flow_newton import exact_newton
from .tolerance import EXACT_TOLERANCE
from .variational import RTOL, flow_with_derivatives

# Newton on the shooting equations: iterations, and the closure it stops at (relative to the
# orbit's size, a few hundred of DOP853's rtol).
MAX_SHOOTING_ITERATIONS = 12
CLOSURE_TARGET = EXACT_TOLERANCE.newton_tol


@dataclass
class ExactOrbit:
    """The exact flow's periodic orbit found by `close_exact`: node 0, period, unfolding
    parameters, its monodromy, and how the shooting went (``converged``, ``closure`` = the
    largest ``|phi_T(z_0) - z_0 - shift|`` relative to the orbit's size, ``iterations``);
    ``start_return`` is the same measure of the start (the discrete orbit's node 0 after its
    own period), ``distance`` the largest ``|z_0 - z_0(start)|``, ``period_derivative`` the
    exact family's ``dT/dE``, ``error_bound`` Newton's bound of its own error (its last step,
    relative to the orbit's size, the period or energy, and 1 for the unfolding)."""

    z0: np.ndarray
    period: float
    unfolding: np.ndarray
    monodromy: np.ndarray
    field: np.ndarray
    converged: bool
    closure: float
    iterations: int
    start_return: float
    distance: float
    energy: float
    period_derivative: float
    history: list = field(default_factory=list)
    error_bound: float = np.inf

    def as_dict(self) -> dict:
        return {"converged": self.converged, "period": self.period, "energy": self.energy,
                "closure": self.closure,
                "iterations": self.iterations, "start_return": self.start_return,
                "distance": self.distance, "period_derivative": self.period_derivative,
                "unfolding": self.unfolding.tolist(),
                "z0": self.z0.tolist()}


def close_exact(system, theta, z0, period: float, *, energy: float, section_index: int,
                section_value: float, integrals=(), shift=0.0, rtol: float = RTOL,
                fixed_period: bool = False) -> ExactOrbit:
    """The exact periodic orbit near ``(z_0, T)`` by Newton on the shooting equations (module
    docstring; the one Newton on the exact flow, ``flow_newton.py``, undamped). ``section_index``
    counts ``t`` as 0 (as the discrete layouts do), so ``z_0[section_index - 1]`` is fixed; the
    integrals' phase conditions are taken at the start's ``z_0``. It stops where the closure and
    the energy equation are both within ``CLOSURE_TARGET`` of their scales (the orbit's size,
    ``max(1, |E|)``), or where the flow fails. The orbit's ``period_derivative`` (``dT/dE``
    along the exact family, at fixed section and phases) comes from the last Newton matrix. With
    ``fixed_period`` the period is held and the energy is the unknown (``energy`` its start):
    regular through a fold in ``E``, where ``dT/dE`` passes infinity and ``dE/dT`` zero."""
    integrals = tuple(integrals)
    k, r = 2 * system.n, len(integrals)
    reference = np.array(z0, float)
    shift = np.broadcast_to(np.asarray(shift, float), (k,))
    gradient = _gradients_function(system, integrals)
    generators = _generators(np.asarray(gradient(reference, theta))[:, 1:]) if r else \
        np.zeros((0, k))
    section_row = np.zeros(k)
    section_row[section_index - 1] = 1.0
    scale = max(float(np.max(np.abs(reference))), 1.0)
    history = []

    def evaluate(x):  # x = (z_0, T or E, u)
        z, u = x[:k], x[k + 1:]
        T, level = (period, x[k]) if fixed_period else (x[k], energy)
        flow = flow_with_derivatives(system, theta, z, T, integrals=integrals, unfolding=u,
                                     rtol=rtol)
        closing = flow.z - z - shift
        H = float(system.energy(z[None, :k // 2], z[None, k // 2:], [0.0], theta)[0])
        F = np.concatenate([closing, [H - level, z[section_index - 1] - section_value],
                            generators @ (z - reference)])
        history.append(float(np.max(np.abs(closing))) / scale)
        rows = _newton_matrix(flow, np.asarray(gradient(z, theta))[:, 0], section_row,
                              generators, fixed_period)
        closed = history[-1] <= CLOSURE_TARGET and \
            abs(F[k]) <= CLOSURE_TARGET * max(1.0, abs(level))
        failed = not flow.success or not np.all(np.isfinite(F))
        return (None if failed and not closed else F), (flow, rows, closed)

    weights = np.r_[np.full(k, scale), max(1.0, abs(energy if fixed_period else period)),
                    np.ones(1 + r)]
    result = exact_newton(
        evaluate, lambda _x, F, payload: np.linalg.solve(payload[1], -F),
        np.concatenate([reference, [energy if fixed_period else period], np.zeros(1 + r)]),
        size=lambda F: float(np.max(np.abs(F[:k]))) / scale,
        converged=lambda _F, payload: payload[2], max_iterations=MAX_SHOOTING_ITERATIONS,
        step_size=lambda dx: float(np.max(np.abs(dx) / weights)))
    flow, rows, _ = result.payload
    z, u = result.x[:k], result.x[k + 1:]
    if fixed_period:  # dE/dT: the closure's derivative in T is the field at the return
        T, energy = float(period), result.x[k]
        derivative = np.linalg.solve(rows, -np.r_[flow.field, np.zeros(2 + r)])
        period_derivative = 1.0 / derivative[k] if derivative[k] != 0 else np.inf
    else:
        T = result.x[k] if result.iterations else float(period)
        energy_row = np.zeros(k + 2 + r)
        energy_row[k] = 1.0
        period_derivative = float(np.linalg.solve(rows, energy_row)[k])
    # an orbit of the Hamiltonian flow: the unfolding at the integrator's accuracy
    converged = bool(result.converged and flow.success and np.max(np.abs(u)) <= 1e3 * rtol)
    return ExactOrbit(z0=z, period=T, unfolding=u, monodromy=flow.monodromy, field=flow.field,
                      converged=converged, closure=history[-1], iterations=len(history) - 1,
                      start_return=history[0], distance=float(np.max(np.abs(z - z0))),
                      energy=float(energy), period_derivative=float(period_derivative),
                      history=history, error_bound=result.error_bound)


def _newton_matrix(flow, energy_gradient, section_row, generators, fixed_period):
    """The shooting equations' Jacobian in ``(z_0, T, u)`` (in ``(z_0, E, u)`` with
    ``fixed_period``): the monodromy minus ``I``, the field and the unfolding's columns, then
    the rows of the energy, the section and the phases."""
    k, r = flow.monodromy.shape[0], generators.shape[0]
    rows = np.vstack([np.hstack([flow.monodromy - np.eye(k), flow.field[:, None],
                                 flow.unfolding]),
                      np.r_[energy_gradient, 0.0, np.zeros(1 + r)],
                      np.r_[section_row, 0.0, np.zeros(1 + r)],
                      np.hstack([generators, np.zeros((r, 2 + r))])])
    if fixed_period:  # the column of E instead of T's
        rows[:, k] = 0.0
        rows[k, k] = -1.0
    return rows


def _gradients_function(system, integrals) -> ca.Function:
    """``(z, theta) -> [grad H, grad I_1, ...]`` (``2n x (1 + r)``)."""
    def build():
        z = ca.vertcat(system.q, system.p)
        columns = [ca.gradient(system.H, z)] + [
            ca.gradient(integral(system.q, system.p), z) for integral in integrals]
        return ca.Function("exact_gradients", [z, system.theta], [ca.horzcat(*columns)])
    return cached(system, ("exact_gradients", tuple(integrals)), build)


def _generators(gradients: np.ndarray) -> np.ndarray:
    """``J grad I_i`` as rows, from the gradients as columns ``(2n, r)``."""
    n = gradients.shape[0] // 2
    return np.vstack([gradients[n:], -gradients[:n]]).T


def exact_field_directions(system, theta, z0, integrals=()) -> np.ndarray:
    """The directions the exact monodromy fixes at ``z_0``: the flow ``f(z_0) = J grad H`` and
    each symmetry's generator ``J grad I_i``, as columns ``(2n, 1 + r)``."""
    gradients = np.asarray(_gradients_function(system, tuple(integrals))(
        np.asarray(z0, float), np.asarray(theta, float)))
    return _generators(gradients).T
