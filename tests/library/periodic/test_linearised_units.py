"""The linearised start about an equilibrium in other units, with a constant in ``H`` and an
equilibrium given to round-off: the same guess, scaled. Before the change its tests read
``max(1, |z_e|)``, ``max(1, |Hess H|)`` and ``max(1, |E|)``: in lengths of ``1e8`` the swing's
equilibrium given ``1e-12`` of a length off was refused as not at rest (in lengths of 1 it was
taken), and with ``1e6`` added to ``H`` the amplitude's secant stopped at once."""

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import HamiltonianSystem, linearised_orbit


def swing(length: float, time: float, constant: float = 0.0):
    def H(q, p, t):
        return (length / time) ** 2 * ((p[0] * time / length) ** 2 / 2 + 1
                                        - ca.cos(q[0] / length)) + constant
    return HamiltonianSystem(H, 1, name=f"swing {length:g} {time:g} {constant:g}")


def guess(length=1.0, time=1.0, constant=0.0, off=0.0):
    return linearised_orbit(swing(length, time, constant),
                            energy=0.3 * (length / time) ** 2 + constant,
                            equilibrium=[off * length, 0.0], section="q1=0", samples=16)


@pytest.mark.parametrize("length, time, constant", [
    (1e-8, 1.0, 0.0), (1e8, 1.0, 0.0), (1.0, 1e5, 0.0), (1.0, 1.0, 1e6)])
def test_the_same_guess_in_other_units(length, time, constant):
    base = guess()
    other = guess(length, time, constant)
    assert np.allclose(other["t"] / time, base["t"], rtol=1e-12, atol=0)
    assert np.max(np.abs(other["p"] * time / length - base["p"])) <= 1e-9 * np.ptp(base["p"])
    # an equilibrium 1e-12 of a length off is the same equilibrium in any units
    offset = guess(length, time, constant, off=1e-12)
    assert np.max(np.abs(offset["q"] / length - base["q"])) <= 1e-10
