"""Cubic spline: L = q''^2/2 (the paper's case 1 with l = 2); its motions are cubics."""

from ddvp_nlp import Endpoints, HigherOrderScene


def lagrangian(q, v, t):
    return v[1][0] ** 2 / 2  # v[1] is the second difference


def cubic(t):
    return (1 + 0.5 * t - 2 * t**2 + 1.5 * t**3)[:, None]


# fixed by default: fixed steps reproduce the cubic to round-off; with the times released
# (--scheme vddvp) the solution is verified up to about 150 nodes, its steps drift far from
# uniform and its error against the cubic is larger (README, "Higher derivatives").
scene = HigherOrderScene(lagrangian, n=1, order=2, exact=cubic, tau0=0.05, t_end=2.0,
                         boundary=Endpoints(t_span=(0.0, 1.0), nodes=21),
                         scheme="fixed")
