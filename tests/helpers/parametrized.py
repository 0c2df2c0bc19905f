"""Systems with parameters shared by the derivative tests (imported as
``helpers.parametrized``): the pendulum in its frequency ``w`` and Kepler's problem in ``mu``."""

import casadi as ca

from ddvp_nlp import HamiltonianSystem


def pendulum_w():
    """``H = p^2/2 + w^2 (1 - cos q)``."""
    def H(q, p, t, w):
        return p[0] ** 2 / 2 + w ** 2 * (1 - ca.cos(q[0]))
    return HamiltonianSystem(H, 1, {"w": 1.0}, name="pendulum_w")


def kepler_mu():
    """``H = |p|^2/2 - mu / |q|``."""
    def H(q, p, t, mu):
        return ca.sumsqr(p) / 2 - mu / ca.norm_2(q)
    return HamiltonianSystem(H, 2, {"mu": 1.0}, name="kepler_mu")
