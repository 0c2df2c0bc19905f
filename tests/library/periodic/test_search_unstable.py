"""The search's multiple shooting (issue 46): an orbit whose multiplier is above 1e4 per period,
on a system without the reversing symmetry the half-orbit shot needs, is found from a seed where
Newton on the return map (single shooting) is not.

The system: a double well in x times an anharmonic oscillator in y,

    H = |p|^2 / 2 - 9 x^2 / 8 + x^4 / 4 + y^2 / 2 + y^3 / 10,

has the invariant line x = p_x = 0; the oscillation along it is a periodic orbit whose transverse
motion is x'' = (9/4) x exactly, so its nontrivial multipliers are exp(+-3 T / 2) (about 1.9e4 at
E = 1/2). The y^3 term leaves H unchanged by no reflection of y: the section y = 0 has no
reversing symmetry.
"""

import casadi as ca
import numpy as np

from ddvp_nlp import HamiltonianSystem
from ddvp_nlp.solvers.periodic.search import _newton_map, _two_sided, parse_reversing
from ddvp_nlp.solvers.periodic.section_map import (
    RTOL,
    Escape,
    SectionAtEnergy,
    parse_search_section,
    returns,
)


def well(q, p, t):
    x, y = q[0], q[1]
    return ca.sumsqr(p) / 2 - 9 * x ** 2 / 8 + x ** 4 / 4 + y ** 2 / 2 + y ** 3 / 10


WELL = HamiltonianSystem(well, n=2, name="double-well")
ENERGY = 0.5
SEED = np.array([3e-3, 1.5e-3])  # (x, p_x): 3e-3 from the orbit's crossing (0, 0)


def _geometry():
    section = parse_search_section("q2=0", WELL)
    return SectionAtEnergy(WELL, np.zeros(0), section, ENERGY)


def test_the_section_has_no_reversing_symmetry():
    assert parse_reversing("auto", WELL, np.zeros(0), parse_search_section("q2=0", WELL)) \
        is None


def test_multiple_shooting_finds_the_orbit_single_shooting_does_not():
    geometry = _geometry()
    atol, escape = RTOL * 2.0, Escape((0.0, 0.0), 8.0)
    z0 = geometry.points([SEED])[0]
    ahead, behind = returns(geometry, z0, 20.0, atol), returns(geometry, z0, -20.0, atol)
    single = _newton_map(geometry, SEED, 1, ahead.t[ahead.direction > 0][0],
                         np.array([2.0, 2.0]), atol, escape)
    on_line = not isinstance(single, str) and np.max(np.abs(single.start[[0, 2]])) < 1e-8
    assert not on_line, "single shooting found the orbit: the seed is no test"
    orbit = _two_sided(geometry, SEED, (ahead.t[0], -behind.t[0]), atol, escape)
    assert not isinstance(orbit, str), orbit
    assert np.max(np.abs(orbit.start[[0, 2]])) < 1e-9  # on the line x = p_x = 0
    largest = float(np.max(np.abs(orbit.multipliers)))
    assert largest > 1e4
    np.testing.assert_allclose(largest, np.exp(1.5 * orbit.period), rtol=1e-6)
    assert orbit.closure < 1e-8
