"""What the search says of its orbits is true (the fresh-eyes trial of session 56): one
verdict from the exact index with the documented tolerance, a grid refinement that lands on
another orbit flagged (and which orbit it is), the orbits listed bounded by max_returns, and
the seeds counted per way of searching."""

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp.solvers.periodic.floquet import DEFAULT_TOL, verdict
from ddvp_nlp.solvers.periodic.search import (
    FoundOrbit,
    SearchRegion,
    _within_returns,
)
from ddvp_nlp.solvers.periodic.search_grid import (
    ANOTHER,
    GAP,
    compare_grid,
    identify_landing,
)
from ddvp_nlp.solvers.periodic.section_map import SearchSection

SECTION = SearchSection(index=1, other=0, value=0.0, label="q2=0")


def found(period=1.0, index=0.5, returns=1, start=(1.0, 0.0, 0.0, 1.0), crossings=None,
          tol=DEFAULT_TOL, size=1.0):
    """A found orbit through ``start`` whose positions and momenta each range over ``size``
    (its own size, `search_grid.own_size`)."""
    start = np.asarray(start, float)
    rows = np.atleast_2d(start[[0, 2]]) if crossings is None else np.asarray(crossings, float)
    path = start + size * np.linspace(-0.5, 0.5, 3)[:, None] * np.ones(4)
    return FoundOrbit(period=period, start=start, returns=returns, symmetric=False,
                      multipliers=np.ones(2), index=index, closure=1e-12, crossings=rows,
                      path=path, tol=tol)


def grid(period, start, error=1e-3, name="accurate"):
    """A stand-in for solve_periodic's solution: nodes from 0 to ``period``, node 0 at
    ``start``, its accuracy check's largest error ``error``."""
    start = np.asarray(start, float)
    return SimpleNamespace(success=True, t=np.array([0.0, period]), q=np.tile(start[:2], (2, 1)),
                           p=np.tile(start[2:], (2, 1)), status=SimpleNamespace(code="success"),
                           verdict=SimpleNamespace(error_max=error, name=name))


@pytest.mark.parametrize("index, tol, expected", [
    (2 - 1e-11, DEFAULT_TOL, "marginal"),   # the trial's orbits: listed stable before
    (-2 + 1e-9, DEFAULT_TOL, "marginal"),
    (2 - 1e-11, 1e-12, "stable"),
    (1.5, DEFAULT_TOL, "stable"),
    (2.0 + 1e-3, DEFAULT_TOL, "unstable"),
])
def test_the_verdict_is_the_exact_index_with_the_tolerance(index, tol, expected):
    assert found(index=index, tol=tol).verdict == expected


@settings(max_examples=80, derandomize=True, deadline=None, database=None)
@given(st.floats(-10, 10), st.floats(1e-12, 1e-1))
def test_one_classification_whatever_the_grid_said(index, tol):
    """The verdict is floquet's of the exact index, with or without a grid stability (a grid
    that says otherwise does not change it), and within tol of +-2 it is marginal."""
    orbit = found(index=index, tol=tol)
    expected = verdict(np.array([index], complex), tol)
    assert orbit.verdict == expected
    orbit.stability = SimpleNamespace(verdict="stable" if expected != "stable" else "unstable")
    assert orbit.verdict == expected
    if abs(abs(index) - 2) < tol:
        assert orbit.verdict == "marginal"


def test_the_rows_and_the_figure_use_the_orbits_verdict(tmp_path):
    from ddvp_nlp.io.search_files import orbit_rows

    orbits = [found(period=1.0, index=2 - 1e-11), found(period=2.0, index=0.3)]
    search = SimpleNamespace(orbits=orbits)
    rows = orbit_rows(search)
    assert [row["verdict"] for row in rows] == ["marginal", "stable"]
    assert [row["grid_verdict"] for row in rows] == ["not refined"] * 2


@settings(max_examples=60, derandomize=True, deadline=None, database=None)
@given(st.floats(1e-3, 1e3), st.floats(-3, 3), st.floats(1e-6, 1e-2), st.floats(0.0, 5.0),
       st.floats(0.0, 5.0), st.floats(1e-3, 1e3), st.sampled_from([0.0, 2000.0, -3e4]))
def test_a_grid_further_than_its_own_error_is_another_orbit(period, u, error, dt, du, unit,
                                                            offset):
    """The grid's orbit is this orbit's refinement exactly when its period and start are within
    the grid's own error of the exact orbit's (GAP times it; the start against the orbit's own
    size); the same in any unit of time (the period scaled, the gaps relative) and wherever
    the origin of q1 (the start moved by ``offset``). The start's gap was over ``max |start|``:
    with the origin 2000 away a grid ``du`` errors off passed as within ``du / 2000``."""
    start = (1.0 + u * u, 0.0, 0.0, 1.0)
    moved = (start[0] + du * error, 0.0, 0.0, 1.0)  # the orbit's own size is 1
    # how far from GAP a verdict is certain: the round-off of the start's position, in errors
    slack = 1e-9 + 8 * np.finfo(float).eps * (abs(offset) + start[0]) / error
    outcomes = []
    for scale, shift in ((1.0, 0.0), (unit, 0.0), (1.0, offset)):
        orbit = found(period=scale * period, start=np.add(start, (shift, 0, 0, 0)))
        check = compare_grid(orbit, grid(scale * period * (1 + dt * error),
                                         np.add(moved, (shift, 0, 0, 0)), error), SECTION)
        outcomes.append(check.verdict)
        if max(dt, du) <= GAP * (1 - slack):
            assert check.verdict == "accurate" and check.refines
        if max(dt, du) >= GAP * (1 + slack):
            assert check.verdict == ANOTHER and not check.refines
    assert len(set(outcomes)) == 1 or abs(max(dt, du) - GAP) < GAP * slack


def test_a_failed_grid_is_said_failed():
    orbit = found()
    assert compare_grid(orbit, None, SECTION).verdict == "failed"
    assert compare_grid(orbit, SimpleNamespace(success=False), SECTION).verdict == "failed"


def test_a_grid_without_an_accuracy_check_is_not_flagged():
    """No estimate (the accuracy check was not made): the gaps are given, nothing is claimed."""
    solution = grid(1.5, (1.0, 0.0, 0.0, 1.0))
    solution.verdict = None
    check = compare_grid(found(), solution, SECTION)
    assert check.verdict == "success" and abs(check.period_gap - 0.5) < 1e-12


def test_the_orbit_the_grid_landed_on_is_named():
    """The trial's orbit 5 (T = 77.604, index 2 - 1e-11) whose grid went to 76.185: the double
    cover of orbit 2 (T = 38.080, its crossing at q1 = 1.1867)."""
    two = found(period=38.08019738, start=(1.18668293, 0.0, 0.0, 1.44850480))
    five = found(period=77.60422837, index=2 - 1e-11, start=(0.97589886, 0.0, -0.27433993, 1.4))
    solution = grid(76.18522004, (1.18720386, 0.0, 8.05e-6, 1.4), error=3.2e-3)
    five.solution = solution
    five.grid = compare_grid(five, solution, SECTION)
    five.note = "the grid's refinement landed on another orbit (x): not this orbit's refinement"
    assert five.grid.verdict == ANOTHER
    identify_landing([two, five], SECTION)
    assert five.grid.landed == "the grid's orbit is orbit 1 covered twice"
    assert "orbit 1 covered twice" in five.note
    assert two.grid is None  # an orbit whose grid was not flagged is left alone


def test_orbits_beyond_max_returns_are_said_not_listed():
    orbits = [found(period=1.0, returns=1), found(period=2.0, returns=3)]
    kept, beyond = _within_returns(orbits, 2)
    assert kept == orbits[:1]
    assert len(beyond) == 1 and "3 upward crossings, beyond max_returns = 2" in beyond[0].reason


@settings(max_examples=40, derandomize=True, deadline=None, database=None)
@given(st.lists(st.tuples(st.integers(1, 500), st.integers(0, 500)), min_size=1, max_size=2))
def test_the_seeds_are_said_per_way(parts):
    parts = tuple((f"way {j}", n, min(a, n)) for j, (n, a) in enumerate(parts))
    region = SearchRegion(energy=1.0, section="q2=0", window=(-1.0, 1.0), momentum=None,
                          seeds=sum(n for _, n, _ in parts),
                          accessible=sum(a for _, _, a in parts), reversing=None,
                          max_returns=2, horizon=10.0, parts=parts)
    said = region.describe()
    assert f"{region.seeds} seeds of which {region.accessible} accessible" in said
    assert "orbits of up to 2 upward crossings per period" in said
    if len(parts) == 2:
        for where, n, a in parts:
            assert f"{n} {where} ({a} accessible)" in said


def magnetic(q, p, t, B, m, k):
    """The trial's charged particle: a uniform field B along z, a weak anharmonic well."""
    x, y = q[0], q[1]
    px, py = p[0] + B * y / 2, p[1] - B * x / 2
    return (px ** 2 + py ** 2) / (2 * m) + k * (x ** 2 + y ** 2) / 2 + 0.1 * k * x ** 4


@pytest.mark.slow(why="study")
def test_the_charged_particles_grid_lands_on_a_double_cover():
    """The trial's search (E = 0.305, q2 = 0, 60 seeds): the orbit of period 77.604 has index
    2 to 1e-11 (marginal, a nearly degenerate family: the guiding centre's adiabatic invariant
    makes the motion nearly integrable), and its grid of 201 nodes closes on the double cover of
    the orbit of period 38.080 (T = 76.185): flagged and named, the others refined. The
    orbits listed have at most max_returns upward crossings."""
    from ddvp_nlp import HamiltonianSystem, find_periodic_orbits

    system = HamiltonianSystem(magnetic, n=2, params={"B": 2.0, "m": 1.0, "k": 0.3})
    search = find_periodic_orbits(system, energy=0.305, section="q2=0", seeds=60)
    assert all(orbit.returns <= 2 for orbit in search.orbits)
    periods = [orbit.period for orbit in search.orbits]
    long = next(o for o in search.orbits if abs(o.period - 77.6042284) < 1e-5)
    assert long.verdict == "marginal" and abs(long.index - 2) < 1e-9
    assert long.grid.verdict == ANOTHER and abs(long.grid.period - 76.185) < 1e-2
    j = next(i for i, period in enumerate(periods) if abs(period - 38.0801974) < 1e-5)
    assert long.grid.landed == f"the grid's orbit is orbit {j + 1} covered twice"
    short = search.orbits[j]
    assert short.grid.verdict == "accurate" and short.grid.period_gap < short.grid.estimate
