"""find_periodic_orbits(workers=N): the seeds' returns and shots on forked processes
(``section_map.SeedPool``) give the same orbits as the search in this process (the same calls
merged back in order), on the Barbanis-type potential (the whole return map) and on
Henon-Heiles (the half-orbit shots of its reversing symmetry and the whole map); ``workers``
is checked before anything runs."""

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import HamiltonianSystem, InputError, find_periodic_orbits
from ddvp_nlp.solvers.periodic.search import CLOSURE, RESIDUAL, SAME
from ddvp_nlp.solvers.periodic.section_map import (
    SectionAtEnergy,
    SeedPool,
    parse_search_section,
)


def barbanis(q, p, t):
    x, y = q[0], q[1]
    return ca.sumsqr(p) / 2 + (x ** 2 + y ** 2) / 2 - x * y ** 2


def henon_heiles(q, p, t):
    x, y = q[0], q[1]
    return ca.sumsqr(p) / 2 + (x ** 2 + y ** 2) / 2 + x ** 2 * y - y ** 3 / 3


BARBANIS = HamiltonianSystem(barbanis, n=2, name="barbanis")
HENON_HEILES = HamiltonianSystem(henon_heiles, n=2, name="henon_heiles")
CHEAP = {"seeds": 48, "max_returns": 1, "refine": False}


def _same_orbits(one, many) -> None:
    """The same orbits in the same order: periods to SAME (two orbits are one within it), starts
    to the closure an orbit is allowed (CLOSURE of its size, above the shot's RESIDUAL), and the
    same failed seeds with the same reasons."""
    assert len(one.orbits) == len(many.orbits) and one.found
    for a, b in zip(one.orbits, many.orbits, strict=True):
        assert abs(a.period - b.period) <= SAME * a.period
        size = float(np.max(np.abs(a.start)))
        assert np.max(np.abs(a.start - b.start)) <= max(CLOSURE, RESIDUAL) * size
        assert a.seeds == b.seeds and a.returns == b.returns
    assert [f.reason for f in one.failures] == [f.reason for f in many.failures]
    assert one.searched == many.searched


@pytest.mark.slow(why="processes")
@pytest.mark.parametrize("system, section", [(BARBANIS, "q1=0"), (HENON_HEILES, "q1=0")])
def test_workers_find_the_same_orbits(system, section):
    energy = 0.1 if system is BARBANIS else 1 / 8
    one = find_periodic_orbits(system, energy=energy, section=section, **CHEAP)
    for workers in (2, 3):
        many = find_periodic_orbits(system, energy=energy, section=section, workers=workers,
                                    **CHEAP)
        _same_orbits(one, many)
    if system is HENON_HEILES:  # both paths ran: half-orbit shots and the whole map
        assert one.searched.reversing is not None
        assert any(o.symmetric for o in one.orbits)


@pytest.mark.slow(why="processes")
def test_the_pool_merges_blocks_in_order():
    geometry = SectionAtEnergy(BARBANIS, BARBANIS.parameter_vector(None),
                               parse_search_section("q1=0", BARBANIS), 0.1)
    with SeedPool(geometry, workers=2) as pool:
        assert pool.pool is not None
        assert pool.map(_label, [(i,) for i in range(37)]) == [("q1=0", i) for i in range(37)]
    assert pool.pool is None


def _label(geometry, i):
    return geometry.section.label, i


def _pair(geometry, i):
    return geometry, i


def test_in_this_process_the_pool_is_a_loop():
    pool = SeedPool("geometry")  # workers=1: nothing forked, the calls in order here
    with pool:
        assert pool.pool is None
        assert pool.map(_pair, [(3,), (1,), (2,)]) == [("geometry", 3), ("geometry", 1),
                                                       ("geometry", 2)]


@settings(max_examples=20, deadline=None)
@given(st.one_of(st.integers(max_value=0), st.floats(allow_nan=True), st.booleans(),
                 st.text(max_size=3), st.none()))
def test_workers_that_are_not_a_positive_integer_are_refused(workers):
    with pytest.raises(InputError) as refused:
        find_periodic_orbits(BARBANIS, energy=0.1, section="q1=0", workers=workers)
    assert str(refused.value) == f"workers must be a positive integer, got {workers!r}"


def test_workers_beyond_the_memory_are_refused():
    with pytest.raises(InputError, match="workers = 1000000000 is more than this machine"):
        find_periodic_orbits(BARBANIS, energy=0.1, section="q1=0", workers=10 ** 9)
