"""`orbit_gradient`'s check that the orbit holds the equations of the system it is given reads
each row against how far it moves when the nodes move by the orbit's size, so that it says the
same in any units: with ``max(1, |x|)`` it took, in lengths of ``1e-8``, an orbit solved at
``w = 1`` for one of ``w = 1.01`` and returned that system's gradient (measured before)."""

import casadi as ca
import pytest

from ddvp_nlp import HamiltonianSystem, InputError, solve_periodic
from ddvp_nlp.solvers import orbit_gradient


def swing(length: float):
    def H(q, p, t, w):
        return length ** 2 * ((p[0] / length) ** 2 / 2 + w ** 2 * (1 - ca.cos(q[0] / length)))
    return HamiltonianSystem(H, 1, {"w": 1.0}, name=f"swing in lengths of {length:g}")


@pytest.mark.parametrize("length", [1e-8, 1e8])
def test_the_orbits_own_system_is_told_from_another_in_any_units(length):
    system = swing(length)
    orbit = solve_periodic(system, energy=0.5 * length ** 2, nodes=41)
    assert orbit.success, orbit.message
    gradient = orbit_gradient(orbit, {"period": 1.0}, system=system)
    assert gradient["energy"] * length ** 2 == pytest.approx(
        orbit_gradient(solve_periodic(swing(1.0), energy=0.5, nodes=41), {"period": 1.0},
                       system=swing(1.0))["energy"], rel=1e-8)
    with pytest.raises(InputError, match="does not hold the equations"):
        orbit_gradient(orbit, {"period": 1.0}, system=system, params={"w": 1.01})
