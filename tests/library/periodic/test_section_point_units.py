"""The periodic problem's start on the section is found in the units the system is written in:
the scan along the start's ray runs over scales from 1e-12 to 1e12 of it, not to 20. A pendulum
in lengths of 1e8 was refused ("the energy is outside the range where the section meets the
energy surface") although its section meets every energy up to 2e16 (measured before)."""

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import HamiltonianSystem, solve_periodic
from ddvp_nlp.solvers.periodic.first_orbit import section_point


def swing(length: float, time: float = 1.0):
    def H(q, p, t):
        x, v = q[0] / length, p[0] * time / length
        return (length / time) ** 2 * (v ** 2 / 2 + 1 - ca.cos(x))
    return HamiltonianSystem(H, n=1, name=f"swing in units {length:g}, {time:g}")


@pytest.mark.parametrize("length", [1e-8, 1.0, 1e8])
def test_the_section_point_is_the_same_in_any_length_unit(length):
    system = swing(length)
    theta = system.parameter_vector(None)
    # the section p1 = 0 (index 2 of (t, q, p)) at E = 0.5 (in the swing's own energy unit)
    z = section_point(system, theta, 0.5 * length ** 2, 2, 0.0, np.ones(2), "p1=0")
    assert z[1] == 0.0
    assert z[0] / length == pytest.approx(np.arccos(0.5), rel=1e-12)


def test_a_periodic_orbit_in_lengths_of_1e8_is_the_one_in_lengths_of_1():
    orbits = [solve_periodic(swing(length), energy=0.5 * length ** 2, nodes=101,
                             section="p1=0") for length in (1.0, 1e8)]
    assert all(orbit.success for orbit in orbits), [orbit.message for orbit in orbits]
    one, scaled = orbits
    assert np.max(np.abs(scaled.t - one.t)) <= 1e-10 * one.t[-1]
    assert np.max(np.abs(scaled.q / 1e8 - one.q)) <= 1e-10 * np.ptp(one.q)
