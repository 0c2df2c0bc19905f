"""The discrete action of a higher-derivative Lagrangian ``L(q, v_1, ..., v_l, t)`` (case 1).

Forward differences on the variable grid, evaluated at the left node (docs/theory.md section 4)::

    v_1^(k) = (q_{k+1} - q_k) / tau_k,   v_m^(k) = (v_{m-1}^(k+1) - v_{m-1}^(k)) / tau_k,
    L^(k) = L(q_k, v_1^(k), ..., v_l^(k), t_k),   S_D = sum_k tau_k L^(k),

the sum running over the intervals whose differences the grid defines (``k <= N - 1 - l``).

The paper introduces the ``v_m`` as independent variables with Lagrange multipliers for
``v_m = Delta v_{m-1}``; eliminating the multipliers (its eq. n-order) leaves the stationarity of
``S_D`` in the free node positions (the discrete Euler-Lagrange equations, here the gradient of
the assembled action by automatic differentiation) and, for the energy rule, in the free node
times. The multipliers are recovered on a solution from the recursion

    lambda_l^(k) = dL/dv_l^(k),
    lambda_m^(k) = dL/dv_m^(k) - (lambda_{m+1}^(k) - lambda_{m+1}^(k-1)) / tau_k,

that is ``lambda_m = sum_h (-Delta R^-1)^h dL/dv_{m+h}``, and the energy is
``E^(k) = sum_m lambda_m^(k) . v_m^(k) - L^(k)``. For an autonomous ``L`` the node-time
stationarity keeps ``E^(k)`` constant: the tests measure it to round-off along variable-step
solutions, which checks the recursion and the equations against each other. The energy rule
here is that stationarity (``lee``); ``vddvp`` differs from it only through the paper's hatted
time derivative of a time-dependent ``L``, which is not implemented: it is accepted for
autonomous ``L`` (where the two coincide) and refused otherwise.

Fixed-endpoint problems fix ``l`` nodes (times and positions) at each end; marches start from
``2l`` given nodes and solve, per step, the Euler-Lagrange equation at node ``k`` (and the energy
equation at node ``k``) for node ``k + l``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..errors import InputError
from ..physics.higher_order import HigherOrderSystem

RULES = ("vddvp", "lee", "fixed")


def differences(order: int, q_nodes: list, t_nodes: list) -> list[list]:
    """``[[v_1^(k), ..., v_l^(k)] for each k]`` over the intervals the nodes define."""
    levels = [q_nodes]
    for _ in range(order):
        previous = levels[-1]
        levels.append([(previous[k + 1] - previous[k]) / (t_nodes[k + 1] - t_nodes[k])
                       for k in range(len(previous) - 1)])
    count = len(q_nodes) - order
    return [[levels[m][k] for m in range(1, order + 1)] for k in range(count)]


def action(system: HigherOrderSystem, q_nodes: list, t_nodes: list, theta) -> ca.SX:
    """``S_D = sum_k tau_k L(q_k, v^(k), t_k)`` over the given nodes."""
    total = 0
    for k, v in enumerate(differences(system.order, q_nodes, t_nodes)):
        total += (t_nodes[k + 1] - t_nodes[k]) * system.L_function(q_nodes[k], *v, t_nodes[k],
                                                                    theta)
    return total


def check_rule(system: HigherOrderSystem, rule: str) -> str:
    if rule not in RULES:
        raise InputError(f"unknown scheme {rule!r} (choose from {', '.join(RULES)})")
    if rule == "vddvp" and system.time_dependent:
        raise InputError("the vddvp rule for a time-dependent higher-order Lagrangian (the "
                         "paper's hatted time derivative) is not implemented; use lee or fixed")
    return rule


def energies(system: HigherOrderSystem, t, q, theta) -> tuple[np.ndarray, np.ndarray]:
    """Multipliers ``lambda_1^(k)`` (shape ``(K, n)``) and energies ``E^(k)`` (``(K,)``) on a
    grid, for ``k = l-1 .. N-1-l`` (where the recursion has what it needs)."""
    l, n = system.order, system.n  # noqa: E741 (l is the order, as in the paper)
    t = np.asarray(t, float)
    q = np.asarray(q, float).reshape(t.size, n)
    v = differences(l, list(q), list(t))
    partials = [[np.asarray(d, float).ravel() for d in system.L_v_function(q[k], *v[k], t[k],
                                                                          theta)]
                for k in range(len(v))]
    lam = [[None] * l for _ in range(len(v))]
    for k in range(len(v)):
        lam[k][l - 1] = partials[k][l - 1]
    for m in range(l - 2, -1, -1):  # lambda_m from lambda_{m+1} at k and k - 1
        for k in range(len(v)):
            if k == 0 or lam[k - 1][m + 1] is None or lam[k][m + 1] is None:
                continue
            lam[k][m] = partials[k][m] - (lam[k][m + 1] - lam[k - 1][m + 1]) / (t[k + 1] - t[k])
    first, E = [], []
    for k in range(len(v)):
        if any(x is None for x in lam[k]):
            continue
        L = float(system.L_function(q[k], *v[k], t[k], theta))
        E.append(sum(float(np.dot(lam[k][m], np.asarray(v[k][m], float))) for m in range(l))
                 - L)
        first.append(lam[k][0])
    return np.array(first).reshape(-1, n), np.array(E)
