"""A switched half's grid chosen from a period accuracy target (``branch_grid.py``): on the
pitchfork of two coupled oscillators (as ``test_switching.py``, N = 40) the half is followed on
a finer grid, every orbit's estimated period error is within the target and matches the error
against the same orbit on a much finer grid; the same under an energy offset and swapped
coordinates; bad targets refused by name; the direction's resampling."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import (
    Continuation,
    HamiltonianSystem,
    InputError,
    Switch,
    follow_periodic_family,
)
from ddvp_nlp.solvers.periodic.branch_grid import resampled, resolved
from ddvp_nlp.solvers.periodic.closed_grid import ClosedLayout

W, BETA = 0.9, 0.5
NODES, HALF, TOL = 41, 2, 1e-3


def _oscillators(swap: bool = False, offset: float = 0.0) -> HamiltonianSystem:
    a, b = (1, 0) if swap else (0, 1)

    def hamiltonian(q, p, t):
        return ((p[a] ** 2 + q[a] ** 2) / 2 + (p[b] ** 2 + W ** 2 * q[b] ** 2) / 2
                + BETA * q[a] ** 2 * q[b] ** 2 + offset)
    return HamiltonianSystem(hamiltonian, 2, name=f"branch_grid_{int(swap)}_{offset}")


def _follow(swap: bool = False, offset: float = 0.0, tol=TOL):
    a = 1 if swap else 0
    t = np.linspace(0.0, 2 * np.pi, NODES)
    amplitude = np.sqrt(2 * 0.1)
    q, p = np.zeros((NODES, 2)), np.zeros((NODES, 2))
    q[:, a], p[:, a] = amplitude * np.cos(t), -amplitude * np.sin(t)
    return follow_periodic_family(
        _oscillators(swap, offset), (0.1 + offset, 0.3 + offset), nodes=NODES,
        section=f"p{a + 1}=0", guess={"t": t, "q": q, "p": p},
        continuation=Continuation(step=0.05, switch=Switch(orbits=HALF, tol=tol),
                                  exact=False, confirm=False))


@pytest.fixture(scope="module")
def switched():
    return _follow()


def test_the_half_is_followed_on_the_grid_its_target_asks_for(switched):
    for branch in switched.branches:
        half = branch.family
        grid = half.grid
        assert half.complete and len(half.members) == HALF, half.message
        assert grid["coarse_intervals"] == NODES - 1 and grid["intervals"] > NODES - 1
        assert grid["intervals"] % 10 == 0 and grid["tol"] == TOL
        # the first orbit's error on N, scaled to N', is within the target (the choice)
        assert abs(grid["first_estimate"]) * (40 / grid["intervals"]) ** 2 <= TOL
        assert all(m.orbit.t.size == grid["intervals"] + 1 for m in half.members)
        assert len(grid["errors"]) == HALF and max(grid["errors"]) <= TOL
        assert f"{grid['intervals']} intervals for relative period error" in half.message


@pytest.mark.slow(why="study")
def test_each_estimate_matches_the_error_against_a_much_finer_grid(switched):
    """The estimate (N' against N) beside ``T_N' - T_4N'`` (4/3 of it: Richardson) for every
    orbit: within a fifth of each other."""
    half = switched.branches[0].family
    intervals = half.grid["intervals"]

    class Walker:  # what resolved() reads of a walker
        system = _oscillators()
        common = {"section": "p1=0", "scheme": "vddvp", "params": None, "integrals": (),
                  "angles": (), "options": None}
    for member, estimate in zip(half.members, half.grid["errors"], strict=True):
        fine = resolved(Walker, member.orbit, 4 * intervals)
        assert fine.success
        period = member.orbit.orbit.period
        error = 16 / 15 * abs(period - fine.orbit.period) / period
        assert abs(error - estimate) <= 0.2 * error


@pytest.mark.slow(why="repetition")
def test_swapped_coordinates_and_an_energy_offset_choose_the_same_grid(switched):
    other = _follow(swap=True, offset=0.25)
    mine = {b.label[0]: b.family for b in switched.branches}
    theirs = {b.label[0]: b.family for b in other.branches}
    for sign in "+-":
        assert mine[sign].grid["intervals"] == theirs[sign].grid["intervals"]
        assert np.allclose(mine[sign].grid["errors"], theirs[sign].grid["errors"], rtol=1e-4)
        for a, b in zip(mine[sign].members, theirs[sign].members, strict=True):
            assert abs(b.energy - 0.25 - a.energy) < 1e-9
            assert abs(b.orbit.orbit.period - a.orbit.orbit.period) < 1e-9


@pytest.mark.parametrize("tol", [0.0, -1e-4, float("nan"), float("inf"), "1e-4", True])
def test_a_bad_target_is_refused_by_name(tol):
    with pytest.raises(InputError, match="tol"):
        Switch(tol=tol)


@settings(max_examples=25, deadline=None)
@given(st.floats(-1e6, 0.0) | st.sampled_from([float("nan"), float("-inf")]))
def test_any_non_positive_target_is_refused(tol):
    with pytest.raises(InputError, match="tol"):
        Switch(tol=tol)


def test_no_target_keeps_the_family_grid():
    assert Switch(tol=None).tol is None and Switch().tol == 3e-5


@settings(max_examples=25, deadline=None)
@given(st.integers(4, 30), st.integers(4, 60), st.floats(-3, 3), st.floats(-3, 3))
def test_the_direction_is_resampled_by_node_index(coarse, fine, slope, energy):
    """Node values linear in the node index stay linear in it; the unfoldings are zero, the
    energy's component is kept."""
    layout = ClosedLayout(2, coarse)
    nodes = slope * np.arange(layout.nodes)[:, None] / coarse + np.arange(layout.m)[None, :]
    direction = np.r_[nodes.ravel(), np.ones(layout.unfoldings), energy]
    moved = resampled(direction, layout, fine, 1)
    assert moved.size == (fine + 1) * layout.m + 2 and moved[-1] == energy and moved[-2] == 0
    expected = slope * np.arange(fine + 1)[:, None] / fine + np.arange(layout.m)[None, :]
    assert np.allclose(moved[:-2].reshape(fine + 1, layout.m), expected, atol=1e-12)
