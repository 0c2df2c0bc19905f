"""Periodic orbits of the Henon-Heiles potential by single shooting, independent of ddvp_nlp:
scipy's DOP853 with the variational equations, written out by hand.

``H = (px^2 + py^2)/2 + (x^2 + y^2)/2 + x^2 y - y^3/3``. An orbit starts on the section
``py = 0`` at ``u = (x0, y0, px0)`` and closes after ``T``: ``phi_T(z0) - z0 = 0`` (four rows,
one dependent on the others through the energy). Two ways to fix the one free direction along
the family (Gauss-Newton on the consistent overdetermined rows, the state transition matrix
``Phi`` and the field ``f`` at ``T`` giving the Jacobian):

- ``energy=E``: the row ``H(z0) - E`` added; unknowns ``(x0, y0, px0, T)``: the period at a
  prescribed energy;
- ``x0`` fixed: unknowns ``(y0, px0, T)``: the energy of the orbit through ``x0``.

Used by ``bench_doubling_switch.py`` and the slow test of switching at a period doubling
(``tests/library/periodic/test_doubling_switch.py``); nothing of the package is used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

RTOL = ATOL = 1e-13


@dataclass
class Shot:
    """A closed orbit: its start ``(x0, y0, px0)`` (``py0 = 0``), period, energy, Gauss-Newton's
    iterations, its closure ``max |phi_T(z0) - z0|`` and ``half = max |phi_{T/2}(z0) - z0|``
    (0 for an orbit of period ``T/2`` traversed twice)."""

    x0: float
    y0: float
    px0: float
    period: float
    energy: float
    iterations: int
    closure: float
    half: float


def energy(z) -> float:
    x, y, px, py = z
    return float((px ** 2 + py ** 2) / 2 + (x ** 2 + y ** 2) / 2 + x ** 2 * y - y ** 3 / 3)


def _field(t, w):
    x, y, px, py = w[:4]
    A = np.array([[0, 0, 1, 0], [0, 0, 0, 1],
                  [-(1 + 2 * y), -2 * x, 0, 0], [-2 * x, -(1 - 2 * y), 0, 0]], float)
    Phi = w[4:].reshape(4, 4)
    return np.r_[px, py, -x - 2 * x * y, -y - x ** 2 + y ** 2, (A @ Phi).ravel()]


def flow(z0, T: float):
    """``(phi_T(z0), Phi_T)``."""
    run = solve_ivp(_field, (0.0, T), np.r_[z0, np.eye(4).ravel()], method="DOP853",
                    rtol=RTOL, atol=ATOL)
    return run.y[:4, -1], run.y[4:, -1].reshape(4, 4)


def _gradient(z) -> np.ndarray:
    x, y, px, py = z
    return np.array([x + 2 * x * y, y + x ** 2 - y ** 2, px, py])


def shoot(x0: float, y0: float, px0: float, period: float, *, energy_level: float | None = None,
          tol: float = 1e-12, max_iter: int = 30) -> Shot:
    """The closed orbit near ``(x0, y0, px0)`` of period near ``period``: at the energy
    ``energy_level`` or, when it is ``None``, through ``x0`` (module docstring)."""
    u = np.array([x0, y0, px0, period], float)
    free = [0, 1, 2, 3] if energy_level is not None else [1, 2, 3]
    for iteration in range(1, max_iter + 1):
        z0 = np.array([u[0], u[1], u[2], 0.0])
        zT, Phi = flow(z0, u[3])
        field = _field(0.0, np.r_[zT, np.eye(4).ravel()])[:4]
        rows = zT - z0
        # columns: d/dx0, d/dy0, d/dpx0 (py0 = 0 fixed), d/dT
        J = np.column_stack([Phi[:, :3] - np.eye(4)[:, :3], field])
        if energy_level is not None:
            rows = np.r_[rows, energy(z0) - energy_level]
            J = np.vstack([J, np.r_[_gradient(z0)[:3], 0.0]])
        step = np.linalg.lstsq(J[:, free], -rows, rcond=None)[0]
        u[free] += step
        if np.max(np.abs(step)) < tol:
            z0 = np.array([u[0], u[1], u[2], 0.0])
            zT, _ = flow(z0, u[3])
            zh, _ = flow(z0, u[3] / 2)
            return Shot(u[0], u[1], u[2], u[3], energy(z0), iteration,
                        float(np.max(np.abs(zT - z0))), float(np.max(np.abs(zh - z0))))
    raise RuntimeError(f"shooting did not converge in {max_iter} iterations")
