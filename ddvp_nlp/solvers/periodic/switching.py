"""Branch switching at a branch point of a followed family: the new branch's direction from the
kernel of the extended system, and its two halves followed by the same continuation.

At a branch point ``y* = (x*, E*)`` located by ``arclength.py`` (a multiplier pair through +1
without a fold: a symmetry-breaking pitchfork such as the halo family's birth from the planar
Lyapunov family) the extended Jacobian ``[F_x, F_E]`` of the periodic system has a
two-dimensional kernel: the followed family's tangent ``t_1`` and the new branch's direction
``t_2``. The bordered matrix ``[[F_x, F_E], [W t_1^T, 0]]`` (``W`` the arclength weights) then
has the one-dimensional kernel ``t_2``, found by inverse iteration with its sparse LU (three
solves from a fixed start); ``t_2`` is made ``W``-orthogonal to ``t_1`` and of unit ``W``-norm.
Its relative residual ``|[F_x, F_E] t_2| / (|[F_x, F_E]| |t_2|)`` (infinity norms) is reported,
and a direction whose residual is above ``KERNEL_TOL`` is refused: the point is no branch point
of the grid's system.

Each half of the new branch (``+t_2`` and ``-t_2``) starts with the corrector at arclength
``ds`` from ``y*`` along it (``<W t_2, y - y*> = ds``, the step halved on failure down to
``min_step``); the orbit found must lie off the followed family (its component along ``t_1``
below half its component along ``t_2``) and pass `solve_periodic`'s verification, the exact
flow's check included. From it the continuation walks on (``arclength._Walker``, the first
tangent oriented along ``+-t_2``) for ``orbits`` members in all, every member verified like the
family's, with its stability and the bifurcations between members located. A half that cannot
be followed says why; no orbit that was not verified is reported.

Each half is named by the coordinate that moves most along its direction (a position if any
moves; ``+q3``: ``q3`` grows at the first node where it moves most). At the CR3BP's halo birth
the kernel is out of the plane and the two halves are each other's images under ``z -> -z``
(the northern and southern halo families).

At a period doubling (a pair through -1) the new branch's orbits have twice the period: the
direction is found on the grid of the orbit traversed twice, and the two signs of it give one
orbit shifted by half its period (``doubling.py``); that branch is followed once.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse.linalg as spla

from ...errors import InputError
from ...validation import check_integer, check_real
from . import doubling

# The largest relative residual of a kernel direction; inverse iteration's solves.
KERNEL_TOL = 1e-6
KERNEL_SOLVES = 3
# The bifurcations a branch is switched onto.
SWITCHED = ("branch point", "period doubling")


@dataclass(frozen=True)
class Switch:
    """How `follow_periodic_family` switches branches (``Continuation(switch=Switch(...))``).

    Attributes:
        orbits: members of each half of the new branch (the first, next to the branch point,
            included).
        step: the first step off the branch point, in the arclength (default: the family's
            step across the branch point).
        at: the number of the bifurcation to switch at (``1`` for the first located, as the
            command line prints them); default the first branch point or period doubling.
    """

    orbits: int = 20
    step: float | None = None
    at: int | None = None

    def __post_init__(self):
        object.__setattr__(self, "orbits", check_integer("orbits", self.orbits, minimum=2))
        if self.step is not None:
            object.__setattr__(self, "step", check_real("step", self.step, positive=True))
        if self.at is not None:
            object.__setattr__(self, "at", check_integer("at", self.at, minimum=1))


@dataclass
class Branch:
    """One half of a new branch: its sign along the kernel direction, its name (the node value
    that moves most, ``+q3``), the bifurcation it starts at (its number), the kernel
    direction's relative residual and the followed half (an ``arclength.Family``, its first
    member next to the branch point). At a period doubling ``kind`` says so, the half's
    orbits have twice the nodes and period, and ``same`` says whether the other sign's orbit
    was found to be this one shifted by half its period (then this is the one branch
    followed)."""

    sign: int
    label: str
    at: int
    residual: float
    family: object
    kind: str = "branch point"
    same: bool = False


def checked_switch(switch) -> Switch | None:
    """``None`` (no switch), ``True`` (the defaults) or a `Switch`; anything else refused."""
    if switch is None or switch is False:
        return None
    if switch is True:
        return Switch()
    if not isinstance(switch, Switch):
        raise InputError(f"switch must be a Switch, True or None, got {switch!r}")
    return switch


def follow_branches(walker, bifurcations: list, switch: Switch, family) -> tuple[list, str]:
    """``(branches, message)``: both halves of the new branch at the chosen branch point
    (module docstring), or none and why; ``family``: the class a half is returned as
    (``arclength.Family``)."""
    chosen = _chosen(bifurcations, switch)
    if isinstance(chosen, str):
        return [], chosen
    number, point = chosen
    if point.kind == "period doubling":
        return _follow_doubled(walker, number, point, switch, family)
    y = walker.point(point.orbit)
    along = walker.tangents[point.after]
    direction, residual = kernel_direction(walker, y, along)
    if residual > KERNEL_TOL:
        return [], (f"no branch direction at bifurcation {number} (E = {point.energy:.12g}): "
                    f"the extended system is not singular there (kernel residual "
                    f"{residual:.1e} > {KERNEL_TOL:g})")
    ds = switch.step or walker.steps[point.after]
    longest = max(max(walker.steps), ds)
    branches = []
    for sign in (1, -1):
        label = _label(direction * sign, walker.system.n, walker.assembly.layout)
        half = _follow_half(walker, y, along, sign * direction, (ds, longest), switch, family)
        branches.append(Branch(sign, label, number, residual, half))
    counts = ", ".join(f"{b.label}: {len(b.family.members)} orbits" for b in branches)
    return branches, (f"switched at bifurcation {number} ({point.kind} at E = "
                      f"{point.energy:.12g}; kernel residual {residual:.1e}): {counts}")


def _chosen(bifurcations: list, switch: Switch):
    """``(number, bifurcation)`` to switch at, or the message why there is none."""
    if switch.at is None:
        found = [(j + 1, b) for j, b in enumerate(bifurcations) if b.kind in SWITCHED]
        if not found:
            kinds = ", ".join(b.kind for b in bifurcations) or "none"
            return (f"no branch point was located on the family, nor a period doubling "
                    f"(bifurcations located: {kinds}): no branch to switch onto")
        return found[0]
    if switch.at > len(bifurcations):
        return (f"at = {switch.at}, but {len(bifurcations)} bifurcation(s) were located: no "
                f"branch to switch onto")
    point = bifurcations[switch.at - 1]
    if point.kind not in SWITCHED:
        return (f"bifurcation {switch.at} is a {point.kind}: switching is done at branch "
                f"points and period doublings (the family turns back at a fold: no new "
                f"branch)")
    return switch.at, point


def kernel_direction(walker, y: np.ndarray, along: np.ndarray) -> tuple[np.ndarray, float]:
    """The unit (``W``-norm) kernel direction of the extended Jacobian at ``y`` that is
    ``W``-orthogonal to ``along``, and its relative residual (module docstring)."""
    return kernel(walker.arc, walker.closure, y, along)


def kernel(arc, closure, y: np.ndarray, along: np.ndarray) -> tuple[np.ndarray, float]:
    """`kernel_direction` of the system ``arc`` (an ``arclength.ArclengthSystem``) with the
    data ``closure``: of the followed family's grid or of the doubled one."""
    weights = arc.weights
    closure = replace(closure, energy=float(y[-1]))
    _, blocks = arc.base.evaluate(y[:-1], closure, True)
    matrix = arc.bordered(blocks, weights * along)
    factor = spla.splu(matrix)
    v = np.cos(np.arange(y.size) * 0.7 + 0.3)  # a fixed start with no symmetry of its own
    for _ in range(KERNEL_SOLVES):
        v = factor.solve(v)
        v /= np.max(np.abs(v))
    v = v - np.sum(weights * v * along) / np.sum(weights * along * along) * along
    v /= np.sqrt(np.sum(weights * v * v))
    extended = matrix[:-1]
    scale = float(abs(extended).sum(axis=1).max()) * float(np.max(np.abs(v)))
    return v, float(np.max(np.abs(extended @ v)) / scale)


def _label(direction: np.ndarray, n: int, layout) -> str:
    """``+q3`` / ``-p1``: the coordinate that moves most along ``direction`` (a position if
    any moves, else a momentum), with the sign it moves by at the first node where it moves
    most (to a part in 1e6: a tie between nodes goes to the first)."""
    nodes = direction[:layout.nodes * layout.m].reshape(layout.nodes, layout.m)[:, 1:]
    part, kind = (nodes[:, :n], "q") if np.max(np.abs(nodes[:, :n])) > 0 else (nodes[:, n:], "p")
    j = int(np.argmax(np.max(np.abs(part), axis=0)))
    k = int(np.argmax(np.abs(part[:, j]) >= (1 - 1e-6) * np.max(np.abs(part[:, j]))))
    return ("+" if part[k, j] > 0 else "-") + f"{kind}{j + 1}"


def _follow_half(walker, y: np.ndarray, along: np.ndarray, direction: np.ndarray, steps,
                 switch: Switch, Family):  # noqa: N803 - the class, passed in
    """One half: its first orbit off the branch point, then the walk (module docstring), as a
    ``Family`` (``arclength.Family``), empty with the reason when the first orbit is not found;
    ``steps``: the first and the longest step in the arclength."""
    ds, longest = steps
    started = time.perf_counter()
    first, step, why = None, ds, "no step tried"
    smallest = walker.settings.min_step * ds
    while first is None and step >= smallest:
        first, why = _first_orbit(walker, y, along, direction, step)
        if first is None:
            step /= 2
    if first is None:
        return Family([], [], False, f"the first orbit off the branch point was not found: a "
                                     f"step below {smallest:.3g} failed ({why})",
                      time.perf_counter() - started)
    return _walk_on(walker, first, walker.nodes, direction, (step, longest), switch, Family,
                    started)


def _walk_on(walker, first, nodes: int, direction: np.ndarray, steps, switch: Switch,
             Family, started: float):  # noqa: N803 - the class, passed in
    """The half from its verified ``first`` orbit (of ``nodes`` nodes) on: the walker's walk,
    its first tangent oriented along ``direction``, for ``switch.orbits`` members, and the
    bifurcations along it, as a ``Family``; ``steps``: the first and the longest arclength."""
    step, longest = steps
    settings = replace(walker.settings, max_orbits=switch.orbits, switch=None)
    half = type(walker)(walker.system, first, nodes, walker.common, settings,
                        (-np.inf, np.inf), previous=direction)
    members, message, _ = half.walk(ds=step, longest=longest)
    complete = len(members) == switch.orbits
    if complete:
        message = f"orbits = {switch.orbits} reached"
    bifurcations, unlocated = half.locate_all()
    return Family(members, bifurcations, complete, message, time.perf_counter() - started,
                  unlocated)


def _first_orbit(walker, y: np.ndarray, along: np.ndarray, direction: np.ndarray,
                 step: float):
    """``(orbit, None)``: the verified orbit at arclength ``step`` from ``y`` along
    ``direction`` and off the followed family, or ``(None, why)``."""
    point, _ = walker.correct_from(y, direction, step)
    if point is None:
        return None, "the corrector did not converge"
    weights = walker.arc.weights
    off = abs(np.sum(weights * along * (point - y)))
    if off > 0.5 * step:
        return None, (f"the corrector went back to the followed family (component {off:.2e} "
                      f"along its tangent at arclength {step:.3g})")
    orbit = walker.verified(point)
    if not orbit.success:
        return None, orbit.message
    return orbit, None


def _follow_doubled(walker, number: int, point, switch: Switch, Family):  # noqa: N803
    """``(branches, message)`` at the period doubling ``point`` (``doubling.py``): the kernel
    direction on the doubled grid, the first orbit of each sign, whether they are one orbit
    shifted by half its period, and the branch followed (once if they are)."""
    along = walker.tangents[point.after]
    grid = doubling.doubled_grid(walker, walker.point(point.orbit), along)
    direction, residual = kernel(grid.arc, grid.closure, grid.y, grid.along)
    where = f"bifurcation {number} (period doubling at E = {point.energy:.12g})"
    if residual > KERNEL_TOL:
        return [], (f"no branch direction at {where}: the doubled period's extended system is "
                    f"not singular there (kernel residual {residual:.1e} > {KERNEL_TOL:g})")
    odd = doubling.antisymmetry(direction, grid)
    ds = switch.step or walker.steps[point.after]
    longest = max(max(walker.steps), ds)
    started = time.perf_counter()
    firsts, whys = {}, {1: "no step tried", -1: "no step tried"}
    for sign in (1, -1):
        step = ds
        while sign not in firsts and step >= walker.settings.min_step * ds:
            found, whys[sign] = doubling.first_orbit(walker, grid, sign * direction, step)
            if found is not None:
                firsts[sign] = found
            step /= 2
    said = (f"switched at {where}; kernel residual {residual:.1e}, antisymmetric over the two "
            f"periods to {odd:.1e}")
    if not firsts:
        return [], (f"{said}: no orbit of the doubled period was found off it (+: {whys[1]}; "
                    f"-: {whys[-1]})")
    signs = sorted(firsts, reverse=True)
    note = ""
    if len(firsts) == 2:
        gap, apart = doubling.same_orbit(walker, grid, firsts[1].orbit, firsts[-1].orbit)
        if gap < doubling.SAME_ORBIT * apart:
            signs, note = [1], (f"; the two signs give one orbit shifted by half its period "
                                f"(re-solved at equal energy {gap:.1e} apart, against {apart:.1e} "
                                f"before the shift): followed once")
        else:
            note = (f"; the two signs' orbits are not one orbit shifted by half its period "
                    f"({gap:.1e} apart at equal energy, {apart:.1e} before the shift): both "
                    f"followed")
    else:
        missing = -signs[0]
        note = f"; the other sign found no orbit ({whys[missing]})"
    branches = []
    for sign in signs:
        first = firsts[sign]
        same = len(signs) == 1 and len(firsts) == 2
        label = _label(direction * sign, walker.system.n, grid.assembly.layout)
        label = "+-" + label[1:] if same else label
        half = _walk_on(walker, first.orbit, grid.nodes, sign * direction,
                        (first.step, longest), switch, Family, started)
        branches.append(Branch(sign, label, number, residual, half, "period doubling", same))
        started = time.perf_counter()  # a second branch's seconds are its own
    counts = ", ".join(f"{b.label}: {len(b.family.members)} orbits of twice the period"
                       for b in branches)
    return branches, f"{said}{note}: {counts}"
