"""The grid a switched branch is followed on, chosen from an accuracy target for its periods, and
every orbit's period error estimated against a coarser grid.

The closed grid's period is second order: ``T_N = T + C h^2 + ...`` with ``h ~ 1 / N`` (the
grid's nodes are placed by the scheme's energy rows, not by the user, so ``N`` is the one knob).
``C`` changes slowly along a branch (on the CR3BP's halo branches ``T_N - T`` was 2.25e-4 to
2.26e-4 over 20 orbits at N = 200), so it is measured once, at the first orbit of a half on
the family's grid ``N``: that orbit is solved again on ``2N`` at its energy (from its nodes
resampled by node index, ``refinement.refine_by_index``), and Richardson's rule gives the
``N`` grid's error ``e_N = 4 (T_N - T_2N) / 3``. The half is then followed on the least
``N' >= N`` (a multiple of ``ROUNDING``) with ``e_N (N / N')^2 <= SAFETY tol T``, ``tol`` the
target relative to the period (``Switch.tol``); its first orbit there is solved from the ``N``
one's nodes at its energy.

After the walk, every orbit of the half is solved again on a reference grid ``R`` at its
energy (the family's ``N`` when ``N' > N``, else ``2N``), and the two periods give that orbit's
own estimate of its error on ``N'``::

    e_N' = |T_R - T_N'| R^2 / |N'^2 - R^2|

An orbit whose estimate is above ``tol T`` is reported, and the half is not complete: the
target is met orbit by orbit, not assumed from the first. What is reported as each orbit's
period is ``T_N'``, the period of that orbit on that grid; the estimates are not added to it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .orbit import solve_periodic
from .refinement import refine_by_index

# The chosen grid's estimated error is at most this fraction of the target; N' is rounded up
# to a multiple of ROUNDING intervals.
SAFETY = 0.8
ROUNDING = 10
# The halves' step control (arclength._Walker.walk's turning): the predictor's miss, relative
# to the step, aimed at (about half the tangent's turn per step, in radians).
TURNING = 0.05
# ... and its longest step, in the family's longest steps.
GROWTH = 20.0


@dataclass
class BranchGrid:
    """The grid of a half and what chose it: ``intervals`` (``N'``), the family's ``coarse``
    grid (``N``), the first orbit's relative period error estimated on ``N`` by ``N`` against
    ``2N`` (``estimate``), the target (``tol``), and after the walk each orbit's relative
    estimate on ``N'`` (``errors``; ``None`` for an orbit whose coarse solve failed)."""

    intervals: int
    coarse: int
    estimate: float
    tol: float
    errors: list = field(default_factory=list)

    def as_dict(self) -> dict:
        return {"intervals": self.intervals, "coarse_intervals": self.coarse,
                "first_estimate": self.estimate, "tol": self.tol, "errors": list(self.errors)}


def resolved(walker, orbit, intervals: int):
    """``orbit`` solved again on ``intervals`` at its energy, from its nodes resampled by node
    index (a verified `Solution`, or the failed one)."""
    angles = tuple(i for i, w in enumerate(orbit.orbit.winding) if w)
    t, z = refine_by_index(orbit.t, np.hstack([orbit.q, orbit.p]), intervals, angles)
    n = walker.system.n
    return solve_periodic(walker.system, energy=float(orbit.orbit.energy), nodes=intervals + 1,
                          guess={"t": t, "q": z[:, :n], "p": z[:, n:]}, **walker.common)


def chosen_grid(walker, first, tol: float):
    """``(grid, first_on_grid, why)``: the half's grid and its first orbit there (module
    docstring), or ``(None, None, why)`` when the orbit on ``2N`` or on ``N'`` was not
    found."""
    coarse = walker.intervals
    finer = resolved(walker, first, 2 * coarse)
    if not finer.success:
        return None, None, f"the first orbit on {2 * coarse} intervals: {finer.message}"
    period = float(first.orbit.period)
    estimate = 4.0 * (period - float(finer.orbit.period)) / 3.0 / period
    wanted = coarse * math.sqrt(abs(estimate) / (SAFETY * tol))
    intervals = max(coarse, ROUNDING * math.ceil(wanted / ROUNDING))
    grid = BranchGrid(intervals, coarse, estimate, tol)
    if intervals == coarse:
        return grid, first, None
    if intervals == 2 * coarse:
        return grid, finer, None
    orbit = resolved(walker, first, intervals)
    if not orbit.success:
        return None, None, f"the first orbit on {intervals} intervals: {orbit.message}"
    return grid, orbit, None


def resampled(direction: np.ndarray, layout, intervals: int, unfoldings: int) -> np.ndarray:
    """A direction of the ``layout`` grid's unknowns (nodes, unfoldings, energy) on
    ``intervals`` intervals: node values linear in the node index, unfoldings zero, the
    energy's component kept (it orients the first tangent only)."""
    m = layout.m
    nodes = direction[:layout.nodes * m].reshape(layout.nodes, m)
    index = np.linspace(0.0, layout.nodes - 1, intervals + 1)
    moved = np.column_stack([np.interp(index, np.arange(layout.nodes), nodes[:, j])
                             for j in range(m)])
    return np.r_[moved.ravel(), np.zeros(unfoldings), direction[-1]]


def checked_members(walker, grid: BranchGrid, members) -> str | None:
    """Each member's relative period error on ``grid.intervals`` (module docstring), into
    ``grid.errors``; the message when one is above the target or cannot be estimated, else
    ``None``."""
    reference = grid.coarse if grid.intervals > grid.coarse else 2 * grid.intervals
    ratio = reference ** 2 / abs(grid.intervals ** 2 - reference ** 2)
    for member in members:
        other = resolved(walker, member.orbit, reference)
        period = float(member.orbit.orbit.period)
        grid.errors.append(abs(float(other.orbit.period) - period) * ratio / period
                           if other.success else None)
    for j, error in enumerate(grid.errors):
        if error is None:
            return (f"orbit {j + 1}'s period error was not estimated (its orbit on "
                    f"{reference} intervals was not found)")
        if error > grid.tol:
            return (f"orbit {j + 1}'s estimated relative period error {error:.2e} on "
                    f"{grid.intervals} intervals is above the target {grid.tol:g}")
    return None


def half_walker(walker, first, direction, settings, tol):
    """``(half, grid, why)``: the walker of a half (``type(walker)``) through ``first`` with its
    first tangent along ``direction``, on the family's grid when ``tol`` is ``None`` (``grid``
    ``None``), else on the grid chosen for ``tol`` (`chosen_grid`); ``(None, None, why)`` when
    that grid's first orbit was not found."""
    nodes, previous, grid = walker.nodes, direction, None
    if tol is not None:
        grid, first, why = chosen_grid(walker, first, tol)
        if grid is None:
            return None, None, why
        layout = walker.assembly.layout
        nodes = grid.intervals + 1
        previous = resampled(direction, layout, grid.intervals, layout.unfoldings)
    half = type(walker)(walker.system, first, nodes, walker.common, settings,
                        (-np.inf, np.inf), previous=previous)
    return half, grid, None


def checked_half(half, grid, members, complete: bool, message: str) -> tuple[bool, str]:
    """``(complete, message)`` of a walked half with its members' period errors checked
    (`checked_members`; unchanged without a ``grid``)."""
    if grid is None:
        return complete, message
    why = checked_members(half, grid, members)
    worst = max((e for e in grid.errors if e is not None), default=0.0)
    said = (f"{grid.intervals} intervals for relative period error {grid.tol:g} (estimated "
            f"{abs(grid.estimate):.1e} on {grid.coarse}; largest along the half {worst:.1e})")
    if why is not None:
        return False, f"{message}; {said}; {why}"
    return complete, f"{message}; {said}"
