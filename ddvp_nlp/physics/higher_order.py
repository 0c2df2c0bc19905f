"""Lagrangians with higher derivatives, ``L(q, v_1, ..., v_l, t)``: the paper's case 1.

``v_m`` stands for the ``m``-th derivative; the system checks that ``L`` is regular in the
highest one (``d2L/dv_l^2`` invertible). The discrete action, its differences and energies are in
``discrete/higher_order_action.py``; the solvers in ``solvers/higher/``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import casadi as ca
import numpy as np

from ..errors import InputError
from ..validation import check_integer, check_parameter_values


class HigherOrderSystem:
    """``L(q, v, t, **params)`` with ``v[m-1]`` the ``m``-th difference, ``m = 1 .. order``.

    Attributes:
        lagrangian, n, order, params, name: as given.
        time_dependent: whether ``L`` depends on ``t`` (read off the expression).
    """

    def __init__(self, lagrangian: Callable[..., object], n: int, order: int,
                 params: Mapping[str, float] | None = None, name: str = "system"):
        n = check_integer("n", n)
        self.order = check_integer("order", order)
        self.n, self.name, self.lagrangian = int(n), name, lagrangian
        self.params = check_parameter_values(dict(params or {}),
                                             {k: 0.0 for k in dict(params or {})},
                                             owner=f"system {name!r}")
        self.q = ca.SX.sym("q", self.n)
        self.v = [ca.SX.sym(f"v{m}", self.n) for m in range(1, self.order + 1)]
        self.t = ca.SX.sym("t")
        self.theta = ca.SX.sym("theta", len(self.params))
        symbols = {k: self.theta[i] for i, k in enumerate(self.params)}
        try:
            value = lagrangian(self.q, self.v, self.t, **symbols)
        except Exception as exc:
            raise InputError(f"lagrangian of {name!r} failed on symbolic input: "
                             f"{type(exc).__name__}: {exc}") from exc
        from .hamiltonian import as_scalar_expression

        self.L = as_scalar_expression(value, name, "lagrangian")
        given = ca.vertcat(self.q, *self.v, self.t, self.theta)
        stray = [s.name() for s in ca.symvar(self.L) if not ca.depends_on(s, given)]
        if stray:
            raise InputError(f"lagrangian of {name!r} depends on symbols it was not given: "
                             f"{', '.join(stray)}")
        self.time_dependent = bool(ca.depends_on(self.L, self.t))
        inputs = [self.q, *self.v, self.t, self.theta]
        self.L_function = ca.Function("L", inputs, [self.L])
        self.L_v_function = ca.Function("L_v", inputs, [ca.gradient(self.L, v) for v in self.v])
        self._check_regular()

    def _check_regular(self):
        from .lagrangian import is_regular

        top = self.v[-1]
        hessian = ca.Function("L_top", [self.q, *self.v, self.t, self.theta],
                              [ca.jacobian(ca.gradient(self.L, top), top)])
        if not is_regular(hessian, vectors=self.order + 1, n=self.n,
                          theta=list(self.params.values())):
            raise InputError(
                f"lagrangian of {self.name!r} is singular in its highest derivative v{self.order}"
                f": d2L/dv{self.order}^2 is not invertible, so the discrete Euler-Lagrange "
                "equations do not determine the next node")

    def parameter_vector(self, values: Mapping[str, object] | None = None) -> np.ndarray:
        resolved = check_parameter_values(dict(values or {}), self.params,
                                          owner=f"system {self.name!r}")
        return np.array([resolved[k] for k in self.params], dtype=float)


def euler_lagrange_field(system: HigherOrderSystem) -> ca.Function:
    """``(y, t, theta) -> y'``: the Euler-Lagrange equation of ``L(q, q', ..., q^(l), t)`` as a
    first-order system in ``y = (q, q', ..., q^(2l-1))`` (Ostrogradsky's variables).

    The equation ``sum_m (-1)^m D^m (dL/dq^(m)) = 0``, with ``D`` the total time derivative
    ``D f = df/dt + sum_j df/dy_j y_(j+1)``, is linear in ``q^(2l)`` with coefficient
    ``(-1)^l d2L/dq^(l)2``, invertible for a regular ``L`` (checked when the system is made);
    solved for ``q^(2l)`` it gives ``y' = (y_1, ..., y_(2l-1), q^(2l)(y, t))``. This is the
    exact flow the discrete higher-order schemes approximate (the accuracy check integrates it).
    """
    from ..cache import cached

    def build():
        l, n = system.order, system.n  # noqa: E741 (l is the order, as in the paper)
        y = [ca.SX.sym(f"y{j}", n) for j in range(2 * l + 1)]
        t = ca.SX.sym("t")
        values = [y[0], *y[1:l + 1], t, system.theta]
        symbols = [system.q, *system.v, system.t]

        def total(expression):
            rate = ca.jacobian(expression, t)
            for j in range(2 * l):
                rate = rate + ca.mtimes(ca.jacobian(expression, y[j]), y[j + 1])
            return rate

        equation = ca.SX.zeros(n)
        for m in range(l + 1):
            term = ca.gradient(system.L, symbols[m])
            term = ca.substitute([term], [ca.vertcat(*symbols, system.theta)],
                                 [ca.vertcat(*values)])[0]
            for _ in range(m):
                term = total(term)
            equation = equation + (-1) ** m * term
        top = ca.jacobian(equation, y[2 * l])
        rest = ca.substitute(equation, y[2 * l], ca.SX.zeros(n))
        highest = -ca.solve(top, rest)
        state = ca.vertcat(*y[:2 * l])
        return ca.Function("euler_lagrange_field", [state, t, system.theta],
                           [ca.vertcat(*y[1:2 * l], highest)], ["z", "t", "theta"], ["f"])
    return cached(system, "euler_lagrange_field", build)


__all__ = ["HigherOrderSystem", "euler_lagrange_field"]

