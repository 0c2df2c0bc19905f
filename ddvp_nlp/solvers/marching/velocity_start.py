"""A march from ``v0`` (a Lagrangian system's first velocity) differentiated in ``v0`` (issue 47):
``march(system, q0, v0=v0, ..., derivatives=("q0", "v0", "params"))`` and ``gradient`` of such
a march.

Such a march starts from ``p_0 = P(q_0, v_0, theta)``: the discrete Legendre transform on the
first interval (``q_1 = q_0 + tau0 v0``, ``discrete/lagrangian_action.start_momentum``), the
first ``n`` rows ``r(p_0; q_0, q_1, theta) = 0`` of that interval's canonical equations
(``discrete.canonical_function``) solved for ``p_0``. Its Jacobians follow from the
implicit-function theorem on those rows (no equation written here)::

    dP = -r_p^-1 (r_q dq_0 + r_v dv_0 + r_theta dtheta),   r_v = tau0 r_{q_1}.

The march's derivatives in ``(q0, p0, params)`` then chain: with ``q0`` and ``params`` moved at
fixed ``v0`` (what a user holding ``v0`` means),

    D_q0|v0 = D_q0 + D_p0 P_q,   D_v0 = D_p0 P_v,   D_params|v0 = D_params + D_p0 P_theta,

on any array whose last axis is the input's columns (states at ``t_eval``, crossing times,
crossing states); reverse mode applies the transposes to a gradient. ``p0`` is not an input of
such a march (asking for it is refused by name), and ``v0`` is not one of a march from ``p0``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ...discrete import Scheme, canonical_function
from ...errors import InputError

__all__ = ["march_names", "refuse_start_names", "start_jacobians", "to_velocity",
           "velocity_gradient"]


def refuse_start_names(names, *, from_velocity: bool) -> None:
    """``v0`` only for a march from ``v0``; ``p0`` never for one (module docstring)."""
    if from_velocity and "p0" in names:
        raise InputError("derivatives: 'p0' is not an input of a march started from v0 (its "
                         "p0 is the discrete Legendre transform of q0, v0): ask for 'v0'")
    if not from_velocity and "v0" in names:
        raise InputError("derivatives: 'v0' needs a march started from v0 (march(system, q0, "
                         "v0=...)); this one starts from p0: ask for 'p0'")


def march_names(names, from_velocity: bool) -> tuple[str, ...]:
    """The inputs of ``(q0, p0, params)`` a march's derivative is taken in, for ``names``:
    ``names`` itself for a start from ``p0``; with ``p0`` for ``v0`` (the chain's ``D_p0``)."""
    if not from_velocity:
        return tuple(names)
    return tuple(name for name in ("q0", "p0", "params")
                 if name == "p0" or name in names)


def start_jacobians(system, scheme, q0, v0, p0, *, t0: float, tau0: float,
                    theta) -> dict[str, np.ndarray]:
    """``{"q0": P_q (n, n), "v0": P_v (n, n), "params": P_theta (n, m)}`` at the start
    ``(q0, v0)`` whose momentum is ``p0`` (module docstring)."""
    n = system.n
    theta = np.asarray(theta, float).ravel()
    q, v, p = ca.SX.sym("q", n), ca.SX.sym("v", n), ca.SX.sym("p", n)
    th = ca.SX.sym("theta", theta.size)
    canonical = canonical_function(system, Scheme.coerce(scheme))
    rows = canonical(t0, t0 + tau0, q, p, q + tau0 * v, p, th)[:n]
    jacobians = ca.Function("start_jacobians", [q, v, p, th], [
        ca.densify(ca.jacobian(rows, p)), ca.densify(ca.jacobian(rows, q)),
        ca.densify(ca.jacobian(rows, v)), ca.densify(ca.jacobian(rows, th))])
    r_p, r_q, r_v, r_theta = (np.asarray(value, float).reshape(n, -1) for value in jacobians(
        np.asarray(q0, float), np.asarray(v0, float), np.asarray(p0, float), theta))
    return {"q0": -np.linalg.solve(r_p, r_q), "v0": -np.linalg.solve(r_p, r_v),
            "params": -np.linalg.solve(r_p, r_theta).reshape(n, theta.size)}


def to_velocity(values: dict, jacobians: dict, names) -> dict:
    """Derivatives in ``(q0, p0, params)`` (last axis: the input's columns; ``p0`` present)
    as derivatives in ``names`` of ``(q0, v0, params)`` (module docstring)."""
    D_p = values["p0"]
    found = {}
    for name in names:
        chained = D_p @ jacobians[name]
        found[name] = chained if name == "v0" else values[name] + chained
    return found


def velocity_gradient(found: dict, jacobians: dict) -> dict:
    """A gradient in ``(q0, p0, params)`` as one in ``(q0, v0, params)`` (the transposes)."""
    g_p = np.asarray(found["p0"], float)
    return {"q0": found["q0"] + jacobians["q0"].T @ g_p, "v0": jacobians["v0"].T @ g_p,
            "params": found["params"] + jacobians["params"].T @ g_p}
