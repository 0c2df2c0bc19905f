"""Halo orbits of the CR3BP by Howell's differential correction, independent of ddvp_nlp: scipy's
DOP853 with the variational equations, in the rotating frame's velocities.

A halo orbit is symmetric about the ``xz``-plane: it crosses ``y = 0`` at right angles twice a
period. From ``(x0, 0, z0, 0, vy0, 0)`` the flow is run to its next ``y = 0`` crossing (half the
period); there ``vx = vz = 0``. Newton corrects the start with the state transition matrix
``Phi`` at the crossing, the crossing time's change eliminated (``delta t = -Phi_y / vy``):

    d vx_f = (Phi_vx - ax_f / vy_f Phi_y) d u,   d vz_f = (Phi_vz - az_f / vy_f Phi_y) d u.

Two ways to close the count: ``x0, vy0`` corrected at fixed ``z0`` (Howell 1984), or ``x0, z0,
vy0`` corrected with the Jacobi constant ``C = 2 Omega - |v|^2`` prescribed as a third row.

Used by ``bench_halo_switch.py`` and the slow test of branch switching
(``tests/library/periodic/test_switching.py``); nothing of the package's solvers is used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

RTOL = ATOL = 1e-13
K = np.array([[0.0, 2.0, 0.0], [-2.0, 0.0, 0.0], [0.0, 0.0, 0.0]])


@dataclass
class Halo:
    """A corrected symmetric orbit: its start ``(x0, z0, vy0)``, period, Jacobi constant,
    Newton's iterations and the final ``|vx_f| + |vz_f|``."""

    x0: float
    z0: float
    vy0: float
    period: float
    jacobi: float
    iterations: int
    defect: float


def _distances(r, mu):
    x, y, z = r
    return np.sqrt((x + mu) ** 2 + y ** 2 + z ** 2), np.sqrt((x - 1 + mu) ** 2 + y ** 2 + z ** 2)


def gradient(r, mu):
    """``grad Omega``, ``Omega = (x^2 + y^2)/2 + (1 - mu)/r1 + mu/r2``."""
    x, y, z = r
    r1, r2 = _distances(r, mu)
    a, b = (1 - mu) / r1 ** 3, mu / r2 ** 3
    return np.array([x - a * (x + mu) - b * (x - 1 + mu), y - a * y - b * y, -a * z - b * z])


def hessian(r, mu):
    """``Omega``'s second derivatives (written out, not differentiated by a tool)."""
    x, y, z = r
    r1, r2 = _distances(r, mu)
    d1 = np.array([x + mu, y, z])
    d2 = np.array([x - 1 + mu, y, z])
    H = -((1 - mu) / r1 ** 3 + mu / r2 ** 3) * np.eye(3)
    H += 3 * (1 - mu) * np.outer(d1, d1) / r1 ** 5 + 3 * mu * np.outer(d2, d2) / r2 ** 5
    H[0, 0] += 1.0
    H[1, 1] += 1.0
    return H


def jacobi(state, mu) -> float:
    r, v = np.asarray(state[:3]), np.asarray(state[3:6])
    r1, r2 = _distances(r, mu)
    omega = (r[0] ** 2 + r[1] ** 2) / 2 + (1 - mu) / r1 + mu / r2
    return float(2 * omega - v @ v)


def _field(t, w, mu):
    r, v = w[:3], w[3:6]
    acceleration = gradient(r, mu) + K @ v
    Phi = w[6:].reshape(6, 6)
    A = np.zeros((6, 6))
    A[:3, 3:] = np.eye(3)
    A[3:, :3] = hessian(r, mu)
    A[3:, 3:] = K
    return np.concatenate([v, acceleration, (A @ Phi).ravel()])


def half_period(x0, z0, vy0, mu, guess: float):
    """``(t_f, state_f, Phi_f)`` at the first ``y = 0`` crossing after ``guess / 4``."""
    start = np.concatenate([[x0, 0.0, z0, 0.0, vy0, 0.0], np.eye(6).ravel()])

    def crossing(t, w, mu):
        return w[1]
    crossing.terminal = True
    crossing.direction = -np.sign(vy0)
    # past the start's own crossing before the event is armed
    early = solve_ivp(_field, (0.0, guess / 4), start, method="DOP853", rtol=RTOL, atol=ATOL,
                      args=(mu,))
    run = solve_ivp(_field, (guess / 4, 2 * guess), early.y[:, -1], method="DOP853",
                    rtol=RTOL, atol=ATOL, events=crossing, args=(mu,))
    if not run.t_events[0].size:
        raise RuntimeError("the orbit did not return to y = 0")
    w = run.y_events[0][0]
    return float(run.t_events[0][0]), w[:6], w[6:].reshape(6, 6)


def correct(x0, z0, vy0, mu, period_guess: float, *, jacobi_constant: float | None = None,
            tol: float = 1e-12, max_iter: int = 30) -> Halo:
    """The symmetric orbit near ``(x0, z0, vy0)``: at fixed ``z0`` (``jacobi_constant`` None)
    or at the prescribed Jacobi constant (module docstring)."""
    u = np.array([x0, z0, vy0], float)
    guess = period_guess / 2
    for iteration in range(1, max_iter + 1):
        t, w, Phi = half_period(u[0], u[1], u[2], mu, guess)
        guess = t
        acceleration = gradient(w[:3], mu) + K @ w[3:]
        rows = np.array([Phi[3] - acceleration[0] / w[4] * Phi[1],
                         Phi[5] - acceleration[2] / w[4] * Phi[1]])[:, [0, 2, 4]]
        residual = np.array([w[3], w[5]])
        if jacobi_constant is None:
            step = np.linalg.solve(rows[:, [0, 2]], -residual)
            u[[0, 2]] += step
        else:
            g = gradient(np.array([u[0], 0.0, u[1]]), mu)
            start = np.array([u[0], 0.0, u[1], 0.0, u[2], 0.0])
            residual = np.r_[residual, jacobi(start, mu) - jacobi_constant]
            matrix = np.vstack([rows, [2 * g[0], 2 * g[2], -2 * u[2]]])
            step = np.linalg.solve(matrix, -residual)
            u += step
        if np.max(np.abs(step)) < tol:
            t, w, _ = half_period(u[0], u[1], u[2], mu, guess)
            start = np.array([u[0], 0.0, u[1], 0.0, u[2], 0.0])
            return Halo(u[0], u[1], u[2], 2 * t, jacobi(start, mu), iteration,
                        abs(w[3]) + abs(w[5]))
    raise RuntimeError(f"differential correction did not converge in {max_iter} iterations")
