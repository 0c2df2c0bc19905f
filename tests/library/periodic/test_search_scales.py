"""The search's own scales (`search.py`) under a change of the coordinates' origin and units: a
verdict of the search must not depend on where the origin is nor on the unit of length.

Hill's problem (tests/library/periodic/hill_scene.py) is written in coordinates moved by the
canonical map ``Q1 = a x + c``, ``Q2 = a y``, ``P = p / a`` (``offset = c``, ``length = a``):
the same orbits, moved and scaled. Each check here is one function of the search on a known
orbit, so that the default run pays a few flows, not a search; the searches under an offset
are in test_search.py (slow tier).
"""

import re

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import HamiltonianSystem, find_periodic_orbits
from ddvp_nlp.solvers.periodic import search
from ddvp_nlp.solvers.periodic.section_map import RTOL, SectionAtEnergy, parse_search_section

ENERGY = -1.663
# the retrograde orbit at E = -1.663 (issue 46), its start on y = 0 crossing upwards
RETROGRADE = np.array([-0.2335293254646291, 0.0, 0.0, 2.0906571430610477])
PERIOD = 0.6471579313374237
FRAMES = [dict(offset=0.0, length=1.0), dict(offset=2000.0, length=1.0),
          dict(offset=-3e4, length=1.0), dict(offset=0.0, length=1e3),
          dict(offset=2000.0, length=1e-3)]


def moved_hill(q, p, t, c=0.0, a=1.0):
    x, y = (q[0] - c) / a, q[1] / a
    px, py = p[0] * a, p[1] * a
    return ((px ** 2 + py ** 2) / 2 + y * px - x * py - x ** 2 + y ** 2 / 2
            - 1 / ca.sqrt(x ** 2 + y ** 2))


MOVED = HamiltonianSystem(moved_hill, n=2, params={"c": 0.0, "a": 1.0}, name="hill_moved")


def _geometry(offset, length):
    theta = MOVED.parameter_vector({"c": offset, "a": length})
    return SectionAtEnergy(MOVED, theta, parse_search_section("q2=0", MOVED), ENERGY)


def _moved(z, offset, length):
    """A state of Hill's problem in the moved coordinates."""
    z = np.array(z, float)
    return np.array([length * z[0] + offset, length * z[1], z[2] / length, z[3] / length])


def _atol(length):
    """The flow's tolerance of the search at the origin (its window's reach, 2.1), moved."""
    return RTOL * 2.1 * np.array([length, length, 1 / length, 1 / length])


@pytest.mark.parametrize("frame", FRAMES)
def test_an_orbit_that_does_not_close_is_refused_wherever_the_origin(frame):
    """The retrograde orbit closes over its period; over a period 1e-5 longer it misses its
    start by about 1e-5 of its size and is refused, in every frame. Its closure was measured
    against ``max |z0|``: 2000 with the origin moved 2000 away, so the miss passed as 5e-9 of
    the orbit's size and the candidate was listed as a closed orbit."""
    geometry = _geometry(**frame)
    z0 = _moved(RETROGRADE, **frame)
    atol = _atol(frame["length"])
    orbit = search._closed(geometry, z0, PERIOD, atol, None, symmetric=True)
    assert isinstance(orbit, search.FoundOrbit), orbit
    assert orbit.closure < 1e-8
    missed = search._closed(geometry, z0, PERIOD * (1 + 1e-5), atol, None, symmetric=True)
    assert isinstance(missed, str) and "does not close" in missed, missed


@pytest.mark.parametrize("frame", FRAMES)
def test_a_jump_of_the_crossings_momentum_is_refused_wherever_the_origin(frame, monkeypatch):
    """A half-orbit shot whose residual ``p_o`` jumps across the bracket's root (by 2e-6 of
    the orbit's momenta, faked here on the retrograde orbit) has no root there: refused. The
    jump was compared to ``1e-8 max |z0|``, 2e-5 with the origin 2000 away: accepted."""
    geometry = _geometry(**frame)
    z0 = _moved(RETROGRADE, **frame)
    jump = 1e-6 / frame["length"]
    root = z0[0]

    def crossing(geometry, x, k, direction, horizon, atol, escape):
        end = z0.copy()
        end[2] = jump if x >= root else -jump
        return z0, PERIOD / 2, end

    monkeypatch.setattr(search, "_half_crossing", crossing)
    shot = search._shoot_half(geometry, root - 0.1 * frame["length"],
                              root + 0.1 * frame["length"], 1, 1, PERIOD,
                              _atol(frame["length"]), None)
    assert isinstance(shot, str) and "momentum jumps" in shot, shot


@pytest.fixture(scope="module")
def window_at_the_origin():
    return np.array(search._window(_geometry(0.0, 1.0), None))


@pytest.mark.parametrize("frame", FRAMES[1:])
def test_the_window_moves_with_the_origin_and_the_unit(frame, window_at_the_origin):
    """The default window (the libration points' span beyond each) is the window at the origin,
    moved and scaled. Scanned about the origin, the libration points and the Moon 2000 away fell
    between two of the scan's points (46 apart there): the window was [-197054, 201024] and the
    search found nothing."""
    window = np.array(search._window(_geometry(**frame), None))
    back = (window - frame["offset"]) / frame["length"]
    width = window_at_the_origin[1] - window_at_the_origin[0]
    np.testing.assert_allclose(back, window_at_the_origin, rtol=0, atol=1e-6 * width)


def _escapes(failures, frame):
    """``(seed, t)`` of each failed seed of a search in ``frame``: where it was (moved back) and
    when it escaped (NaN for another failure)."""
    rows = []
    for failure in failures:
        seed = (failure.seed[0] - frame["offset"]) / frame["length"]
        found = re.search(r"escaped \(.*at t = ([-\d.e+]+)\)", failure.reason)
        rows.append((seed, float(found.group(1)) if found else np.nan))
    return np.array(rows)


@pytest.fixture(scope="module")
def seeds_at_the_origin(window_at_the_origin):
    return search._symmetric_search(_geometry(0.0, 1.0), tuple(window_at_the_origin), 12, 1)


@pytest.mark.parametrize("frame", FRAMES[1:])
def test_the_seeds_run_alike_wherever_the_origin(frame, window_at_the_origin,
                                                 seeds_at_the_origin):
    """Twelve seeds on Hill's symmetric line, in the window at the origin moved: followed to
    the same horizon, each that leaves leaving when it does at the origin (within a step of
    the flow, whose steps the offset changes). The seeds' first horizon was ``|q| / |q'|``
    (800 times longer with the origin 2000 away, so every seed was followed 800 times longer),
    the motion had left beyond four times the window's reach from the origin (8008 for a
    half-width of 2.1) and the flow's tolerance was that reach's: the window's centre and
    half-width now."""
    _, failures, region = search._symmetric_search(
        _geometry(**frame), tuple(frame["offset"] + frame["length"] * window_at_the_origin),
        12, 1)
    _, failures_here, region_here = seeds_at_the_origin
    np.testing.assert_allclose(region["horizon"], region_here["horizon"], rtol=1e-9)
    there, here = _escapes(failures, frame), _escapes(failures_here, dict(offset=0, length=1))
    assert there.shape == here.shape and np.sum(np.isfinite(here[:, 1])) >= 4, (there, here)
    np.testing.assert_allclose(there[:, 0], here[:, 0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(there[:, 1], here[:, 1], rtol=0.05)


def _listed(frame) -> np.ndarray:
    """The orbits found at E = -1.663 in ``frame`` (120 seeds on the symmetric line, one
    return): rows ``(period, x, p_y, index)`` of their upward crossings, moved back, by
    period."""
    found = find_periodic_orbits(MOVED, energy=ENERGY, section="q2=0", reversing=("q2", "p1"),
                                 seeds=120, max_returns=1, refine=False,
                                 params={"c": frame["offset"], "a": frame["length"]})
    # by the period to 1e-6, then the crossing: the mirror pair's periods agree to round-off
    rows = sorted((round(o.period, 6), (o.start[0] - frame["offset"]) / frame["length"],
                   o.period, o.start[3] * frame["length"], o.index) for o in found.orbits)
    return np.array([row[1:] for row in rows])[:, [1, 0, 2, 3]]


@pytest.mark.slow(why="repetition")  # 1 to 7 s CPU each: the whole search in each frame; the
# default run checks its parts in them (the closure, the window, the seeds' runs, above)
@pytest.mark.parametrize("frame", FRAMES[2:])
def test_the_search_lists_the_same_orbits_in_other_units_and_origins(frame):
    """The 4 orbits of one return at E = -1.663 (the retrograde orbit, the orbit of period
    2.6168252 and the Lyapunov pair about the libration points), moved and scaled: the same
    periods (to 1e-8) crossing where they did (to 1e-6 of Hill's units) with the origin 3e4
    away, lengths in units of 1e3, and both (2000 away in a unit of 1e-3). Beyond that, what
    the offset's round-off allows: a position is known to ``eps |offset|`` there, ``4e-10`` of
    Hill's units 2000 away in a unit of 1e-3, an error the orbit's stability index (up to 1225,
    the Lyapunov pair) amplifies over a period. The origin 2000 away is test_search.py's
    shifted search."""
    here, there = _listed(FRAMES[0]), _listed(frame)
    assert len(here) == 4 and there.shape == here.shape, (here, there)
    round_off = np.finfo(float).eps * abs(frame["offset"]) / frame["length"] * np.abs(here[:, 3])
    assert np.all(np.abs(there[:, 0] - here[:, 0]) <= (1e-8 + round_off) * here[:, 0]), \
        (there, here)
    assert np.all(np.abs(there[:, 1:3] - here[:, 1:3]) <= (1e-6 + round_off)[:, None]), \
        (there, here)
