"""A mechanical system declared by its Lagrangian ``L(q, v, t)``, regular in ``v``.

``H(q, p, t)`` is also built, by the Legendre transform ``p = dL/dv``: exactly where ``L`` is
quadratic in ``v``, else by six Newton iterations from ``v = 0``. The discrete equations never
use it (they come from ``L``: ``discrete/lagrangian_action.py``); the march's predictor, the
solvability monitor and the energy guard do.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import casadi as ca
import numpy as np

from ..errors import InputError
from .hamiltonian import HamiltonianSystem, varying_part

LEGENDRE_NEWTON_STEPS = 6


class Lagrangian:
    """Marks a scene's function as ``L(q, v, t, **params)`` rather than ``H(q, p, t, ...)``::

        scene = Scene(Lagrangian(lagrangian), n=1, q0=[0.5], v0=[0.5], tau0=0.05, t_end=10)
    """

    def __init__(self, function: Callable[..., object]):
        if not callable(function):
            raise InputError(f"Lagrangian needs a function L(q, v, t, ...), got {function!r}")
        self.function = function


class LagrangianSystem(HamiltonianSystem):
    """``L(q, v, t; params)`` on ``R^n x R^n x R``, regular in ``v`` (``d2L/dv2`` invertible).

    Attributes:
        lagrangian: ``L(q, v, t, **params)`` returning a scalar CasADi expression.
        n, params, name, angles, constraints: as for `HamiltonianSystem`.
        v: the velocity symbols; ``L`` the expression.
    """

    lagrangian_form = True

    def __init__(self, lagrangian: Callable[..., object], n: int,
                 params: Mapping[str, float] | None = None, name: str = "system",
                 angles: tuple = (), constraints: Callable[..., object] | None = None):
        self.lagrangian = lagrangian
        self.hamiltonian = None
        self.n = n
        self.params = dict(params or {})
        self.name = name
        self.angles = angles
        self.constraints = constraints
        self._symbols()
        self.v = ca.SX.sym("v", self.n)
        self.L = self._user_expression("lagrangian", lagrangian, self.v)
        L_v = ca.gradient(self.L, self.v)
        L_vv = ca.jacobian(L_v, self.v)
        _check_regular(self, L_vv)
        # Legendre transform p = dL/dv solved for v: one Newton step from v = 0 is exact when
        # L is quadratic in v.
        steps = 1 if not ca.depends_on(L_vv, self.v) else LEGENDRE_NEWTON_STEPS
        velocity = ca.SX.zeros(self.n)
        for _ in range(steps):
            residual = self.p - ca.substitute(L_v, self.v, velocity)
            velocity = velocity + ca.solve(ca.substitute(L_vv, self.v, velocity), residual)
        self.H = ca.dot(self.p, velocity) - ca.substitute(self.L, self.v, velocity)
        self._finish()
        self.L_function = ca.Function("L", [self.q, self.v, self.t, self.theta], [self.L],
                                      ["q", "v", "t", "theta"], ["L"])
        varying = varying_part(self.L, ca.vertcat(self.q, self.v, self.t))
        self.L_varying_function = self.L_function if varying is self.L else ca.Function(
            "L_varying", [self.q, self.v, self.t, self.theta], [varying],
            ["q", "v", "t", "theta"], ["L"])
        self._constrain()

    def __repr__(self):
        return f"LagrangianSystem(name={self.name!r}, n={self.n}, params={self.params})"


def _check_regular(system: LagrangianSystem, L_vv) -> None:
    """``d2L/dv2`` must be invertible (`is_regular`)."""
    function = ca.Function("L_vv", [system.q, system.v, system.t, system.theta], [L_vv])
    if not is_regular(function, vectors=2, n=system.n, theta=list(system.params.values())):
        raise InputError(
            f"lagrangian of {system.name!r} is singular in v: d2L/dv2 is not invertible "
            "(its smallest singular value is 0 at test points), so there is no Legendre "
            "transform and the discrete equations do not determine the motion")


def is_regular(hessian: ca.Function, *, vectors: int, n: int, theta) -> bool:
    """Whether ``hessian(x_1, .., x_vectors, t, theta)`` (an ``n x n`` matrix) is invertible at
    three fixed pseudo-random points (``x_i`` in ``[-1, 1]^n``, ``t`` in ``[0, 1]``, ``theta``
    the parameters' defaults): its smallest singular value, relative to its largest entry
    ``max |entry|`` (no floor of 1: the same Lagrangian in other units is as regular; a zero
    matrix is singular), above 1e-12 at every finite point."""
    generator = np.random.default_rng(20261121)
    theta = np.asarray(theta, dtype=float)
    worst = np.inf
    for _ in range(3):
        args = [generator.uniform(-1, 1, n) for _ in range(vectors)]
        t = float(generator.uniform(0, 1))
        matrix = np.asarray(hessian(*args, t, theta), dtype=float).reshape(n, n)
        if np.all(np.isfinite(matrix)):
            largest = np.abs(matrix).max()
            worst = min(worst, np.linalg.svd(matrix, compute_uv=False)[-1] / largest
                        if largest > 0 else 0.0)
    return worst > 1e-12










__all__ = ["Lagrangian", "LagrangianSystem", "is_regular"]
