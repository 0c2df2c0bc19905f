"""Step 6 of the search, "each orbit once" (`search._distinct`), on synthetic orbits: what is one
orbit and what is two must not depend on where the coordinates' origin is nor on the units.

Each synthetic orbit is a circle of radius ``a`` about ``(c, 0)`` travelled at angular speed
``w``: ``q = (c + a cos wt, a sin wt)``, ``p = q'`` (a point of it on the section ``q2 = 0``
crossing upwards at ``t = 0``: ``u = (q1, p1) = (c + a, 0)``). The merge compared crossings to
``1e-3`` of the start's largest component, ``max |z|``, which grows with the distance from the
origin and not with the orbit: two distinct orbits of one period at a distance of their own
size merged once the origin was a few hundred of their sizes away.
"""

import numpy as np
import pytest

from ddvp_nlp.solvers.periodic.search import FoundOrbit, _distinct


def circle(centre: float, radius: float, period: float, *, phase: float = 0.0,
           offset: float = 0.0, length: float = 1.0, time: float = 1.0) -> FoundOrbit:
    """The synthetic orbit, with its coordinates shifted by ``offset`` (in ``q1``), lengths in
    units ``length`` times smaller (``q * length``, ``p * length / time``) and time in units
    ``time`` times smaller (the period ``* time``). ``phase``: the start moved along the orbit
    and back to the section (its crossing computed at a perturbed phase: the same orbit as
    a second shot finds it, to round-off)."""
    w = 2 * np.pi / period
    t = np.linspace(0.0, period, 400) + phase / w
    q = np.stack([centre + radius * np.cos(w * t), radius * np.sin(w * t)], axis=1)
    p = np.stack([-radius * w * np.sin(w * t), radius * w * np.cos(w * t)], axis=1)
    path = np.hstack([(q + [offset / length, 0.0]) * length, p * length / time])
    start = path[0].copy()
    start[1] = 0.0
    return FoundOrbit(period=period * time, start=start, returns=1, symmetric=False,
                      multipliers=np.ones(2), index=2.0, closure=0.0,
                      crossings=start[[0, 2]][None, :], path=path)


def merged(orbits) -> list:
    return [orbit.seeds for orbit in _distinct(orbits)]


UNITS = [dict(), dict(offset=1e4), dict(offset=-3e2, length=1e-3), dict(time=60.0),
         dict(offset=7.0, length=1e3, time=1e-2)]


@pytest.mark.parametrize("units", UNITS)
def test_two_orbits_a_size_apart_stay_two_wherever_the_origin(units):
    """Two small orbits of one period, one of their sizes apart (about two equilibria, as
    Lyapunov orbits of small amplitude about libration points far from the origin): two."""
    pair = [circle(1.0, 1e-4, 3.0, **units), circle(1.0 + 2e-4, 1e-4, 3.0, **units)]
    assert merged(pair) == [1, 1]


@pytest.mark.parametrize("units", UNITS)
def test_mirror_images_far_from_the_origin_stay_two(units):
    """Orbits of size 0.2 about x = -1 and x = +1 (Hill's Lyapunov pair, roughly): two, also
    with the origin moved 1e4 away."""
    pair = [circle(-1.0, 0.1, 3.2, **units), circle(1.0, 0.1, 3.2, **units)]
    assert merged(pair) == [1, 1]


@pytest.mark.parametrize("units", UNITS)
def test_one_orbit_found_twice_is_one_whatever_the_units(units):
    """The same orbit from two seeds (its crossing and period to round-off of the shots,
    1e-9 of its size): one, reached by two seeds."""
    one = [circle(1.0, 1e-4, 3.0, **units), circle(1.0, 1e-4, 3.0, phase=1e-9, **units)]
    one[1].period *= 1 + 1e-12
    assert merged(one) == [2]


def test_orbits_of_different_periods_stay_two():
    assert merged([circle(1.0, 0.1, 3.0), circle(1.0, 0.1, 3.0 * (1 + 1e-4))]) == [1, 1]
