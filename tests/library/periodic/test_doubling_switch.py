"""Branch switching at a period doubling (``solvers/periodic/doubling.py``): Henon-Heiles'
orbit on the axis ``x = 0`` passes a multiplier pair through -1 at E = 0.13529 (exact flow); on
a coarse grid (N = 60) the branch of period near ``2T`` is switched onto and followed, the two
signs of its direction found to be one orbit shifted by ``T``; the same with the Hamiltonian
scaled (time unit), an energy offset and the coordinates swapped; the doubled grid's helpers;
the refusals. The doubled orbits against an independent shooting
(``scripts/benchmarks/doubled_shooting.py``) at the scene's N and 2N are the slow test at the
end."""

import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import (
    Continuation,
    HamiltonianSystem,
    Switch,
    follow_periodic_family,
    solve_periodic,
)
from ddvp_nlp.solvers.periodic.closed_grid import ClosedLayout
from ddvp_nlp.solvers.periodic.doubling import twice

NODES, ORBITS = 61, 3


def _henon_heiles(scale: float = 1.0, offset: float = 0.0, swap: bool = False):
    """``scale (|p|^2/2 + |q|^2/2 + x^2 y - y^3/3) + offset``, ``(x, y)`` the coordinates
    ``(q1, q2)`` or, with ``swap``, ``(q2, q1)``."""
    x, y = (1, 0) if swap else (0, 1)

    def hamiltonian(q, p, t):
        return scale * ((p[0] ** 2 + p[1] ** 2) / 2 + (q[0] ** 2 + q[1] ** 2) / 2
                        + q[x] ** 2 * q[y] - q[y] ** 3 / 3) + offset
    return HamiltonianSystem(hamiltonian, 2, name=f"hh_doubling_{scale}_{offset}_{int(swap)}")


def _follow(scale: float = 1.0, offset: float = 0.0, swap: bool = False, nodes: int = NODES,
            switch=None, min_step: float = 1e-4):
    y = 0 if swap else 1
    direction = np.zeros(2)
    direction[y] = 1.0
    return follow_periodic_family(
        _henon_heiles(scale, offset, swap), (scale * 0.13 + offset, scale * 0.14 + offset),
        nodes=nodes, section=f"p{y + 1}=0", start=(direction, np.zeros(2)),
        continuation=Continuation(step=scale * 0.005, min_step=min_step,
                                  switch=switch or Switch(orbits=ORBITS)))


@pytest.fixture(scope="module")
def doubled():
    return _follow()


def test_the_doubled_branch_is_switched_onto_once_and_followed(doubled):
    point = doubled.bifurcations[0]
    assert point.kind == "period doubling" and abs(point.energy - 0.13529) < 1e-3
    assert len(doubled.branches) == 1, doubled.switched
    branch = doubled.branches[0]
    assert branch.kind == "period doubling" and branch.same and branch.label == "+-q1"
    assert "the two signs give one orbit shifted by half its period" in doubled.switched
    assert branch.family.complete and len(branch.family.members) == ORBITS
    period = point.orbit.orbit.period
    for member in branch.family.members:
        orbit = member.orbit
        assert orbit.success and orbit.verdict.accurate
        assert orbit.q.shape == (2 * NODES - 1, 2)
        assert abs(orbit.orbit.period - 2 * period) < 1e-2 * period
        # off the axis orbit traversed twice: x moves, and its two periods differ
        half = NODES - 1
        size = np.max(np.abs(orbit.q[:, 1]))
        assert np.max(np.abs(orbit.q[:, 0])) > 1e-3 * size
        assert np.max(np.abs(orbit.q[half:, 0] - orbit.q[:half + 1, 0])) > 1e-3 * size


@pytest.mark.slow(why="study")
def test_an_energy_offset_and_swapped_coordinates_give_the_same_branch(doubled):
    """``H + 0.25`` with ``x`` and ``y`` exchanged: the same members at energies 0.25 higher,
    the same periods, the nodes the same with the coordinates exchanged (up to the sign of
    ``x``: the two signs are one orbit, which one is followed is the kernel's choice)."""
    other = _follow(offset=0.25, swap=True)
    assert len(other.branches) == 1 and other.branches[0].label == "+-q2"
    assert abs(other.bifurcations[0].energy - 0.25 - doubled.bifurcations[0].energy) < 1e-9
    mine, theirs = doubled.branches[0].family.members, other.branches[0].family.members
    assert len(theirs) == len(mine) == ORBITS
    for u, v in zip(mine, theirs, strict=True):
        assert abs(v.energy - 0.25 - u.energy) < 1e-9
        assert abs(v.orbit.orbit.period - u.orbit.orbit.period) < 1e-9
        assert np.max(np.abs(v.orbit.q[:, 0] - u.orbit.q[:, 1])) < 1e-8
        assert np.max(np.abs(np.abs(v.orbit.q[:, 1]) - np.abs(u.orbit.q[:, 0]))) < 1e-8


@pytest.mark.slow(why="study")
def test_a_time_unit_gives_the_same_branch(doubled):
    """``3 H``: the bifurcation at ``3 E``; every orbit of the branch, its times multiplied by 3,
    is an orbit of ``H`` at a third of its energy (solved again from it: the nodes move by
    round-off) with three times its period. (The arclength mixes node times and energy, so the
    members themselves fall elsewhere on the branch.)"""
    other = _follow(scale=3.0)
    assert abs(other.bifurcations[0].energy - 3 * doubled.bifurcations[0].energy) < 1e-8
    assert len(other.branches) == 1 and other.branches[0].label == "+-q1"
    members = other.branches[0].family.members
    assert len(members) == ORBITS
    for member in members:
        orbit = member.orbit
        again = solve_periodic(_henon_heiles(), energy=member.energy / 3,
                               nodes=2 * NODES - 1, section="p2=0",
                               guess={"t": 3 * orbit.t, "q": orbit.q, "p": orbit.p})
        assert again.success
        assert abs(again.orbit.period - 3 * orbit.orbit.period) < 1e-9
        assert np.max(np.abs(again.q - orbit.q)) < 1e-9


@pytest.mark.slow(why="study")
def test_a_first_step_that_finds_no_doubled_orbit_says_why():
    family = _follow(switch=Switch(orbits=3, step=1000.0), min_step=0.5)
    assert family.branches == []
    assert "no orbit of the doubled period was found off it" in family.switched


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 6), st.integers(0, 2), st.floats(0.1, 10.0), st.integers(0, 10 ** 6))
def test_twice_repeats_the_nodes_over_a_second_period(intervals, integrals, shift, seed):
    layout = ClosedLayout(2, intervals, integrals)
    rng = np.random.default_rng(seed)
    vector = rng.normal(size=layout.size + 1)
    vector[0] = 0.0  # t_0 = 0, a row of the periodic system
    offsets = np.full(4, shift)
    doubled = twice(vector, layout, offsets)
    long = ClosedLayout(2, 2 * intervals, integrals)
    assert doubled.size == long.size + 1
    z = vector[:layout.nodes * layout.m].reshape(layout.nodes, layout.m)
    z2 = doubled[:long.nodes * long.m].reshape(long.nodes, long.m)
    assert np.array_equal(z2[:layout.nodes], z)
    assert np.allclose(z2[intervals + 1:, 0], z[1:, 0] + z[-1, 0])
    assert np.allclose(z2[intervals + 1:, 1:], z[1:, 1:] + shift)
    assert np.array_equal(doubled[long.nodes * long.m:], vector[layout.nodes * layout.m:])


@pytest.mark.slow(why="study")
def test_the_doubled_orbits_match_an_independent_shooting_at_the_scenes_n_and_2n():
    """The scene's N = 200 and N = 400, five orbits each: every period within 1e-2 of the
    independent shooting at equal energy, every energy within 1e-4 of it through equal ``x0``,
    the gaps falling by about 4 (order 2) from N to 2N; the shot orbits are not of period
    ``T`` (``|phi_{T/2}(z0) - z0|`` above 1e-2)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "scripts" / "benchmarks"))
    from doubled_shooting import shoot
    gaps = []
    for nodes in (201, 401):
        family = _follow(nodes=nodes, switch=Switch(orbits=5))
        worst = [0.0, 0.0]
        for member in family.branches[0].family.members:
            orbit = member.orbit
            start = (orbit.q[0, 0], orbit.q[0, 1], orbit.p[0, 0], orbit.orbit.period)
            at_energy = shoot(*start, energy_level=member.energy)
            through = shoot(*start)
            assert at_energy.half > 1e-2
            worst = [max(worst[0], abs(orbit.orbit.period - at_energy.period)),
                     max(worst[1], abs(member.energy - through.energy))]
        assert worst[0] < 1e-2 and worst[1] < 1e-4
        gaps.append(worst)
    for coarse, fine in zip(*gaps, strict=True):
        assert 3.5 < coarse / fine < 4.5
