"""The orbits the search finds do not hang on where its seeds fall (issue 46): on the
Henon-Heiles potential at E = 1/8 through x = 0, two stratified layouts (each seed at a random
point of its cell, two generator seeds) and the cells' centres give one orbit set at the default
density; each orbit says how many seeds reached it. Bad layouts are refused by name."""

import numpy as np
import pytest

from ddvp_nlp import InputError, find_periodic_orbits, load_scene


def _same(orbit, other) -> bool:
    return abs(orbit.period - other.period) <= 1e-7 * orbit.period and any(
        np.max(np.abs(row - other.crossings[0])) <= 1e-5 for row in orbit.crossings)


@pytest.mark.slow(why="repetition")  # three searches at the default density, ~9 s CPU each
def test_two_stratified_layouts_find_the_same_orbits():
    system = load_scene("henon_heiles").system
    searches = [find_periodic_orbits(system, energy=1 / 8, section="q1=0", refine=False,
                                     jitter=jitter) for jitter in (None, 1, 2)]
    reference = searches[0].orbits
    assert len(reference) >= 7
    for search in searches[1:]:
        assert len(search.orbits) == len(reference), [o.period for o in search.orbits]
        for orbit in reference:
            assert sum(_same(orbit, other) for other in search.orbits) == 1, orbit.period
    for search in searches:
        assert all(orbit.seeds >= 1 for orbit in search.orbits)


@pytest.mark.parametrize("jitter", [-1, 1.5, "a", True])
def test_a_bad_jitter_is_refused_by_name(jitter):
    system = load_scene("henon_heiles").system
    with pytest.raises(InputError, match="jitter must be an integer >= 0"):
        find_periodic_orbits(system, energy=1 / 8, section="q1=0", jitter=jitter)
