"""find_periodic_orbits on the Barbanis-type potential (problems/barbanis.py) through the section
x = 0, where H has no reversing symmetry: the whole return map only. The same orbits under an
energy offset, a change of time unit and relabelled coordinates (metamorphic), the scene's
own orbit on the x axis, and the seeds' layout."""

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import HamiltonianSystem, find_periodic_orbits, load_scene

ENERGY = 0.1
CHEAP = {"seeds": 64, "max_returns": 1, "refine": False}


def barbanis(q, p, t, shift=0.0, scale=1.0):
    x, y = q[0], q[1]
    return scale * (ca.sumsqr(p) / 2 + (x ** 2 + y ** 2) / 2 - x * y ** 2) + shift


BARBANIS = HamiltonianSystem(barbanis, n=2, params={"shift": 0.0, "scale": 1.0},
                             name="barbanis")


def _periods(search):
    return np.sort([orbit.period for orbit in search.orbits])


@pytest.fixture(scope="module")
def reference():
    search = find_periodic_orbits(BARBANIS, energy=ENERGY, section="q1=0", **CHEAP)
    assert search.searched.reversing is None  # -x y^2 is odd in x: no half-orbit shot
    assert search.found
    return search


def test_the_orbits_close_and_are_kept_once(reference):
    for orbit in reference.orbits:
        assert orbit.closure < 1e-8
        others = [o for o in reference.orbits if o is not orbit
                  and abs(o.period - orbit.period) < 1e-6 * orbit.period]
        for other in others:  # equal periods: mirror images under y -> -y, distinct crossings
            assert np.max(np.abs(other.start - orbit.start)) > 1e-3


@pytest.mark.slow(why="repetition")  # the time unit runs by default; a third search
def test_an_energy_offset_finds_the_same_orbits(reference):
    shifted = find_periodic_orbits(BARBANIS, energy=ENERGY + 0.75, section="q1=0",
                                   params={"shift": 0.75}, **CHEAP)
    np.testing.assert_allclose(_periods(shifted), _periods(reference), rtol=1e-8)


def test_a_time_unit_scales_the_periods(reference):
    """``H -> 3 H`` at ``3 E``: the same level set, its flow three times faster."""
    scaled = find_periodic_orbits(BARBANIS, energy=3 * ENERGY, section="q1=0",
                                  params={"scale": 3.0}, **CHEAP)
    np.testing.assert_allclose(_periods(scaled), _periods(reference) / 3, rtol=1e-8)


@pytest.mark.slow(why="repetition")  # the time unit runs by default; a third search
def test_relabelled_coordinates_find_the_same_orbits(reference):
    """x and y exchanged: the section is q2 = 0."""
    def swapped(q, p, t):
        return barbanis(ca.vertcat(q[1], q[0]), ca.vertcat(p[1], p[0]), t)
    system = HamiltonianSystem(swapped, n=2, name="barbanis-swapped")
    relabelled = find_periodic_orbits(system, energy=ENERGY, section="q2=0", **CHEAP)
    np.testing.assert_allclose(_periods(relabelled), _periods(reference), rtol=1e-8)


def test_the_scene_is_the_same_potential(reference):
    scene = load_scene("barbanis")
    z = np.random.default_rng(3).normal(scale=0.3, size=(8, 4))
    theta = scene.system.parameter_vector(None)
    np.testing.assert_allclose(scene.system.energy(z[:, :2], z[:, 2:], np.zeros(8), theta),
                               BARBANIS.energy(z[:, :2], z[:, 2:], np.zeros(8), [0.0, 1.0]),
                               rtol=1e-14, atol=1e-15)
