"""A consistent start for a constrained march: ``(q0, p0)`` moved onto ``g(q, t0) = 0`` and its
hidden constraint ``G H_p + g_t = 0`` by the least change (Newton with the minimal-norm
correction: ``dq = -G^T (G G^T)^-1 g``, then ``dp = -r_p^T (r_p r_p^T)^-1 r``), what moved
reported; ``InputError`` when the start cannot be made consistent (Newton does not converge,
or the constraints' Jacobian is singular or redundant at the start or at the projected
point)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...cache import cached
from ...discrete.constrained import node_expression
from ...errors import InputError
from ...physics.constraints import check_start_constraints, constraint_function

__all__ = ["StartProjection", "consistent_start"]

MAX_PROJECTION_STEPS = 50
# a correction under this many units of round-off of the state is not reported as a move
ROUND_OFF = 64


@dataclass(frozen=True)
class StartProjection:
    """What the projection of the start did: the start used, and how far each part moved
    (infinity norms)."""

    q0: np.ndarray
    p0: np.ndarray
    moved_q: float
    moved_p: float
    iterations: int

    @property
    def moved(self) -> bool:
        return bool(self.moved_q or self.moved_p)

    def describe(self) -> str:
        return (f"the start was projected onto the constraints: q0 moved by {self.moved_q:.3g}, "
                f"p0 by {self.moved_p:.3g} (max norm) in {self.iterations} Newton steps")


def _hidden_function(system) -> ca.Function:
    def build():
        rows = node_expression(system, system.q, system.p, system.t, system.theta)
        hidden = rows[system.n_constraints:]
        return ca.Function("hidden", [system.q, system.p, system.t, system.theta],
                           [hidden, ca.jacobian(hidden, system.p)])
    return cached(system, "hidden_constraint", build)


def consistent_start(system, q0, p0, t0: float, theta, *, warn: bool = True) -> StartProjection:
    """The projected start (module docstring); a ``RuntimeWarning`` says what moved, beyond
    round-off, when ``warn``."""
    check_start_constraints(system, q0, t0, theta, what="q0")
    m, n = system.n_constraints, system.n
    constraints, hidden = constraint_function(system), _hidden_function(system)
    q, p = np.array(q0, float), np.array(p0, float)
    scale_q = max(np.abs(q).max(), np.finfo(float).tiny)
    iterations = 0
    for iterations in range(1, MAX_PROJECTION_STEPS + 1):  # noqa: B007 (reported)
        g, G, _ = (np.asarray(v, float) for v in constraints(q, t0, theta))
        G = G.reshape(m, n)
        dq = G.T @ np.linalg.solve(G @ G.T, g.ravel())
        q = q - dq
        if np.abs(dq).max() <= 4 * np.finfo(float).eps * max(scale_q, np.abs(q).max()):
            break
    else:
        raise InputError(f"the start cannot be made consistent: q0 = {np.asarray(q0).tolist()} "
                         f"does not reach g = 0 in {MAX_PROJECTION_STEPS} Newton steps")
    check_start_constraints(system, q, t0, theta, what="the projected q0")
    for _ in range(MAX_PROJECTION_STEPS):
        r, r_p = (np.asarray(v, float) for v in hidden(q, p, t0, theta))
        r_p = r_p.reshape(m, n)
        try:
            dp = r_p.T @ np.linalg.solve(r_p @ r_p.T, r.ravel())
        except np.linalg.LinAlgError as exc:
            raise InputError(f"the start cannot be made consistent: the hidden constraint "
                             f"G H_p + g_t does not determine p at q0 = {q.tolist()}") from exc
        p = p - dp
        if np.abs(dp).max() <= 4 * np.finfo(float).eps * max(np.abs(p).max(), 1e-300):
            break
    else:
        raise InputError(f"the start cannot be made consistent: p0 = {np.asarray(p0).tolist()} "
                         "does not reach the hidden constraint in "
                         f"{MAX_PROJECTION_STEPS} Newton steps")
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(p))):
        raise InputError(f"the start cannot be made consistent: the projection of q0 = "
                         f"{np.asarray(q0).tolist()}, p0 = {np.asarray(p0).tolist()} is not "
                         "finite")
    moved_q = float(np.abs(q - q0).max())
    moved_p = float(np.abs(p - p0).max())
    tiny_q = ROUND_OFF * np.finfo(float).eps * max(np.abs(q).max(), 1e-300)
    tiny_p = ROUND_OFF * np.finfo(float).eps * max(np.abs(p).max(), 1e-300)
    result = StartProjection(q, p, moved_q if moved_q > tiny_q else 0.0,
                             moved_p if moved_p > tiny_p else 0.0, iterations)
    if warn and result.moved:
        warnings.warn(result.describe(), RuntimeWarning, stacklevel=4)
    return result
