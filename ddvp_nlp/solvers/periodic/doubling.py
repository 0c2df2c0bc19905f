"""Branch switching at a period doubling: the doubled-period branch's direction on the grid of
the orbit traversed twice, its first orbit off the old one, and the branch followed.

At a period doubling located by ``arclength.py`` (a multiplier pair through -1) the orbit
``x*`` of ``N`` intervals and period ``T``, traversed twice, is a solution of the periodic system
of ``2N`` intervals (its nodes repeated, the second period's times shifted by ``T``): the point
``y2*``. There the doubled family (every member of the followed family traversed twice) meets
the branch of orbits of period near ``2T``: the extended Jacobian ``[F_x, F_E]`` of the ``2N``
system has the two-dimensional kernel spanned by the doubled family's tangent ``t_1`` and the
new branch's direction ``t_2``, the eigenvector of the monodromy for the multiplier -1 carried
over the two periods (its states at node ``k + N`` are minus those at node ``k``). It is found
as at a branch point (``switching.kernel``: inverse iteration with the bordered matrix, ``t_1``
the followed family's tangent across the point, doubled); its relative residual and its
*antisymmetry* ``max_k |v_{k+N} + v_k| / max_k |v_k|`` (states only) are reported.

Each sign of ``t_2`` starts with the corrector on the ``2N`` grid at arclength ``ds`` from
``y2*`` (the walker's corrector, on the doubled grid), the step halved on failure; the orbit
found must lie off the doubled family (its component along ``t_1`` below half the step), pass
`solve_periodic`'s verification with the exact flow's check, have a period within
``NEAR_DOUBLED`` of ``2T`` (relative), and must not be the old orbit
traversed twice: its *half mismatch* ``d = max_k max_i |z_{k+N,i} - z_{k,i}| / S_i`` (``S`` the
accuracy check's scales of the motion) must exceed both twice the exact flow's largest distance
from it (``Verdict.error_max``: the exact orbit within that of the grid's is then not of period
``T`` either) and half the mismatch the step along ``t_2`` predicts (``2 ds max |v_k|``).

The two signs give one orbit: the orbit of ``-t_2`` is that of ``+t_2`` shifted by ``T`` (the
doubled system's symmetry ``z_k -> z_{k+N}``). This is checked, not assumed: the ``+t_2`` orbit
shifted by ``N`` nodes (node ``N`` first) is solved again at the energy of the ``-t_2`` orbit
(``solve_periodic``, the section's condition moving its node 0 onto the section), and the two
solutions of the same system at the same energy are compared node by node (``gap``, relative
to ``S``) against their distance before the shift (``apart``). When ``gap < SAME_ORBIT apart``
the branch is followed once and the message says so; otherwise both signs are followed as two
branches, and the message says that too.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .closed_grid import PeriodicAssembly
from .orbit import solve_periodic

# Two orbits are one when re-solved at one energy they differ by less than this part of their
# distance before the shift by T.
SAME_ORBIT = 1e-3
# The first orbit's period is within this part of twice the period at the doubling.
NEAR_DOUBLED = 0.25


@dataclass
class DoubledGrid:
    """The periodic system of ``2N`` intervals at the period doubling: what the walker's
    corrector reads (``closure``, ``arc``, ``assembly``, ``intervals``), with the doubled
    point ``y``, the doubled tangent ``along`` and the number of nodes ``2N + 1``."""

    closure: object
    arc: object
    assembly: PeriodicAssembly
    intervals: int
    nodes: int
    y: np.ndarray
    along: np.ndarray
    sizes: np.ndarray  # the orbit's size in each coordinate (the corrector's targets)


@dataclass
class FirstOrbit:
    """The first verified orbit of one sign off the period doubling, the arclength it was
    found at and its half mismatch (module docstring)."""

    orbit: object
    step: float
    mismatch: float


def doubled_grid(walker, y: np.ndarray, along: np.ndarray) -> DoubledGrid:
    """The ``2N`` system at ``y`` traversed twice, ``along`` doubled the same way (its period's
    change carried into the second period's times)."""
    intervals = 2 * walker.intervals
    assembly = PeriodicAssembly(walker.system, walker.assembly.scheme, intervals,
                                walker.integrals)
    shift = np.asarray(walker.closure.shift, float) * np.ones(2 * walker.system.n)
    closure = replace(walker.closure, shift=2 * shift)
    layout = walker.assembly.layout
    return DoubledGrid(closure, type(walker.arc)(assembly), assembly, intervals, intervals + 1,
                       twice(y, layout, shift), twice(along, layout, 0 * shift), walker.sizes)


def twice(vector: np.ndarray, layout, shift: np.ndarray) -> np.ndarray:
    """The nodes of ``vector = (nodes, unfoldings, E)`` on ``N`` intervals repeated over a second
    period: node ``N + k`` is node ``k`` with the period (node ``N``'s time) and ``shift`` (the
    closure's ``z_N - z_0``) added."""
    m, nodes = layout.m, layout.nodes
    z = vector[:nodes * m].reshape(nodes, m)
    offset = np.r_[z[-1, 0], shift]
    return np.r_[np.vstack([z, z[1:] + offset]).ravel(), vector[nodes * m:]]


def antisymmetry(direction: np.ndarray, grid: DoubledGrid) -> float:
    """``max_k |v_{k+N} + v_k| / max_k |v_k|`` over the states of ``direction`` on the ``2N``
    grid: 0 for the eigenvector of the multiplier -1 carried over two periods."""
    states = _states(direction, grid)
    half = grid.intervals // 2
    return float(np.max(np.abs(states[half:] + states[:half + 1])) / np.max(np.abs(states)))


def half_mismatch(orbit, grid: DoubledGrid, scale: np.ndarray) -> float:
    """``max_k max_i |z_{k+N,i} - z_{k,i}| / S_i`` of a ``2N``-interval orbit."""
    z = np.hstack([orbit.q, orbit.p])
    half = grid.intervals // 2
    shift = grid.closure.shift / 2
    return float(np.max(np.abs(z[half:] - z[:half + 1] - shift) / scale))


def orbit_scale(orbit) -> np.ndarray:
    """The accuracy check's scales ``S_i`` of the motion, or the largest ``|z_i|`` where the
    orbit was not checked (or a component never moves from 0: then the largest of all)."""
    z = np.hstack([orbit.q, orbit.p])
    if orbit.verdict is not None and orbit.verdict.scale is not None:
        return np.asarray(orbit.verdict.scale, float)
    size = np.max(np.abs(z), axis=0)
    return np.where(size > 0, size, np.max(size))


def first_orbit(walker, grid: DoubledGrid, direction: np.ndarray, step: float):
    """``(FirstOrbit, None)`` at arclength ``step`` along ``direction`` from the doubled point,
    or ``(None, why)`` (module docstring: off the doubled family, verified, off the old orbit
    traversed twice)."""
    point, _ = type(walker).correct_from(grid, grid.y, direction, step)
    if point is None:
        return None, "the corrector did not converge"
    off = abs(np.sum(grid.arc.weights * grid.along * (point - grid.y)))
    if off > 0.5 * step:
        return None, (f"the corrector went back to the doubled family (component {off:.2e} "
                      f"along its tangent at arclength {step:.3g})")
    orbit = _solved(walker, grid, point)
    if not orbit.success:
        return None, orbit.message
    doubled = float(grid.y[grid.assembly.layout.time_index()[-1]])
    if abs(orbit.orbit.period - doubled) > NEAR_DOUBLED * doubled:
        return None, (f"the orbit found has the period {orbit.orbit.period:.10g}, not near twice "
                      f"the doubling's {doubled / 2:.10g}")
    scale = orbit_scale(orbit)
    mismatch = half_mismatch(orbit, grid, scale)
    exact = 0.0 if orbit.verdict is None else float(orbit.verdict.error_max)
    predicted = 2 * step * float(np.max(np.abs(_states(direction, grid)) / scale))
    if mismatch <= 2 * exact or mismatch <= 0.5 * predicted:
        return None, (f"the orbit found is the old one traversed twice: its two periods differ "
                      f"by {mismatch:.2e} of its size, not above twice the exact flow's "
                      f"distance {exact:.2e} and half the {predicted:.2e} the step predicts")
    return FirstOrbit(orbit, step, mismatch), None


def same_orbit(walker, grid: DoubledGrid, plus, minus) -> tuple[float, float]:
    """``(gap, apart)``: the ``+t_2`` orbit shifted by ``T`` and solved again at the ``-t_2``
    orbit's energy, against the ``-t_2`` orbit (``gap``), and the two orbits' distance before
    the shift (``apart``), node by node relative to ``S`` (module docstring); ``gap`` is
    infinite when the shifted orbit is not solved."""
    half = grid.intervals // 2
    t, z = plus.t - plus.t[0], np.hstack([plus.q, plus.p])
    period = t[-1]
    shift = grid.closure.shift / 2
    moved_t = np.r_[t[half:] - t[half], t[1:half + 1] + period - t[half]]
    moved_z = np.vstack([z[half:], z[1:half + 1] + 2 * shift]) - shift
    n = walker.system.n
    shifted = solve_periodic(walker.system, energy=float(minus.orbit.energy), nodes=grid.nodes,
                             guess={"t": moved_t, "q": moved_z[:, :n], "p": moved_z[:, n:]},
                             **walker.common)
    scale = orbit_scale(minus)
    other = np.hstack([minus.q, minus.p])
    apart = float(np.max(np.abs(other - z) / scale))
    if not shifted.success:
        return np.inf, apart
    gap = float(np.max(np.abs(other - np.hstack([shifted.q, shifted.p])) / scale))
    return gap, apart


def _solved(walker, grid: DoubledGrid, point: np.ndarray):
    """``solve_periodic`` on the ``2N`` grid from the corrector's ``point`` (its
    verification)."""
    t, q, p, _ = grid.assembly.layout.unpack(point[:-1])
    return solve_periodic(walker.system, energy=float(point[-1]), nodes=grid.nodes,
                          guess={"t": t, "q": q, "p": p}, **walker.common)


def _states(vector: np.ndarray, grid: DoubledGrid) -> np.ndarray:
    layout = grid.assembly.layout
    return vector[:layout.nodes * layout.m].reshape(layout.nodes, layout.m)[:, 1:]
