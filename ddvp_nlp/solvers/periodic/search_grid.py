"""An orbit found by the search (``search.py``) refined on the discrete grid, and whether the
grid's orbit is that orbit: `refine_found`, `GridRefinement`.

``solve_periodic`` is started from the exact orbit (its flow at ``4 N`` equal times) and its
own accuracy check follows the exact flow from the grid's first node over the grid's period.
That check can pass on a grid orbit that is not the exact orbit it started from: where the
exact orbits form a near-degenerate family (multipliers 1 to round-off, the stability index
2: a resonant torus of a nearly integrable system, e.g. a charged particle's guiding centre in
a strong field), the grid's own error of ``O(tau^2)`` moves the closing condition to another
torus, whose nearly closed motion has another period, and the flow from the grid's first node
follows that motion for one period within the grid's error. So the grid orbit is also compared
with the exact orbit it was started from: its period, ``|T_grid - T| / T``, and its first node
on the section, the distance of its ``u = (q_o, p_o)`` from the exact orbit's nearest upward
crossing over the orbit's size. Where either is more than `GAP` times the grid's own error
estimate (the accuracy check's largest error, relative to the orbit's size), the grid has
landed on another orbit: its verdict is ``another orbit``, and its period and index are not
presented as this orbit's.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...errors import InputError
from ..exact.flow import exact_flow
from .section_map import RTOL

# the gaps allowed, in units of the grid's own error estimate: the period's and the start's
# (measured on orbits the grid does refine, Hill's, Henon-Heiles', Pullen-Edmonds', a charged
# particle's: 0.04 to 0.5 of it; 53 where the grid landed on another orbit), and the
# stability index's (0.1 to 3.1 of it there: an index is a sum of multipliers, the orbit's
# growth amplifies its error)
GAP = 1.0
INDEX_GAP = 10.0
ANOTHER = "another orbit"


@dataclass(frozen=True)
class GridRefinement:
    """The grid's refinement of one found orbit: ``verdict`` (the grid's accuracy verdict
    where it refines this orbit; ``another orbit`` where its period or start is further from
    the exact orbit's than `GAP` times its own ``estimate``; ``failed``), ``period`` (the
    grid's), ``period_gap`` (``|T_grid - T| / T``), ``start_gap`` (its first node's distance
    from the exact orbit's nearest upward crossing, relative to the orbit's size) and
    ``estimate`` (the grid's largest error, relative to the orbit's size); ``index_gap``: the
    grid's stability index's distance from the exact flow's, over ``max(2, |index|)`` (where
    it refines the orbit: an index far off with the orbit in place is said, `index_off`); NaN
    where the grid gave no orbit."""

    verdict: str
    period: float = float("nan")
    period_gap: float = float("nan")
    start_gap: float = float("nan")
    estimate: float = float("nan")
    index_gap: float = float("nan")
    landed: str = ""

    @property
    def refines(self) -> bool:
        """Whether the grid's orbit is the found orbit (within its own error)."""
        return self.verdict not in (ANOTHER, "failed")

    @property
    def index_off(self) -> bool:
        """Whether the grid's index is further from the exact flow's than `INDEX_GAP` times the
        grid's own error (the orbit in place, its stability not: a nearly degenerate orbit)."""
        return self.refines and self.index_gap > INDEX_GAP * self.estimate

    def describe(self) -> str:
        if self.verdict == "failed":
            return "the grid gave no orbit"
        landed = f"{self.landed}: " if self.landed else ""
        return (f"{landed}grid T = {self.period:.10g}: period {self.period_gap:.1e} and start "
                f"{self.start_gap:.1e} of the exact orbit's, its own error {self.estimate:.1e}")


def own_size(path: np.ndarray) -> np.ndarray:
    """The orbit's own size for each component of ``z = (q1, q2, p1, p2)`` (rows of ``path``,
    over at least one period): the largest range of a position over it for ``q1`` and ``q2``,
    of a momentum for ``p1`` and ``p2``. Points of an orbit compared to a fraction of it are
    one point or two whatever the origin of the coordinates and their units (of length, of
    momentum, of time). ``max |z|`` at the start, used before, grew with the distance from the
    origin: Hill's problem with ``x`` shifted by 2000 cut its orbits of period ``3.2102332`` to
    half their period (the start and the crossing half a period on, 1.97 apart, were within
    ``1e-3`` of 2000), and two orbits of one period a few of their sizes apart merged
    (``tests/library/periodic/test_search_distinct.py``); the search's closure and the
    grid's start gap (`compare_grid`) are measured against it too."""
    ranges = np.ptp(np.asarray(path, float), axis=0)
    return np.repeat([ranges[:2].max(), ranges[2:].max()], 2)


def compare_grid(orbit, solution, section) -> GridRefinement:
    """`GridRefinement` of the grid's ``solution`` (``solve_periodic``) against the exact
    ``orbit`` (a ``FoundOrbit``) on ``section`` (a ``SearchSection``; module docstring)."""
    if solution is None or not solution.success:
        return GridRefinement("failed")
    period = float(solution.t[-1] - solution.t[0])
    period_gap = abs(period - orbit.period) / orbit.period
    z0 = np.concatenate([solution.q[0], solution.p[0]])
    start_gap = _start_gap(orbit, z0[section.free], section)
    verdict = solution.verdict
    estimate = float(verdict.error_max) if verdict is not None else float("nan")
    name = verdict.name if verdict is not None else solution.status.code
    # no accuracy check made (none asked for): no estimate to compare with, nothing flagged
    far = bool(np.isfinite(estimate)) and not (max(period_gap, start_gap) <= GAP * estimate)
    return GridRefinement(ANOTHER if far else name, period, period_gap, start_gap, estimate)


def _start_gap(orbit, u0: np.ndarray, section) -> float:
    """The distance of ``u0 = (q_o, p_o)`` from the orbit's nearest upward crossing, each
    component over the orbit's own size (`own_size`: the grid's error estimate is relative to
    the orbit's ranges too). It was over ``max |start|``, which grows with the distance from
    the coordinates' origin: with the origin 2000 away a grid 0.2 of the orbit's size off its
    start passed as within its error of 3e-3."""
    scale = own_size(orbit.path)[section.free]
    with np.errstate(divide="ignore", invalid="ignore"):
        gaps = np.max(np.abs(np.atleast_2d(orbit.crossings) - u0) / scale, axis=1)
    return float(np.min(gaps))


def refine_found(system, orbit, energy: float, section, nodes: int, params,
                 tol: float) -> None:
    """The orbit on the discrete grid (``solve_periodic`` from it), compared with it
    (`compare_grid`: ``orbit.grid``), and its stability there (tolerance ``tol``)."""
    from .floquet import periodic_stability
    from .orbit import solve_periodic

    theta = system.parameter_vector(params)
    flow = exact_flow(system)
    # the guess's absolute tolerance from the orbit's own size (it was RTOL itself, absolute:
    # 1e-12 of a unit of length or momentum whatever the units)
    run = flow.run(orbit.start, 0.0, orbit.period, theta, rtol=RTOL,
                   atol=RTOL * own_size(orbit.path))
    t = np.linspace(0.0, orbit.period, 4 * nodes)
    z = run.z(t)
    z[-1] = z[0]
    guess = {"t": t, "q": z[:, :2], "p": z[:, 2:]}
    label = f"q{section.index + 1}={section.value:g}"
    try:
        solution = solve_periodic(system, energy=energy, nodes=nodes, section=label,
                                  guess=guess, params=params)
    except InputError as error:
        orbit.note = f"not refined on the grid: {error}"
        orbit.grid = GridRefinement("failed")
        return
    orbit.solution = solution
    orbit.grid = compare_grid(orbit, solution, section)
    if not solution.success:
        orbit.note = f"the grid's refinement failed: {solution.message[:200]}"
        return
    orbit.stability = periodic_stability(system, solution, params=params, tol=tol)
    indices = orbit.stability.indices.real
    if indices.size:
        orbit.grid = replace(orbit.grid, index_gap=float(
            abs(indices[0] - orbit.index) / max(2.0, abs(orbit.index))))
    if not orbit.grid.refines:
        orbit.note = (f"the grid's refinement landed on another orbit ({orbit.grid.describe()}"
                      "): not this orbit's refinement")


def identify_landing(orbits: list, section) -> None:
    """For each orbit whose grid landed on another orbit (`compare_grid`), which of the others
    found (numbered from 1 in the list's order) the grid's orbit is, covered ``m`` times: its
    period ``m T_j`` and a start on ``T_j``'s crossings, each within the grid's own error (a
    nearly degenerate orbit's grid sliding onto the double cover of a neighbour: the charged
    particle at E = 0.305, docs/periodic/search.md)."""
    for orbit in orbits:
        check = getattr(orbit, "grid", None)
        if check is None or check.verdict != ANOTHER:
            continue
        z0 = np.concatenate([orbit.solution.q[0], orbit.solution.p[0]])
        u0 = z0[section.free]
        for j, other in enumerate(orbits):
            covers = round(check.period / other.period)
            if other is orbit or covers < 1:
                continue
            gap = max(abs(check.period - covers * other.period) / (covers * other.period),
                      _start_gap(other, u0, section))
            if gap <= GAP * check.estimate:
                times = {1: "", 2: " covered twice"}.get(covers, f" covered {covers} times")
                orbit.grid = replace(check, landed=f"the grid's orbit is orbit {j + 1}{times}")
                orbit.note = orbit.note.replace("landed on another orbit (",
                                                f"landed on another orbit ({orbit.grid.landed}; ")
                break
