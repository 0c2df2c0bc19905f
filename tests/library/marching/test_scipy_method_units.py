"""`solve_ivp(..., method=DDVP)` without ``tau0`` takes its first step from the flow's own time
scale at the start, ``1 / rho(df/dz)``: the same march in any units of length or time and with
the origin moved. With ``|y0| / |f(t0, y0)|`` (mixed units, and offset by the origin) a swing
in time units of ``1e5`` or offset by ``1e4`` took 5 steps for 20 of its periods and ended at
``q = -0.499`` for ``0.335``; in lengths of ``1e6`` and time units of ``1e-3`` it took 2 million
(measured before the change)."""

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ddvp_nlp import DDVP, HamiltonianSystem

SPAN = 20.0


def swing(length: float, time: float, centre: float):
    def H(q, p, t):
        return (length / time) ** 2 * ((p[0] * time / length) ** 2 / 2 + 1
                                        - ca.cos(q[0] / length - centre))
    system = HamiltonianSystem(H, 1, name=f"swing {length:g} {time:g} {centre:g}")

    def f(t, y):
        return np.array([y[1], -(length / time ** 2) * np.sin(y[0] / length - centre)])
    return system, f


def marched(length=1.0, time=1.0, centre=0.0):
    system, f = swing(length, time, centre)
    return solve_ivp(f, (0.0, SPAN * time), [(0.5 + centre) * length, 0.0], method=DDVP,
                     hamiltonian=system)


@pytest.mark.parametrize("length, time, centre", [(1.0, 1e5, 0.0), (1e6, 1e-3, 0.0),
                                                  (1.0, 1.0, 1e4)])
def test_the_derived_first_step_follows_the_units(length, time, centre):
    base, other = marched(), marched(length, time, centre)
    assert base.success and other.success
    assert other.t.size == base.t.size
    # the same first step; the march itself then agrees to 4e-6 of the span in lengths of
    # 1e-8 (its step's Newton stops at 6e-14 of the energy there, measured), not to round-off
    assert abs((other.t[1] - other.t[0]) / time - (base.t[1] - base.t[0])) \
        <= 1e-12 * (base.t[1] - base.t[0])
    assert np.max(np.abs(other.t / time - base.t)) <= 1e-5 * SPAN
    assert np.max(np.abs(other.y[0] / length - centre - base.y[0])) <= 1e-4
