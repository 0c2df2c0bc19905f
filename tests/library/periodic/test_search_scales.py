"""The search's own scales (`search.py`) under a change of the coordinates' origin and units: a
verdict of the search must not depend on where the origin is nor on the unit of length.

Hill's problem (tests/library/periodic/hill_scene.py) is written in coordinates moved by the
canonical map ``Q1 = a x + c``, ``Q2 = a y``, ``P = p / a`` (``offset = c``, ``length = a``):
the same orbits, moved and scaled. Each check here is one function of the search on a known
orbit, so that the default run pays a few flows, not a search; the searches under an offset
are in test_search.py (slow tier).
"""

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import HamiltonianSystem
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
    orbit = search._closed(geometry, z0, PERIOD, atol, np.inf, symmetric=True)
    assert isinstance(orbit, search.FoundOrbit), orbit
    assert orbit.closure < 1e-8
    missed = search._closed(geometry, z0, PERIOD * (1 + 1e-5), atol, np.inf, symmetric=True)
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
                              _atol(frame["length"]), np.inf)
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
