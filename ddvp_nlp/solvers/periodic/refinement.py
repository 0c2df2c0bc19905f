"""Continuation in the number of intervals: a closed orbit solved on a coarse grid, then on
grids twice as fine, each started from the last one's nodes resampled by node index.

The energy rules place the nodes themselves: the step distribution of the discrete orbit (its
``tau ~ |w|^(-1/3)`` law and, on a rotation, the spike where ``w = f' H_zz f`` changes sign) is
the hard part of a start, and it is a property of the orbit, not of ``N``. Resampling by node
index keeps it: the node times are interpolated in the index (a new node halfway between two
old ones in index is halfway between them in time), the states by a cubic in time through the
old nodes. So every level starts with the step distribution of the level below, within
``O(tau^2)`` of its own, and the solver's work per level does not grow with ``N``.

Levels: ``N``, then halved while the next one stays at or above ``first`` (default
`FIRST_LEVEL`): ``100, 200, 400, 800`` for ``N = 800``, ``125, 250, 500, 1000`` for
``N = 1000``, just ``N`` below ``2 first``.

`continue_in_nodes` is the walk, for any solver of a grid: ``solve_periodic`` uses it
for its default start, and another problem (a periodic orbit of another system, a grid with
fixed ends and a prescribed energy: ``closed=False`` keeps the end nodes where they are) can
hand it its own solve of one level.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.interpolate import CubicSpline

from ...solution import Solution, Status
from .first_orbit import closing_shift

# The coarsest level: the pendulum's rotation at E = 2.5 took 5 Newton iterations from the
# predicted grid at N = 100 (start.predicted_grid), as at 200 and 800 (measured).
FIRST_LEVEL = 100


def node_levels(nodes: int, first: int = FIRST_LEVEL) -> list[int]:
    """The grids of the walk to ``nodes`` intervals, coarsest first (module docstring)."""
    levels = [int(nodes)]
    while (levels[-1] + 1) // 2 >= first:
        levels.append((levels[-1] + 1) // 2)
    return levels[::-1]


def refine_by_index(t, z, intervals: int, angles=(), closed: bool = True
                    ) -> tuple[np.ndarray, np.ndarray]:
    """``N + 1`` nodes from the grid ``(t, z)`` (``M + 1`` nodes), keeping its step
    distribution: node ``j`` at index ``j M / N`` of the old grid, its time linear in the
    index, its state a cubic in time through the old nodes; on a ``closed`` grid the last node
    is the first plus the whole turns of the ``angles`` (an open grid keeps its ends)."""
    t = np.asarray(t, float) - float(t[0])
    z = np.asarray(z, float)
    index = np.linspace(0.0, t.size - 1, intervals + 1)
    times = np.interp(index, np.arange(t.size), t)
    times[0], times[-1] = 0.0, t[-1]
    states = CubicSpline(t, z, axis=0)(times) if t.size >= 4 else np.column_stack(
        [np.interp(times, t, z[:, j]) for j in range(z.shape[1])])
    if closed:
        states[-1] = states[0] + closing_shift(states[0], states[-1], angles)
    else:
        states[0], states[-1] = z[0], z[-1]
    return times, states


def continue_in_nodes(solve: Callable[[int, np.ndarray, np.ndarray], Solution], t, z,
                      levels: list[int], angles=(), closed: bool = True
                      ) -> tuple[Solution, list[dict]]:
    """Walk ``levels`` (coarsest first): ``solve(intervals, t, z)`` on each, from ``(t, z)``
    (nodes of the first level: ``t`` of shape ``(intervals + 1,)``, ``z = (q, p)`` of shape
    ``(intervals + 1, 2n)``) and then from the last level's solution refined by
    `refine_by_index` (``closed``: a periodic grid; ``False`` for a grid with fixed ends).
    Returns the last level's solution and one record per level
    (``nodes``, ``status``, ``iterations``). A level whose equations do not hold (a status
    other than ``success`` and ``inaccurate``: a coarse grid may be too coarse for the
    accuracy check and still lead to the fine one) ends the walk there: its solution is
    returned, and the caller decides what to try next."""
    records = []
    solution = None
    for k, intervals in enumerate(levels):
        if k:
            t, z = refine_by_index(solution.t, np.hstack([solution.q, solution.p]),
                                   intervals, angles, closed)
        solution = solve(intervals, t, z)
        records.append({"intervals": intervals, "status": solution.status.code,
                        "iterations": solution.newton_iterations})
        if solution.status not in (Status.SUCCESS, Status.INACCURATE):
            break
    return solution, records
