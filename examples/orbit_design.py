"""Design a transfer with the fixed-end solution's exact derivatives: move its end.

A Kepler transfer leaves q_start = (1, 0) and reaches q_end two time units later; where should
it end so that it arrives with the circular-orbit velocity there (a transfer that needs no
burn to stay on the circle through q_end)? The cost is the arrival mismatch
|p_end(q_end) - v_circ(q_end)|^2, its Jacobian d p_end / d q_end from
solve_bvp(..., derivatives=("q_end",)) (the Hessian of the discrete action), and
scipy.optimize.least_squares moves q_end. The answer is known: the circular arc itself,
q_end = (cos 2, sin 2).
Run: python examples/orbit_design.py
"""

import casadi as ca
import numpy as np
from scipy.optimize import least_squares

from ddvp_nlp import HamiltonianSystem, solve_bvp


def kepler_H(q, p, t, mu):
    return (p[0] ** 2 + p[1] ** 2) / 2 - mu / ca.sqrt(q[0] ** 2 + q[1] ** 2)


kepler = HamiltonianSystem(kepler_H, 2, {"mu": 1.0}, name="kepler_mu")
Q_START, DURATION, NODES = [1.0, 0.0], 2.0, 201


def circular_velocity(q):
    """``sqrt(mu / r)`` along the tangent (counter-clockwise), and its Jacobian in ``q``."""
    x, y = q
    r2 = x * x + y * y
    factor = r2 ** -0.75  # sqrt(mu) r^(-3/2), mu = 1
    v = factor * np.array([-y, x])
    d_factor = -1.5 * factor / r2 * np.array([x, y])
    return v, np.outer([-y, x], d_factor) + factor * np.array([[0.0, -1.0], [1.0, 0.0]])


def transfer(q_end):
    solution = solve_bvp(kepler, Q_START, q_end, (0.0, DURATION), nodes=NODES,
                         derivatives=("q_end",))
    if not solution.success:
        raise RuntimeError(solution.message)
    return solution


def mismatch(q_end):
    v, _ = circular_velocity(q_end)
    return transfer(q_end).p[-1] - v


def mismatch_jacobian(q_end):
    solution = transfer(q_end)
    check = solution.derivatives["checks"]["q_end"]
    assert check["verdict"] == "agrees", check  # each derivative carries its own check
    _, dv = circular_velocity(q_end)
    return solution.derivatives["p_end"]["q_end"] - dv


result = least_squares(mismatch, x0=[-0.2, 1.1], jac=mismatch_jacobian)
best = result.x
print(f"q_end = ({best[0]:.6f}, {best[1]:.6f}), circular arc ends at ({np.cos(DURATION):.6f}, "
      f"{np.sin(DURATION):.6f}); arrival mismatch {np.linalg.norm(result.fun):.2e} after "
      f"{result.nfev} solves and {result.njev} Jacobians")
