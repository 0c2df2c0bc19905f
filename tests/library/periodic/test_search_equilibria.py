"""The whole return map's seeds from the equilibria on the section's line
(``search._equilibrium_orbits``): Hill's Lyapunov orbits, whose multiplier of about 2000 per
period makes every seed near them leave before it returns, are closed from the linearised orbits
about the two libration points, without the reversing symmetry; the same orbits under an energy
offset, a change of time unit and relabelled coordinates; the refusals said per critical point."""

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import HamiltonianSystem, find_periodic_orbits
from ddvp_nlp.solvers.periodic.search import (
    FoundOrbit,
    _equilibrium,
    _equilibrium_orbits,
    _window,
)
from ddvp_nlp.solvers.periodic.section_map import SectionAtEnergy, parse_search_section

PERIOD, INDEX = 3.0396555, 1970.2952  # issue 46's Lyapunov orbits at E = -2.14
LIBRATION = 3.0 ** (-1.0 / 3.0)


def hill(q, p, t, shift=0.0, scale=1.0, swap=0.0):
    x, y = (q[1], q[0]) if swap else (q[0], q[1])
    px, py = (p[1], p[0]) if swap else (p[0], p[1])
    return scale * ((px ** 2 + py ** 2) / 2 + y * px - x * py - x ** 2 + y ** 2 / 2
                    - 1 / ca.sqrt(x ** 2 + y ** 2)) + shift


HILL = HamiltonianSystem(hill, n=2, params={"shift": 0.0, "scale": 1.0}, name="hill_eq")
SWAPPED = HamiltonianSystem(lambda q, p, t: hill(q, p, t, swap=1.0), n=2, name="hill_swapped")


def _linearised(system, energy, section="q2=0", params=None):
    theta = system.parameter_vector(params)
    geometry = SectionAtEnergy(system, theta, parse_search_section(section, system), energy)
    return _equilibrium_orbits(geometry, _window(geometry, None), params)


def _lyapunov(found):
    return sorted((o for o in found if isinstance(o, FoundOrbit)
                   and abs(o.period - PERIOD) < 1e-6), key=lambda o: np.mean(o.path[:, 0]))


@pytest.fixture(scope="module")
def reference():
    return _linearised(HILL, -2.14)


def test_both_lyapunov_orbits_are_closed_from_the_libration_points(reference):
    found, failures, count = reference
    assert count == 3  # L1, L2 and the Moon's singularity at x = 0
    pair = _lyapunov(found)
    assert len(pair) == 2
    assert [np.sign(np.mean(o.path[:, 0])) for o in pair] == [-1.0, 1.0]
    assert all(abs(o.index - INDEX) < 1e-2 and o.closure < 1e-8 for o in pair)
    [moon] = failures  # the singularity is said, not passed over
    assert "no linearised orbit about the critical point" in moon.reason


def test_the_equilibrium_is_polished_from_the_line():
    theta = HILL.parameter_vector(None)
    geometry = SectionAtEnergy(HILL, theta, parse_search_section("q2=0", HILL), -2.14)
    z = _equilibrium(geometry, 0.69)
    assert np.max(np.abs(z - [LIBRATION, 0.0, 0.0, LIBRATION])) < 1e-12


def test_an_energy_below_the_libration_points_gives_no_orbit_about_them():
    found, failures, _ = _linearised(HILL, -2.2)
    assert not _lyapunov(found)
    assert any("reaches only energies above" in f.reason for f in failures)


@pytest.mark.slow(why="repetition")
@settings(max_examples=3, deadline=None)
@given(st.floats(-3.0, 3.0), st.sampled_from([0.5, 2.0]))
def test_an_energy_offset_and_a_time_unit_give_the_same_orbits(shift, scale):
    """``H -> scale H + shift`` at ``E -> scale E + shift``: the same orbits, periods divided by
    ``scale``."""
    found, _, _ = _linearised(HILL, scale * -2.14 + shift,
                              params={"shift": shift, "scale": scale})
    pair = [o for o in found if abs(o.period * scale - PERIOD) < 1e-6]
    assert len(pair) == 2


@pytest.mark.slow(why="repetition")  # another system compiled (about 1 s CPU)
def test_relabelled_coordinates_give_the_same_orbits(reference):
    """``x <-> y`` (section ``q1 = 0``): the same two orbits, the same periods and indices."""
    found, _, _ = _linearised(SWAPPED, -2.14, section="q1=0")
    pair = [o for o in found if abs(o.period - PERIOD) < 1e-6]
    assert len(pair) == 2 and all(abs(o.index - INDEX) < 1e-2 for o in pair)


@pytest.mark.slow(why="study")
def test_the_search_without_the_symmetry_finds_the_lyapunov_pair():
    """Issue 46: ``--reversing none`` at E = -2.14 finds both Lyapunov orbits (about 16 s CPU)."""
    search = find_periodic_orbits(HILL, energy=-2.14, section="q2=0", reversing="none",
                                  refine=False)
    assert search.searched.reversing is None and search.searched.equilibria == 3
    assert "linearised orbits about 3 critical points" in search.summary()
    assert len(_lyapunov(search.orbits)) == 2
