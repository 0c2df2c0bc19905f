"""Periodic orbits at a prescribed energy found from a section alone: ``find_periodic_orbits``.

For a system of two degrees of freedom, the section ``q_s = v`` at energy ``E`` is a plane of
points ``u = (q_o, p_o)`` (``section_map.py``: ``p_s`` from ``H = E``, where that has a real root;
the accessible region is computed from ``H``). A periodic orbit crossing the section is a fixed
point of a power ``P^k`` of the return map. Seeds are spread over the accessible region, each is
carried by the exact flow to its returns, and the fixed points are shot for on the exact flow:

- with a declared reversing symmetry ``R`` (an involution flipping ``q_s`` and ``p_o``, e.g. Hill's
  ``(x, y, px, py, t) -> (x, -y, -px, py, -t)``, section ``y = 0``), an orbit that is its own image
  crosses the fixed line ``p_o = 0`` of the section at right angles twice, half a period apart.
  Seeds on that line are shot half an orbit: the residual is ``p_o`` at the ``k``-th crossing,
  one unknown and one equation, bracketed between seeds where it changes sign and solved by
  Brent's method on the flow. Half an orbit: half the work and the square root of the growth of
  errors along it (a multiplier of 2000 per period is 45 over the half);
- without one, seeds fill a box of the plane, and from each grid minimum of ``|P^k(u) - u|``
  Newton solves ``P^k(u) = u`` with the map's derivative from the variational equations
  (``exact_newton``, damped). Seeds near a strongly unstable orbit leave before they return
  (Hill's Lyapunov orbits, a multiplier of 2000 per period), so the equilibria on the section's
  line (critical points of the least energy along it, polished by Newton on ``grad H = 0``) are
  seeds too: the linearised orbit of the centre mode at the energy (``linearised.py``) is a
  whole period, closed by multiple shooting on the exact flow.

Every orbit found is checked by closing it on the exact flow over its whole period; the same
orbit reached from several seeds, or as a multiple cover, is kept once (compared by its period
and its upward crossings of the section); each is refined on the discrete grid by
``solve_periodic`` (the orbit as its guess) with its multipliers and verdict
(``periodic_stability``), beside the exact flow's own monodromy, and compared with it
(``search_grid.py``: a grid orbit further from it than the grid's own error is another orbit,
said so, not this one's refinement). An orbit's verdict is its exact index's with the
tolerance ``stability_tol``. ``max_returns`` bounds the upward crossings of the orbits listed
(an orbit of ``R`` crosses ``R`` times in its half between the right-angle crossings, so the
half-orbit shots go to the ``max_returns``-th crossing); a shot that closes on an orbit of more
is a failed seed, said so.

Where the seeds run: in this process by default (``workers=1``, one after another). With
``workers=N`` the seeds' runs to their returns and the shots (one per bracket or grid minimum)
run on ``N`` processes forked from this one (``section_map.SeedPool``: the exact flows built
here first, the work sent in blocks of consecutive items and merged back in order), the same
calls on the same arguments, so the same orbits, failures and region; the window, the
brackets, the equilibria's orbits, the distinct orbits and the refinement on the grid stay
here. ``seconds`` counts the workers' CPU too. It pays only where a second core is free:
Hill's problem at ``E = -2.14``, 400 seeds, the search alone (``refine=False``), on 2 cores
shared with other jobs (``scripts/benchmarks/bench_search_workers.py``, best of 2): one worker
10.9 s CPU, 11.3 s wall; two 12.5 s CPU (with the workers), 9.1 s wall, at a load average of
3.3 to 3.8; an earlier run at a load of 2.4: 10.8 s CPU, 10.3 s wall against 11.8 s CPU, 6.0 s
wall; with a test run sharing the cores, two were slower (18.4 s wall against 11.8 s). The whole
``ddvp periodic --search`` is mostly the grid's refinements (about 30 of 40 s CPU at that
energy), which stay in this process: two workers saved it 1.5 s of 32 s wall (3.5 s more CPU) at
a load of 2, and doubled its wall time at a load of 5 (docs/periodic/search.md).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field

import numpy as np

from ...errors import InputError
from ...validation import check_integer, check_memory, check_real
from ..exact.flow import exact_flow
from ..exact.flow_newton import exact_newton
from .floquet import DEFAULT_TOL
from .floquet import verdict as stability_verdict
from .search_grid import identify_landing, own_size, refine_found
from .section_map import (
    RTOL,
    SEED_ATTEMPTS,
    Escape,
    SearchSection,
    SectionAtEnergy,
    SeedPool,
    parse_search_section,
    return_derivative,
    returns,
)

SEEDS = 400  # default seeds (on the symmetric line; a square grid of about as many otherwise)
MAX_RETURNS = 2  # default: orbits crossing the section upwards at most this many times
# a half-orbit shot's residual p_o at its right-angle crossing, relative to the orbit's own
# range of a momentum (`own_size`), to be kept
RESIDUAL = 1e-8
# the whole orbit's closure on the exact flow, each component relative to the orbit's own size
# (`own_size`: not max |z|, which grows with the distance from the coordinates' origin)
CLOSURE = 1e-6
# two orbits are one when their periods agree to this (relative) and a crossing to 1e3 times
# it of the orbit's own size (`own_size`)
SAME = 1e-6
# a position further than this many times the window's half-width from its centre: the
# motion has left (`_scales`)
ESCAPE = 4.0
# the scan of the section's line that sizes the window: offsets from the critical points' own
# centre, in a unit of their own size (`_line_scan`)
_SCAN = np.concatenate([-np.geomspace(1e6, 1e-6, 1200), [0.0], np.geomspace(1e-6, 1e6, 1200)])
SCAN_PASSES = 6  # scans of the line at most, each about the centre the last one found


@dataclass(frozen=True)
class SearchRegion:
    """What was searched: the energy, the section, the window of ``q_o``, the box of ``p_o``
    (``None`` on the symmetric line ``p_o = 0``), the seeds spread and how many the energy
    allowed, the reversing symmetry used (``None``: none), the largest number of upward
    returns, and the longest time a seed was followed."""

    energy: float
    section: str
    window: tuple
    momentum: tuple | None
    seeds: int
    accessible: int
    reversing: tuple | None
    max_returns: int
    horizon: float
    jitter: int | None = None
    equilibria: int = 0
    parts: tuple = ()

    def describe(self) -> str:
        parts = []
        if self.reversing is not None:
            parts.append(f"on the line fixed by the reversing symmetry flipping "
                         f"{', '.join(self.reversing)}")
        if self.momentum is not None:
            parts.append(f"momentum in [{self.momentum[0]:.4g}, {self.momentum[1]:.4g}] (the "
                         "whole return map)")
        box = " and ".join(parts)
        placed = "" if self.jitter is None else \
            f" (each at random in its cell, generator seed {self.jitter})"
        linearised = "" if not self.equilibria else \
            f", the linearised orbits about {self.equilibria} critical points of the line"
        return (f"E = {self.energy:.10g}, section {self.section}, other position in "
                f"[{self.window[0]:.4g}, {self.window[1]:.4g}] {box}, {self.seeds_said()}"
                f"{placed}{linearised}, orbits of up to {self.max_returns} upward crossings "
                f"per period, seeds followed to t = {self.horizon:.4g}")

    def seeds_said(self) -> str:
        """The seeds, each way of searching's apart: ``seeds`` asks for that many on the
        symmetric line (both directions) and for about that many accessible on the whole
        map's grid, so the total is about twice it, or more where little of the grid is
        accessible."""
        if len(self.parts) < 2:
            return f"{self.seeds} seeds of which {self.accessible} accessible"
        each = "; ".join(f"{n} {where} ({a} accessible)" for where, n, a in self.parts)
        return f"{self.seeds} seeds of which {self.accessible} accessible: {each}"


@dataclass
class FoundOrbit:
    """One periodic orbit: ``period``, ``start`` (a point of it on the section crossing upwards),
    ``returns`` (upward crossings per period), ``symmetric`` (found by the half-orbit shot),
    its nontrivial ``multipliers`` and stability ``index`` (their sum) from the derivative of the
    return map over one period on the exact flow (``section_map.py``), ``closure`` (its
    closure on the exact flow over one period, each component relative to the orbit's own size,
    `own_size`), ``crossings`` (its upward crossings, rows ``u``),
    ``path`` (``z`` at 400 equal times of one period), how many ``seeds`` reached it, the refined
    ``solution`` with its ``stability`` (``None`` where the refinement failed: ``note``), ``tol``
    (the stability index's tolerance of the verdict) and ``grid`` (a
    ``search_grid.GridRefinement``: whether the grid's orbit is this one; ``None`` unrefined)."""

    period: float
    start: np.ndarray
    returns: int
    symmetric: bool
    multipliers: np.ndarray
    index: float
    closure: float
    crossings: np.ndarray
    path: np.ndarray
    seeds: int = 1
    solution: object = None
    stability: object = None
    note: str = ""
    tol: float = DEFAULT_TOL
    grid: object = None

    @property
    def verdict(self) -> str:
        """``stable``, ``marginal`` or ``unstable`` from the exact flow's ``index`` with the
        tolerance ``tol`` (``floquet.verdict``: ``|index|`` within ``tol`` of 2 is
        ``marginal``), whatever the grid gave: one classification for the list, the files and
        the figure. The grid's own is ``stability.verdict``, told apart in ``grid``."""
        return stability_verdict(np.array([self.index], complex), self.tol)


@dataclass(frozen=True)
class FailedSeed:
    """A seed ``u = (q_o, p_o)`` (or a bracket of them) and why it gave no orbit."""

    seed: tuple
    reason: str


@dataclass
class OrbitSearch:
    """The result of `find_periodic_orbits`: ``orbits`` (distinct, by period), ``searched``
    (a `SearchRegion`), ``failures`` (each failed seed or bracket with its reason), ``seconds``."""

    orbits: list
    searched: SearchRegion
    failures: list = field(default_factory=list)
    seconds: float = 0.0

    @property
    def found(self) -> bool:
        return bool(self.orbits)

    def summary(self) -> str:
        if not self.orbits:
            return f"none found in the region searched ({self.searched.describe()})"
        return (f"{len(self.orbits)} periodic orbit(s) found ({self.searched.describe()}); "
                f"{len(self.failures)} seeds or brackets failed")


class NoMotionOnSection(InputError):
    """The energy allows no motion anywhere on the section's window."""


def find_periodic_orbits(system, *, energy: float, section, reversing="auto",
                         seeds: int = SEEDS, max_returns: int = MAX_RETURNS, window=None,
                         nodes: int = 201, params=None, refine: bool = True,
                         jitter=None, workers: int = 1,
                         stability_tol: float = DEFAULT_TOL) -> OrbitSearch:
    """Periodic orbits of ``system`` at energy ``E`` that cross ``section`` (module docstring).

    Args:
        system: an autonomous Hamiltonian system of two degrees of freedom, quadratic in the
            section's momentum.
        energy: the prescribed energy ``E``.
        section: ``"q2=0"``: the position coordinate the orbits cross and its value.
        reversing: the coordinates a reversing symmetry flips (with ``t -> -t``), e.g.
            ``("q2", "p1")``: it must flip the section's coordinate and the other momentum, the
            section's value must be 0, and ``H`` must be unchanged by it (checked).
            ``"auto"`` (default): that symmetry's half-orbit shots wherever ``H`` is unchanged
            by it, and the whole return map besides (for the orbits that are not their own
            mirror images). ``None`` or ``"none"``: the whole return map only; a declared
            symmetry: its half-orbit shots only.
        seeds: how many seeds (on the symmetric line, both crossing directions; about as many
            accessible ones on a square grid for the whole return map).
        max_returns: orbits up to this many upward crossings of the section per period.
        window: ``(lo, hi)`` of the other position coordinate; default from the critical points
            of the least energy along the section's line (each edge their spread beyond).
        nodes: the grid of the refinement (``solve_periodic``).
        params: the system's parameter values.
        refine: refine each orbit on the grid and compute its stability there.
        jitter: ``None`` (default): each seed at the centre of its cell of the region; an
            integer ``>= 0``: each at a random point of its cell (a stratified layout, numpy's
            generator seeded with it), to check that the orbits found do not hang on where the
            seeds fall.
        workers: processes the seeds' work runs on (their returns and the shooting from each
            seed or bracket), forked from this one; ``1`` (default): all in this process. The
            same orbits either way (the same calls, merged back in order).
        stability_tol: an orbit's stability index within this of ``+-2`` is ``marginal``
            (``floquet.verdict``), the exact flow's index and the grid's alike.

    Returns:
        An `OrbitSearch`. An energy with no motion on the section is refused
        (`NoMotionOnSection`, an `InputError`), before any flow is run.
    """
    started = _cpu_seconds()
    sec = parse_search_section(section, system)
    energy = check_real("energy", energy)
    seeds = check_integer("seeds", seeds)
    max_returns = check_integer("max_returns", max_returns)
    nodes = check_integer("nodes", nodes, minimum=4)
    jitter = None if jitter is None else check_integer("jitter", jitter, minimum=0)
    workers = check_integer("workers", workers)
    stability_tol = check_real("stability_tol", stability_tol, positive=True)
    check_memory("workers", workers, workers * _worker_bytes(), "the seeds' worker processes")
    theta = system.parameter_vector(params)
    flipped = parse_reversing(reversing, system, theta, sec)
    geometry = SectionAtEnergy(system, theta, sec, energy)
    window = _window(geometry, window)
    found, failures, region = [], [], None
    with SeedPool(geometry, workers) as pool:
        if flipped is not None:
            found, failures, region = _symmetric_search(geometry, window, seeds, max_returns,
                                                        jitter, pool)
        if flipped is None or reversing == "auto":  # a found symmetry: its orbits and others
            more, failed, box = _map_search(geometry, window, seeds, max_returns, jitter, pool)
            found, failures = found + more, failures + failed
            region = box if region is None else {
                **box, "seeds": region["seeds"] + box["seeds"],
                "accessible": region["accessible"] + box["accessible"],
                "horizon": max(region["horizon"], box["horizon"]),
                "parts": region["parts"] + box["parts"]}
    if flipped is None:  # no half-orbit shots: the equilibria's linearised orbits too
        more, failed, region["equilibria"] = _equilibrium_orbits(geometry, window, params)
        found, failures = found + more, failures + failed
    orbits, beyond = _within_returns(_distinct(found), max_returns)
    failures = failures + beyond
    for orbit in orbits:
        orbit.tol = stability_tol
        if refine:
            refine_found(system, orbit, energy, sec, nodes, params, stability_tol)
    orbits = sorted(orbits, key=lambda o: o.period)
    identify_landing(orbits, sec)
    region = SearchRegion(reversing=flipped, jitter=jitter, **region)
    return OrbitSearch(orbits, region, failures,
                       _cpu_seconds() - started)


def _worker_bytes() -> float:
    """The memory bound of one forked worker (the ensemble's, ``marching/ensemble.py``)."""
    from ..marching.ensemble import WORKER_BYTES

    return WORKER_BYTES


def _cpu_seconds() -> float:
    """This process's CPU time and its finished children's (the seeds' workers)."""
    times = os.times()
    return time.process_time() + times.children_user + times.children_system


def parse_reversing(reversing, system, theta, section: SearchSection):
    """The names of the coordinates a reversing symmetry flips (`find_periodic_orbits`),
    checked, or ``None`` (no symmetry used). ``"auto"``: the one that flips the section's
    coordinate and the other momentum, where ``H`` is unchanged by it and the section's value
    is 0."""
    names = [f"q{i + 1}" for i in range(2)] + [f"p{i + 1}" for i in range(2)]
    wanted = sorted([section.index, 2 + section.other])
    if reversing is None or reversing is False or reversing == "none":
        return None
    if isinstance(reversing, str) and reversing == "auto":
        if section.value != 0 or _symmetry_gap(system, theta, wanted) is not None:
            return None
        return tuple(names[i] for i in wanted)
    items = reversing.split(",") if isinstance(reversing, str) else reversing
    try:
        flipped = sorted({names.index(str(name).strip()) for name in items})
    except (ValueError, TypeError):
        raise InputError(f"reversing must name coordinates among {', '.join(names)} (those "
                         f"the symmetry flips), or be 'auto' or 'none', got {reversing!r}") \
            from None
    if flipped != wanted:
        raise InputError(
            f"reversing {reversing!r}: the half-orbit shot needs the symmetry that flips the "
            f"section's coordinate and the other momentum ({names[wanted[0]]}, "
            f"{names[wanted[1]]}) for the section {section.label}")
    if section.value != 0:
        raise InputError(f"reversing {reversing!r}: the section {section.label} is not mapped "
                         "to itself by the symmetry (its value must be 0)")
    worst = _symmetry_gap(system, theta, flipped)
    if worst is not None:
        raise InputError(f"reversing {reversing!r} is not a symmetry of H: H changes by up to "
                         f"{worst:.3g} under it")
    return tuple(names[i] for i in flipped)


def _symmetry_gap(system, theta, flipped) -> float | None:
    """``None`` where ``H`` is unchanged (to round-off of its values) when the coordinates
    ``flipped`` change sign, at 16 random points; else the largest change."""
    rng = np.random.default_rng(0)
    z = rng.normal(size=(16, 4)) + 0.5
    image = z.copy()
    image[:, flipped] *= -1
    with np.errstate(all="ignore"):
        H = system.energy(z[:, :2], z[:, 2:], np.zeros(16), theta)
        H_image = system.energy(image[:, :2], image[:, 2:], np.zeros(16), theta)
    ok = np.isfinite(H) & np.isfinite(H_image)
    if not ok.any():
        return float("nan")
    gap = np.abs(H - H_image)[ok]
    size = np.maximum(np.abs(H[ok]), np.abs(H_image[ok]))
    return None if np.all(gap <= 1e-12 * size) else float(np.max(gap))


def _least_energy(geometry: SectionAtEnergy, q_other: np.ndarray) -> np.ndarray:
    """The least ``H`` over both momenta at each ``q_o`` of the section's line (each a
    parabola's vertex; the other momentum's probe on the scale of ``H`` there)."""
    def least_over_ps(p_other):
        u = np.column_stack([q_other, p_other])
        a, b, c = geometry.quadratic(u)
        with np.errstate(all="ignore"):
            return c - b * b / (4 * a)
    zero = least_over_ps(np.zeros(q_other.size))
    size = np.abs(np.where(np.isfinite(zero), zero, 0.0))
    step = np.sqrt(size + (np.median(size[size > 0]) if np.any(size > 0) else 1.0))
    minus, plus = least_over_ps(-step), least_over_ps(step)
    with np.errstate(all="ignore"):
        a, b = ((plus + minus) / 2 - zero) / step ** 2, (plus - minus) / (2 * step)
        return np.where(a > 0, zero - b * b / (4 * a), np.nan)


def _window(geometry: SectionAtEnergy, window) -> tuple:
    """The window of ``q_o`` searched: given, or from the critical points of the least
    energy along the line (their span beyond each end; the edge where the energy stops motion
    when there is only one), found on a scan of the line about their own centre
    (`_line_scan`); refused when the energy allows no motion in it."""
    geometry.check_quadratic(np.column_stack([_SCAN[::97], np.zeros(_SCAN[::97].size)]))
    if window is not None:
        try:
            lo, hi = (check_real("window", float(w)) for w in window)
        except (TypeError, ValueError):
            raise InputError(f"window must be (lo, hi), two real numbers, got {window!r}") \
                from None
        if not lo < hi:
            raise InputError(f"window must have lo < hi, got {window!r}")
    else:
        scan, V, unit = _line_scan(geometry)
        _refuse_no_motion(geometry, V, f", over the other position from {scan[0]:.4g} to "
                                       f"{scan[-1]:.4g}")
        critical = scan[_critical_index(V)]
        allowed = scan[np.isfinite(V) & (V <= geometry.energy)]
        if critical.size >= 2:
            span = critical.max() - critical.min()
            lo, hi = critical.min() - span, critical.max() + span
        elif critical.size == 1 and allowed.size:
            span = 2 * np.max(np.abs(allowed - critical[0])[
                np.abs(allowed - critical[0]) < 1e5 * unit])
            lo, hi = critical[0] - span, critical[0] + span
        else:
            raise InputError(f"window: the least energy along the section {geometry.section.label}"
                             " has no critical point to size a window by; give window=(lo, hi)")
    grid = np.linspace(lo, hi, 4001)
    V = _least_energy(geometry, grid)
    _refuse_no_motion(geometry, V, f" over the other position in [{lo:.4g}, {hi:.4g}]")
    return float(lo), float(hi)


def _line_scan(geometry: SectionAtEnergy) -> tuple[np.ndarray, np.ndarray, float]:
    """``(scan, V, unit)``: points of the section's line ``centre + unit * _SCAN`` and the least
    energy ``V`` at them, the centre and the unit found from the problem. The first scan is about
    the coordinates' origin in a unit of 1; each critical point of ``V`` on it is located within
    its neighbours (`_refine_critical`), and the next scan is about their midpoint (the one
    point, if one), in the power of ten nearest their span (the reach of the motion about the
    one point, if it is bounded), until neither moves. ``_SCAN``'s points are 2.3% apart
    relative to their distance from its centre: about the origin, critical points 2000 away
    fell 46 apart, and Hill's libration points and Moon at ``x = 2000 +- 0.69`` and ``2000``
    were one critical point; the window was ``[-197054, 201024]``. Scanned about their own
    centre, the points the window is made of sit where they sit about the origin, so the window
    moves with the coordinates' origin and scales with a unit of length that is a power of ten
    (another unit places its critical points among the scan's points otherwise: the window's
    edges move by up to the scan's spacing there, 2.3% of the span). At the origin a problem
    whose critical points are centred on it and a span between 0.32 and 3.2 is scanned as
    before, the same points (Hill's problem, Barbanis, Pullen-Edmonds)."""
    centre, unit = 0.0, 1.0
    for _ in range(SCAN_PASSES):
        scan = centre + unit * _SCAN
        V = _least_energy(geometry, scan)
        index = _critical_index(V)
        if not index.size:
            break
        found = _refine_critical(geometry, scan, V, index)
        if found.size >= 2:
            middle, size = (found.min() + found.max()) / 2, found.max() - found.min()
        else:
            middle, size = found[0], _reach_about(geometry, scan, V, index[0], found[0])
        if np.isfinite(size) and size > 0:
            moved_unit = 10.0 ** np.round(np.log10(size))
        else:  # one critical point and no bounded motion about it: the unit stays
            moved_unit, size = unit, float(np.max(scan[index + 1] - scan[index - 1]))
        if moved_unit == unit and abs(middle - centre) <= 1e-6 * size:
            break
        centre, unit = float(middle), float(moved_unit)
    return scan, V, unit


def _critical_index(V: np.ndarray) -> np.ndarray:
    """The points of a scan where the least energy ``V`` turns (finite there)."""
    inner = (V[1:-1] - V[:-2]) * (V[2:] - V[1:-1]) < 0
    return np.flatnonzero(inner & np.isfinite(V[1:-1])) + 1


def _refine_critical(geometry, scan: np.ndarray, V: np.ndarray, index: np.ndarray,
                     passes: int = 12) -> np.ndarray:
    """Each critical point ``scan[index]`` of the least energy located between its neighbours
    on the scan: the largest (a maximum) or least (a minimum) of 21 points spread between
    them, and again between that point's neighbours (a tenth of the interval each pass; a
    flat top stops it at the round-off of ``V``, about ``1e-8`` of the scan's distances)."""
    lo, hi = scan[index - 1].astype(float), scan[index + 1].astype(float)
    sign = np.where(V[index] > V[index - 1], 1.0, -1.0)
    rows = np.arange(index.size)
    for _ in range(passes):
        x = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, 21)
        value = sign[:, None] * _least_energy(geometry, x.ravel()).reshape(x.shape)
        best = np.clip(np.argmax(np.where(np.isnan(value), -np.inf, value), axis=1), 1, 19)
        lo, hi = x[rows, best - 1], x[rows, best + 1]
    return (lo + hi) / 2


def _reach_about(geometry, scan: np.ndarray, V: np.ndarray, i: int, point: float) -> float:
    """How far the motion reaches along the line from ``point`` (the critical point at
    ``scan[i]``): the larger distance to an edge of the stretch of the scan about it where
    ``V <= E``, each edge located by bisection; ``nan`` where the energy stops no motion on one
    side within the scan, or allows none at ``scan[i]``."""
    allowed = np.isfinite(V) & (V <= geometry.energy)
    if not allowed[i]:
        return np.nan
    left, right = np.flatnonzero(~allowed[:i]), np.flatnonzero(~allowed[i + 1:]) + i + 1
    if not (left.size and right.size):
        return np.nan
    inside = np.array([scan[left[-1] + 1], scan[right[0] - 1]])
    outside = np.array([scan[left[-1]], scan[right[0]]])
    for _ in range(60):
        middle = (inside + outside) / 2
        within = _least_energy(geometry, middle) <= geometry.energy
        inside, outside = np.where(within, middle, inside), np.where(within, outside, middle)
    return float(max(point - inside[0], inside[1] - point))


def _refuse_no_motion(geometry, V: np.ndarray, over: str) -> None:
    """`NoMotionOnSection` where the least energy ``V`` along the section's other position
    (``over``: the range it was taken on, in words) is nowhere at or below the energy."""
    if np.any(np.isfinite(V) & (V <= geometry.energy)):
        return
    finite = V[np.isfinite(V)]
    raise NoMotionOnSection(
        f"no motion at this energy on the section: energy {geometry.energy!r} is below the "
        f"least energy on the section {geometry.section.label} "
        f"({np.min(finite) if finite.size else np.nan:.6g}{over})")


def _scales(geometry: SectionAtEnergy, window) -> tuple[np.ndarray, Escape, float]:
    """``(atol, escape, length)``: the exact flow's absolute tolerance per component (``RTOL``
    of the window's half-width ``length`` for the positions, of the momenta's size on the
    section's line for the momenta, `_momentum_scale`), where a seed has left (`Escape`:
    further than `ESCAPE` half-widths from the window's centre on the section), and
    ``length``. The window's own centre and extent, not its reach ``max |q_o|`` from the
    origin: with Hill's ``x`` shifted by 2000 the reach was 2002 for a half-width of 2.1, the
    seeds that left were followed to ``|q| > 8008`` and the flow's ``atol`` was 1000 times
    looser than at the origin (and a position's for the momenta, in another unit)."""
    section = geometry.section
    length = (window[1] - window[0]) / 2
    centre = np.zeros(2)
    centre[section.index], centre[section.other] = section.value, (window[0] + window[1]) / 2
    momentum = _momentum_scale(geometry, window)
    atol = RTOL * np.array([length, length, momentum, momentum])
    return atol, Escape(tuple(float(c) for c in centre), ESCAPE * length), length


def _time_scale(geometry: SectionAtEnergy, z: np.ndarray, escape: Escape) -> float:
    """A time for the seeds' first horizon: the median of ``|q - q_c| / |q'|`` over them
    (``q_c`` the window's centre, `_scales`; ``|q|``, from the origin, made it 800 times longer
    with Hill's ``x`` shifted by 2000)."""
    speeds = np.array([np.linalg.norm(geometry.velocity(row)[:2]) for row in z])
    sizes = np.linalg.norm(z[:, :2] - np.asarray(escape.centre), axis=1)
    ratio = sizes / speeds
    ratio = ratio[np.isfinite(ratio) & (ratio > 0)]
    return float(np.median(ratio)) if ratio.size else 1.0


def _follow(geometry, z0, count: int, first: float, atol, escape):
    """The returns of ``z0`` until ``count`` crossings (doubling the horizon from ``first``,
    at most eight times), or why there are fewer."""
    horizon = first
    for _ in range(9):
        found = returns(geometry, z0, horizon, atol, escape=escape)
        if found.t.size >= count or found.reason:
            return found, horizon
        horizon *= 2
    return found, horizon


def _cells(window, count: int, jitter=None) -> np.ndarray:
    """``count`` seeds at the centres of equal cells of the window: none on its middle, where a
    symmetric problem's singularity sits (Hill's Moon at ``q_o = 0``); with ``jitter`` (a
    generator's seed), each at a random point of its cell instead (a stratified layout)."""
    count += count % 2
    edges = np.linspace(window[0], window[1], count + 1)
    if jitter is None:
        return (edges[:-1] + edges[1:]) / 2
    where = np.random.default_rng(jitter).uniform(0.02, 0.98, count)
    return edges[:-1] + where * np.diff(edges)


def _symmetric_search(geometry, window, seeds: int, max_returns: int, jitter=None,
                      pool=None):
    """Half-orbit shots from seeds on the fixed line ``p_o = 0`` (module docstring); the
    seeds' runs and the shots on ``pool`` (a `SeedPool`; ``None``: here)."""
    pool = pool or SeedPool(geometry)
    atol, escape, _ = _scales(geometry, window)
    line = _cells(window, max(seeds // 2, 2), jitter)
    u = np.column_stack([line, np.zeros(line.size)])
    found, failures, accessible, horizons = [], [], 0, []
    # the crossings alternate in direction, so an orbit of R upward crossings per period
    # crosses 2 R times, R of them in the half from one right-angle crossing to the other
    half = max_returns
    for direction in (1, -1):
        z = geometry.points(u, direction)
        ok = np.all(np.isfinite(z), axis=1)
        accessible += int(ok.sum())
        if not ok.any():
            continue
        first = 4 * _time_scale(geometry, z[ok], escape)
        residual = np.full((line.size, half), np.nan)
        times = np.full((line.size, half), np.nan)
        indices = np.flatnonzero(ok)
        runs = pool.map(_follow, [(z[i], half, first, atol, escape) for i in indices])
        for i, (run, horizon) in zip(indices, runs, strict=True):
            horizons.append(horizon)
            k = min(run.t.size, half)
            residual[i, :k] = run.z[:k, 2 + geometry.section.other]
            times[i, :k] = run.t[:k]
            if k == 0:
                failures.append(FailedSeed((float(line[i]), 0.0), run.reason or
                                           f"did not return to the section by t = {horizon:.4g}"))
        shots = [(a, b, k + 1, direction, t_guess, atol, escape) for k in range(half)
                 for a, b, t_guess in _brackets(geometry, line, residual[:, k], times[:, k],
                                                k + 1, direction, atol, escape)]
        for (a, b, *_), shot in zip(shots, pool.map(_shoot_half, shots), strict=True):
            if isinstance(shot, FoundOrbit):
                found.append(shot)
            else:
                failures.append(FailedSeed((float(a), float(b)), shot))
    region = dict(energy=geometry.energy, section=geometry.section.label, window=window,
                  momentum=None, seeds=2 * line.size, accessible=accessible,
                  max_returns=max_returns, horizon=float(max(horizons, default=0.0)),
                  parts=(("on the symmetric line", 2 * line.size, accessible),))
    return found, failures, region


class _NoShot(Exception):
    """A shooting evaluation without the crossing it needs."""


def _half_crossing(geometry, x: float, k: int, direction: int, horizon: float, atol, escape):
    """``(z0, t_k, z_k)``: the seed at ``q_o = x`` on the fixed line and its ``k``-th crossing,
    or `_NoShot` saying why there is none."""
    z0 = geometry.points([[x, 0.0]], direction)[0]
    if not np.all(np.isfinite(z0)):
        raise _NoShot(f"the energy allows no motion at q_o = {x:.6g}")
    for stretch in (1, 2, 4):  # near a root the crossing can come later than at the ends
        run = returns(geometry, z0, stretch * horizon, atol, attempts=10 * SEED_ATTEMPTS,
                      escape=escape)
        if run.t.size >= k or run.reason:
            break
    if run.t.size < k:
        raise _NoShot(f"shooting did not converge: crossing {k} lost at q_o = {x:.6g} "
                      f"({run.reason or 'not reached'})")
    return z0, run.t[k - 1], run.z[k - 1]


def _shoot_half(geometry, a: float, b: float, k: int, direction: int, t_guess: float, atol,
                escape):
    """The orbit from the fixed line between ``q_o = a`` and ``b`` whose ``k``-th crossing is
    at right angles (Brent's method on ``p_o`` there), closed and checked on the exact flow; or
    why not, in words."""
    other = 2 + geometry.section.other
    horizon = 1.5 * t_guess

    def crossing(x):
        return _half_crossing(geometry, x, k, direction, horizon, atol, escape)

    from scipy.optimize import brentq
    try:
        root = brentq(lambda x: crossing(x)[2][other], a, b, xtol=1e-14 * max(abs(a), abs(b)),
                      rtol=1e-15, maxiter=200)
        z0, t_half, end = crossing(root)
    except _NoShot as why:
        return str(why)
    run = _orbit_run(geometry, z0, 2 * t_half, atol)
    # p_o there against the orbit's own range of a momentum (it was max |z0|, a position's
    # distance from the origin among them)
    if run.success and not abs(end[other]) <= RESIDUAL * own_size(_path(run, 2 * t_half))[other]:
        return (f"shooting did not converge: the crossing's momentum jumps between q_o = "
                f"{a:.6g} and {b:.6g} (|p_o| = {abs(end[other]):.2e} at the bracket's root)")
    return _closed(geometry, z0, 2 * t_half, atol, escape, symmetric=True, run=run)


def _brackets(geometry, line, residual, times, k: int, direction: int, atol, escape):
    """Brackets ``(a, b, t)`` of the residual's roots along the fixed line: its sign changes
    between neighbouring seeds, and the pairs of roots within one dip of ``|residual|``
    (three seeds of one sign whose parabola dips to or through zero: the residual at its
    vertex, on the flow, has the other sign), which no sign change shows and which a shifted
    layout of the seeds would see."""
    found = [(line[i], line[i + 1], np.nanmax(times[i:i + 2]))
             for i in np.flatnonzero(residual[:-1] * residual[1:] <= 0)]
    other = 2 + geometry.section.other
    for i in range(1, line.size - 1):
        r = residual[i - 1:i + 2]
        if not (np.all(np.isfinite(r)) and np.all(np.sign(r) == np.sign(r[1]))
                and abs(r[1]) < min(abs(r[0]), abs(r[2]))):
            continue
        c2, c1, c0 = np.polyfit(line[i - 1:i + 2] - line[i], r * np.sign(r[1]), 2)
        vertex = -c1 / (2 * c2)
        if not (c2 > 0 and c0 - c1 * c1 / (4 * c2) < 0.25 * abs(r[1])):
            continue
        x = line[i] + vertex
        horizon = 1.5 * np.nanmax(times[i - 1:i + 2])
        try:
            value = _half_crossing(geometry, x, k, direction, horizon, atol, escape)[2][other]
        except _NoShot:
            continue
        if value * r[1] < 0:
            found += [(line[i - 1], x, horizon / 1.5), (x, line[i + 1], horizon / 1.5)]
    return found


def _orbit_run(geometry, z0, period: float, atol):
    """The exact flow from ``z0`` over ``period`` (the run an orbit is checked on)."""
    flow = exact_flow(geometry.system)
    with np.errstate(all="ignore"):
        return flow.run(z0, 0.0, period, geometry.theta, rtol=RTOL, atol=atol,
                        max_attempts=10 * SEED_ATTEMPTS)


def _path(run, period: float) -> np.ndarray:
    """``z`` at 400 equal times of ``[0, period]`` on a run's dense output."""
    return run.z(np.linspace(0.0, period, 400))


def _closed(geometry, z0, period: float, atol, escape, *, symmetric: bool, run=None):
    """The orbit from ``z0`` over ``period`` checked to close on the exact flow (``run``: the
    flow's run from ``z0`` over ``period`` where the caller made it), with its upward
    crossings and exact monodromy (a `FoundOrbit`), or why not. Its closure is
    ``|phi_T(z0) - z0|`` per component over the orbit's own size (`own_size`), at most
    `CLOSURE`: the same verdict wherever the coordinates' origin and whatever their units."""
    run = run or _orbit_run(geometry, z0, period, atol)
    own = own_size(_path(run, period)) if run.success else None
    with np.errstate(all="ignore"):  # an orbit of no range (a point) does not close
        closure = float(np.max(np.abs(run.z_end - z0) / own)) if run.success else np.inf
    if not closure <= CLOSURE:
        return f"the orbit does not close on the exact flow (closure {closure:.2e} of its size)"
    seen = returns(geometry, z0, period * (1 + 1e-9), atol, escape=escape, run=run)
    # a start on the section to round-off can be met again at t ~ 0: not a return
    seen = _after(seen, 1e-9 * period)
    again = [j for j in range(seen.t.size) if seen.t[j] < period * (1 - 1e-9)
             and _near(seen.z[j], z0, own, 1e3 * SAME)]
    if again:  # a multiple cover: its primitive orbit (found from this seed all the same)
        period = float(seen.t[again[0]])
        seen = _after(returns(geometry, z0, period * (1 + 1e-9), atol, escape=escape,
                              run=run), 1e-9 * period)
    ups = [j for j in range(seen.t.size) if seen.direction[j] > 0
           and seen.t[j] < period * (1 - 1e-9)]
    starts = seen.z[ups] if ups else z0[None, :]
    if geometry.velocity(z0)[geometry.section.index] > 0:
        starts = np.vstack([z0[None, :], starts])
    start = starts[0]  # z0, or the run's state at its first upward crossing
    # the map's derivative from the slowest crossing: started near a close approach the
    # monodromy has entries of 1e7 and its trace loses digits (measured on Hill's mirror pairs)
    gentle = starts[np.argmin([np.linalg.norm(geometry.velocity(row)) for row in starts])]
    _, derivative = return_derivative(geometry, gentle, period, atol)
    if derivative is None:
        return "the return map's derivative over the period could not be computed"
    crossings = _unique_rows(starts[:, geometry.section.free], own[geometry.section.free])
    return FoundOrbit(period=period, start=start, returns=len(crossings), symmetric=symmetric,
                      multipliers=np.linalg.eigvals(derivative),
                      index=float(np.trace(derivative)),
                      closure=closure, crossings=crossings, path=_path(run, period))


def _after(seen, start: float):
    """The crossings of ``seen`` after ``start``."""
    keep = seen.t > start
    return type(seen)(seen.t[keep], seen.z[keep], seen.direction[keep], seen.reason,
                      seen.reached)


def _unique_rows(rows: np.ndarray, scale: np.ndarray) -> np.ndarray:
    kept = []
    for row in rows:
        if not any(_near(row, other, scale, SAME) for other in kept):
            kept.append(row)
    return np.array(kept)


def _near(a: np.ndarray, b: np.ndarray, scale: np.ndarray, tol: float) -> bool:
    """Whether ``a`` and ``b`` agree to ``tol`` of ``scale`` in every component."""
    return bool(np.all(np.abs(a - b) <= tol * scale))


def _map_search(geometry, window, seeds: int, max_returns: int, jitter=None, pool=None):
    """Newton on ``P^k(u) = u`` from the grid minima of ``|P^k(u) - u|`` over a box of the
    section, and multiple shooting from the grid minima of the two-sided residual (module
    docstring); the seeds' runs and the shots on ``pool`` (a `SeedPool`; ``None``: here)."""
    pool = pool or SeedPool(geometry)
    atol, escape, length = _scales(geometry, window)
    U, side, top = _map_grid(geometry, window, seeds, jitter)
    Z = geometry.points(U)
    ok = np.all(np.isfinite(Z), axis=1)
    first = 4 * _time_scale(geometry, Z[ok], escape) if ok.any() else 1.0
    images = np.full((2, U.shape[0], max_returns, 2), np.nan)  # P^k(u); then F_k(u) - B_k(u)
    times = np.full((3, U.shape[0], max_returns), np.nan)  # t of P^k, F_k and B_k (> 0)
    found, failures, horizons = [], [], []
    indices = np.flatnonzero(ok)
    runs = pool.map(_both_ways, [(Z[i], max_returns, first, atol, escape) for i in indices])
    for i, (run, horizon, back) in zip(indices, runs, strict=True):
        horizons.append(horizon)
        up = np.flatnonzero(run.direction > 0)[:max_returns]
        images[0, i, :up.size] = run.z[up][:, geometry.section.free]
        times[0, i, :up.size] = run.t[up]
        k = min(run.t.size, back.t.size, max_returns)
        images[1, i, :k] = (run.z[:k] - back.z[:k])[:, geometry.section.free]
        times[1, i, :k], times[2, i, :k] = run.t[:k], -back.t[:k]
        if up.size == 0:
            failures.append(FailedSeed(tuple(U[i]), run.reason or
                                       f"did not return to the section by t = {horizon:.4g}"))
    scale = np.array([length, top])  # the window's half-width, not its reach from the origin
    shots = []
    for k in range(max_returns):
        gaps = [np.max(np.abs(residual) / scale, axis=1)
                for residual in (images[0, :, k] - U, images[1, :, k])]
        # where the map stretches, |P^k(u) - u| ~ mu d outgrows |F_k - B_k| ~ sqrt(mu) d
        stretched = ~(gaps[1] >= 0.5 * gaps[0])
        for two_sided, gap in enumerate(gaps):
            for i, j in _grid_minima(gap.reshape(side, side)):
                index = i * side + j
                if two_sided and not stretched[index]:
                    continue  # the return map's own minima serve there
                shots.append((U[index], k + 1, times[:, index, k], bool(stretched[index]),
                              bool(two_sided), scale, atol, escape))
    for shot, result in zip(shots, pool.map(_map_shot, shots), strict=True):
        if isinstance(result, FoundOrbit):
            found.append(result)
        else:
            failures.append(FailedSeed(tuple(shot[0]), result))
    region = dict(energy=geometry.energy, section=geometry.section.label, window=window,
                  momentum=(-top, top), seeds=U.shape[0], accessible=int(ok.sum()),
                  max_returns=max_returns, horizon=float(max(horizons, default=0.0)),
                  parts=((f"on a {side} x {side} grid of the whole map", U.shape[0],
                          int(ok.sum())),))
    return found, failures, region


def _both_ways(geometry, z0, max_returns: int, first: float, atol, escape):
    """A seed of the whole map followed forwards to ``2 max_returns`` crossings and backwards
    to ``max_returns``: ``(forward, horizon, backward)``."""
    run, horizon = _follow(geometry, z0, 2 * max_returns, first, atol, escape)
    back, _ = _follow(geometry, z0, max_returns, -first, atol, escape)
    return run, horizon, back


def _map_shot(geometry, u, k: int, times, stretched: bool, two_sided: bool, scale, atol,
              escape):
    """From a grid minimum ``u`` of the ``k``-th return: Newton on the return map (not
    ``two_sided``), and where the map stretches and that failed, or for a minimum of the
    two-sided residual, multiple shooting (`_two_sided`); ``times``: the map's and the
    two-sided crossing times there. A `FoundOrbit` or why not."""
    result = None if two_sided else _newton_map(geometry, u, k, times[0], scale, atol, escape)
    if result is None or (stretched and not isinstance(result, FoundOrbit)):
        result = _two_sided(geometry, u, times[1:], atol, escape)
    return result


def _equilibrium_orbits(geometry, window, params):
    """``(found, failures, count)``: the orbits closed from the linearised orbits about the
    equilibria on the section's line (``linearised.py``): each critical point of the least
    energy along the line in the window is polished into an equilibrium by Newton on
    ``grad H = 0`` (momenta from zero), its centre mode crossing the section taken at the
    energy, and that orbit closed by multiple shooting on the exact flow (``_close_path``).
    Seeds of the whole map near a strongly unstable orbit (Hill's Lyapunov orbits: a multiplier
    of 2000) leave before they return; the linearised orbit is a whole period already."""
    from .linearised import linearised_orbit

    grid = np.linspace(window[0], window[1], 4001)
    V = _least_energy(geometry, grid)
    inner = (V[1:-1] - V[:-2]) * (V[2:] - V[1:-1]) < 0
    critical = grid[1:-1][inner & np.isfinite(V[1:-1])]
    atol, escape, _ = _scales(geometry, window)
    found, failures = [], []
    for x in critical:
        z_e = _equilibrium(geometry, x)
        seed = (float(x), 0.0)
        try:
            guess = linearised_orbit(geometry.system, energy=geometry.energy, equilibrium=z_e,
                                     section=geometry.section.label, params=params)
        except InputError as why:
            failures.append(FailedSeed(seed, f"no linearised orbit about the critical point at "
                                             f"q_o = {x:.6g}: {why}"))
            continue
        t, path = guess["t"], np.hstack([guess["q"], guess["p"]])
        result = _close_path(geometry, path[0], (t, path), atol, escape)
        (found if isinstance(result, FoundOrbit) else failures).append(
            result if isinstance(result, FoundOrbit) else FailedSeed(seed, result))
    return found, failures, int(critical.size)


def _equilibrium(geometry, x: float, iterations: int = 30) -> np.ndarray:
    """Newton on ``grad H = 0`` from the section's line at ``q_o = x``, the momenta zero (the
    point reached: `linearised_orbit` refuses it when it is no equilibrium)."""
    from .linearised import equilibrium_derivatives

    section = geometry.section
    z = np.zeros(4)
    z[section.index], z[section.other] = section.value, x
    derivatives = equilibrium_derivatives(geometry.system)
    with np.errstate(all="ignore"):
        for _ in range(iterations):
            _, gradient, hessian = (np.asarray(a, float) for a in derivatives(z, geometry.theta))
            try:
                step = np.linalg.solve(hessian, gradient.ravel())
            except np.linalg.LinAlgError:
                break
            if not np.all(np.isfinite(step)):
                break
            z = z - step
            if np.max(np.abs(step)) <= 4 * np.finfo(float).eps * max(np.max(np.abs(z)), 1e-300):
                break
    return z


def _map_grid(geometry, window, seeds: int, jitter):
    """The seeds of the whole map: a ``side x side`` grid of cells over the window and the
    momenta's box ``[-top, top]``, about ``seeds`` of them accessible; each seed at its cell's
    centre, or (``jitter``: a generator's seed) at a random point of its cell."""
    probe = np.linspace(window[0], window[1], 101)
    top = 1.25 * _momentum_scale(geometry, window)
    fine = np.array([(x, p) for x in probe for p in np.linspace(-top, top, 101)])
    share = max(float(np.mean(np.all(np.isfinite(geometry.points(fine)), axis=1))), 1e-3)
    side = max(int(np.sqrt(seeds / share)), 3)  # about `seeds` of the grid's points accessible
    line = _cells(window, side, jitter)
    side = line.size
    momenta = np.linspace(-top, top, side)
    if jitter is not None:  # each within its spacing about the grid's momentum
        spread = np.random.default_rng([jitter, 1]).uniform(-0.48, 0.48, side)
        momenta = momenta + spread * (2 * top / (side - 1))
    U = np.array([(x, p) for x in line for p in momenta])
    return U, side, top


def _momentum_scale(geometry, window) -> float:
    """The momenta's size on the section's line (``p_o = 0``) in the window: most of the line's
    ``|p|`` (its largest is a singularity's, 1e7 near Hill's Moon, and would leave every seed
    of the whole map's grid but a column inaccessible); the window's half-width where the
    energy allows no motion on the line."""
    probe = np.linspace(window[0], window[1], 101)
    z_line = geometry.points(np.column_stack([probe, np.zeros(probe.size)]))
    if not np.any(np.isfinite(z_line)):
        return (window[1] - window[0]) / 2
    return float(np.nanpercentile(np.abs(z_line[:, 2:]), 90))


def _grid_minima(gap: np.ndarray, threshold: float = 0.5):
    """Cells of ``gap`` below ``threshold`` that are the least of their 3 x 3 neighbours."""
    padded = np.pad(np.where(np.isfinite(gap), gap, np.inf), 1, constant_values=np.inf)
    rows, cols = gap.shape
    for i in range(rows):
        for j in range(cols):
            value = padded[i + 1, j + 1]
            if value < threshold and value <= padded[i:i + 3, j:j + 3].min():
                yield i, j


def _newton_map(geometry, u0, k: int, t_guess: float, scale, atol, escape):
    """Newton on ``P^k(u) - u = 0`` from ``u0`` (derivative of the map from the variational
    equations), the orbit closed and checked; or why not."""
    def evaluate(u):
        z0 = geometry.points([u])[0]
        if not np.all(np.isfinite(z0)):
            return None, None
        run = returns(geometry, z0, 1.5 * t_guess, atol, attempts=10 * SEED_ATTEMPTS,
                      escape=escape)
        up = np.flatnonzero(run.direction > 0)
        if up.size < k:
            return None, None
        z_k, D = return_derivative(geometry, z0, run.t[up[k - 1]], atol)
        if z_k is None:
            return None, None
        return z_k[geometry.section.free] - u, (D, run.t[up[k - 1]], z0)

    def step(_u, residual, payload):
        return -np.linalg.lstsq(payload[0] - np.eye(2), residual, rcond=None)[0]

    result = exact_newton(evaluate, step, np.asarray(u0, float),
                          size=lambda r: float(np.max(np.abs(r) / scale)), tolerance=1e-11,
                          max_iterations=25, halvings=12)
    if not result.converged:
        why = "an evaluation left the region or lost the return" if result.failed_evaluation \
            else f"residual {result.residual:.2e} after {result.iterations} iterations"
        return f"shooting did not converge ({why})"
    _, period, z0 = result.payload
    return _closed(geometry, z0, period, atol, escape, symmetric=False)


def _two_sided(geometry, u, times, atol, escape):
    """Multiple shooting from a seed ``u`` whose ``k``-th crossing forwards, after
    ``times[0]``, nearly meets its ``k``-th crossing backwards, ``times[1]`` before: the
    orbit's guess is the forward run up to there and the backward run after it (the seed's
    error grows over half the orbit each way, the square root of its multiplier), closed by
    Newton on the exact flow's shooting equations on segments cut where the flow has grown
    tenfold (``exact/closure.py``; one segment, single shooting, where it never does); the
    orbit closed and checked; or why not."""
    forward, backward = float(times[0]), float(times[1])
    if not (np.isfinite(forward) and np.isfinite(backward)):
        return "shooting did not converge (the crossing was lost on one side)"
    z0 = geometry.points([u])[0]
    flow = exact_flow(geometry.system)
    period = forward + backward
    with np.errstate(all="ignore"):
        ahead = flow.run(z0, 0.0, forward, geometry.theta, rtol=RTOL, atol=atol,
                         max_attempts=10 * SEED_ATTEMPTS)
        behind = flow.run(z0, 0.0, -backward, geometry.theta, rtol=RTOL, atol=atol,
                          max_attempts=10 * SEED_ATTEMPTS)
    if not (ahead.success and behind.success):
        return "shooting did not converge (the seed's run stopped)"
    t = np.linspace(0.0, period, 801)
    first = t <= forward
    path = np.vstack([ahead.z(t[first]), behind.z(t[~first] - period)])
    return _close_path(geometry, z0, (t, path), atol, escape)


def _close_path(geometry, z0, path, atol, escape):
    """The orbit through ``path = (t, z)`` (one period, ``z0`` its start) closed by Newton on the
    exact flow's shooting equations on segments cut where the flow has grown tenfold
    (``exact/closure.py``), then checked (`_closed`); or why not."""
    from ..exact.closure import close_exact

    section = geometry.section
    period = float(path[0][-1])
    try:
        with np.errstate(all="ignore"):
            orbit = close_exact(geometry.system, geometry.theta, z0, period,
                                energy=geometry.energy, section_index=section.index + 1,
                                section_value=section.value, path=path)
    except np.linalg.LinAlgError:
        return "shooting did not converge (multiple shooting: a singular Newton matrix)"
    if not orbit.converged or not np.all(np.isfinite(orbit.z0)):
        return (f"shooting did not converge (multiple shooting on {orbit.cuts.size - 1} "
                f"segments: closure {orbit.closure:.2e} after {orbit.iterations} iterations)")
    if not orbit.period > 0.1 * period:  # T -> 0 closes every point: not an orbit
        return (f"shooting did not converge (multiple shooting went to the period "
                f"{orbit.period:.3g} from {period:.4g})")
    return _closed(geometry, orbit.z0, orbit.period, atol, escape, symmetric=False)


def _distinct(found: list) -> list:
    """Each orbit once: the same period and a shared upward crossing (module docstring);
    multiple covers (a crossing repeated within the period) are not kept."""
    kept = []
    for orbit in found:
        scale = own_size(orbit.path)[[0, 2]]  # of u = (q_o, p_o): a position, a momentum
        if _covers(orbit, scale):
            continue
        same = next((other for other in kept
                     if abs(other.period - orbit.period) <= SAME * other.period and any(
                         _near(row, orbit.crossings[0], scale, 1e3 * SAME)
                         for row in other.crossings)), None)
        if same is None:
            kept.append(orbit)
        else:
            same.seeds += 1
    return kept


def _within_returns(orbits: list, max_returns: int) -> tuple[list, list]:
    """``(kept, failures)``: the orbits of at most ``max_returns`` upward crossings, and a
    `FailedSeed` for each other one (a shot can close on an orbit of more crossings than its
    seed's: the option bounds what is listed, so it is said, not listed)."""
    kept = [orbit for orbit in orbits if orbit.returns <= max_returns]
    beyond = [FailedSeed(tuple(float(v) for v in orbit.crossings[0]),
                         f"closed on an orbit of {orbit.returns} upward crossings, beyond "
                         f"max_returns = {max_returns} (period {orbit.period:.10g})")
              for orbit in orbits if orbit.returns > max_returns]
    return kept, beyond


def _covers(orbit: FoundOrbit, scale: np.ndarray) -> bool:
    """Whether the orbit repeats its start before its period (a multiple cover)."""
    return len(orbit.crossings) < orbit.returns or any(
        _near(row, orbit.crossings[0], scale, 1e3 * SAME) for row in orbit.crossings[1:])
