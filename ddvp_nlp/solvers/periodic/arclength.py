"""A family of periodic orbits by pseudo-arclength continuation in the energy, with each member's
stability and the bifurcations along it located.

The family is the solution curve of ``F(x; E) = 0``, the periodic system of ``closed_grid.py``
(``x``: the nodes, node times and unfolding parameters of ``N`` intervals) with the energy ``E``
an unknown too. From a member ``y_i = (x_i, E_i)`` with unit tangent ``t_i`` (``F_x t_x + F_E
t_E = 0``, ``<t_i, t_i> = 1``; oriented as the previous one) the next member solves::

    F(x; E) = 0,    <t_i, y - y_i> = ds          (Keller's pseudo-arclength)

by the grid's Newton (sparse LU of the bordered Jacobian ``[[F_x, F_E], [W t_i^T, 0]]``) from
the predictor ``y_i + ds t_i``. ``<a, b> = sum_j a_j b_j / K + a_E b_E`` (``K`` the number of
node values): the nodes count by their mean square, so that a step is about as long in the
orbit as in ``E``. At a fold, where the family turns back in ``E`` and ``F_x`` is singular,
``t_E`` changes sign and the bordered matrix stays regular: the continuation passes it. The step
``ds`` grows by 1.5 after a corrector that took at most 3 iterations and halves after one that
failed; every member is then verified by `solve_periodic` (its residuals, its
accuracy check), which starts from it.

Each member's stability is its discrete monodromy's (``floquet.py``). Bifurcations are sign
changes between neighbours of three test functions, smooth along the family whatever order the
multipliers come in:

- ``t_E``: a **fold** (the family turns back in ``E``; a multiplier pair passes +1 with it);
- ``det(R - I) = prod_j (2 - k_j)`` (``R`` the reduced monodromy, ``k_j`` the stability
  indices): a pair passes **+1** without a fold: a **branch point** (a symmetry-breaking
  pitchfork, such as the halo family's birth from the planar Lyapunov family);
- ``det(R + I) = prod_j (2 + k_j)``: a pair passes **-1**: **period doubling**.

Each is located by Brent's method (bisection safeguarded by secant steps) in the arclength
``s`` between the two members, every evaluation a corrector solve at ``<t_i, y - y_i> = s``,
until the bracket's energies are within ``locate_tol``; the orbit at the located point is
verified like a member.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.optimize import brentq

from ...discrete.scheme import Scheme
from ...errors import InputError
from ...physics.constraints import refuse_constrained
from ...solution import Solution
from ...validation import check_integer, check_real
from ..grid.motion_size import energy_traded, orbit_sizes
from ..grid.newton import newton
from ..grid.problem import BorderedLayout
from ..options import GridOptions, coerce
from .bifurcation import KINDS, confirm, tests
from .closed_grid import (
    EPS,
    NOISE_TARGET,
    Closure,
    PeriodicAssembly,
    closed_targets,
    integral_gradients,
)
from .first_orbit import closing_shift
from .floquet import DEFAULT_TOL, Stability, discrete_stability, periodic_stability
from .orbit import check_periodic, parse_section, solve_periodic
from .switching import Switch, checked_switch, follow_branches

# Corrector: iterations, and those at most of which the step grows.
CORRECTOR_ITERATIONS = 15
EASY_ITERATIONS = 3


@dataclass(frozen=True)
class Continuation:
    """How `follow_periodic_family` walks along the family.

    Attributes:
        step: the first step, in the energy (default a twentieth of the range).
        max_step: the longest step, in the energy (default a tenth of the range).
        max_orbits: at most this many members.
        min_step: the continuation stops when a failed step has been halved below this
            fraction of the first step.
        tol: the tolerance of the stability verdicts, on the stability indices.
        locate_tol: the located bifurcations' bracket in the energy, relative to the family's
            energy range (a branch's: the energy its first orbit trades in a radian of its
            period; it was ``max(1, |E|)``, which a constant added to ``H`` or a change of
            units moved).
        exact: close the exact flow at every member and analyse its monodromy
            (`periodic_stability`; about 0.1-1 s an orbit).
        confirm: locate each bifurcation on the exact flow too (``bifurcation.confirm``).
        switch: a `Switch` (or ``True`` for its defaults): at a located branch point, both
            halves of the new branch followed too (``switching.py``), in ``Family.branches``.
    """

    step: float | None = None
    max_step: float | None = None
    max_orbits: int = 200
    min_step: float = 1e-4
    tol: float = DEFAULT_TOL
    locate_tol: float = 1e-10
    exact: bool = True
    confirm: bool = True
    switch: Switch | bool | None = None

    def __post_init__(self):
        for name in ("step", "max_step"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, check_real(name, value, positive=True))
        object.__setattr__(self, "max_orbits", check_integer("max_orbits", self.max_orbits,
                                                             minimum=2))
        for name in ("min_step", "tol", "locate_tol"):
            object.__setattr__(self, name, check_real(name, getattr(self, name), positive=True))
        object.__setattr__(self, "switch", checked_switch(self.switch))


@dataclass
class Member:
    """One orbit of the family: its energy, the verified orbit, its stability, its arclength
    from the first member and the energy component of its unit tangent (``dE/ds``)."""

    energy: float
    orbit: Solution
    stability: Stability
    arclength: float
    slope: float


@dataclass
class Bifurcation:
    """A located bifurcation: its kind (``KINDS``), energy, the energies of the final bracket,
    the member it follows, the test function's values at the two members, the verified orbit
    at the located point and its stability."""

    kind: str
    energy: float
    bracket: tuple
    after: int
    tests: tuple
    orbit: Solution
    stability: Stability
    extra: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        indices = self.stability.indices
        return {"kind": self.kind, "energy": self.energy, "bracket": list(self.bracket),
                "after_member": self.after, "period": self.orbit.orbit.period,
                "indices": [[float(k.real), float(k.imag)] for k in indices],
                "status": self.orbit.status.code, **self.extra}


@dataclass
class Family:
    """The members in the order of the continuation, the bifurcations located between them,
    and how the continuation ended (``message``; ``complete`` when it left the energy range).
    ``unlocated``: sign changes of a test function whose location failed (the corrector lost
    the family inside the bracket), each ``{"kind", "after_member", "energies"}``: reported,
    not dropped. ``branches``: the new branches followed from a branch point when asked
    (``switching.Branch``, each half a `Family` with its own ``seconds``), ``switched`` what
    the switch found or why it found none; ``seconds``: the family's own, without them.
    ``grid``: a half's grid and its orbits' period error estimates (``branch_grid.BranchGrid``
    as a dict), empty on the family's grid."""

    members: list
    bifurcations: list
    complete: bool
    message: str
    seconds: float = 0.0
    unlocated: list = field(default_factory=list)
    branches: list = field(default_factory=list)
    switched: str = ""
    grid: dict = field(default_factory=dict)


# The first steps are at most this share of the first point's length in the arclength measure
# (`_Walker._first_steps`); a bifurcation between members whose slopes are both 0 is located to
# this share of the step between them.
FIRST_SHARE = 0.1
FLAT_XTOL = 1e-12


# The corrector's targets in round-off targets of the orbit solve: every member is solved again
# by `solve_periodic` from the corrector's point, so the corrector stops well short of round-off,
# where its iteration count (which sets the next step) does not hang on the last digits.
CORRECTOR_SLACK = 16.0


def _corrector_targets(walker, arc, guess: np.ndarray) -> np.ndarray:
    """The corrector's per-row targets at ``guess``: ``CORRECTOR_SLACK`` times the orbit rows'
    round-offs (``closed_grid.closed_targets``, read off the rows: ``64 eps max(1, |x|)`` put a
    swing in lengths of ``1e-8`` at ``1e-6`` of its size) and the arclength row's, that of
    every value it weighs (each known to ``eps`` of itself)."""
    rows = closed_targets(walker.assembly, guess[:-1],
                          replace(walker.closure, energy=float(guess[-1])), walker.sizes)
    return CORRECTOR_SLACK * np.r_[rows, 4 * NOISE_TARGET * EPS * max(abs(arc.length), float(
        np.sum(np.abs(arc.row) * (np.abs(guess) + np.abs(arc.origin)))))]


def _energy_scale(low: float, high: float, first: Solution) -> float:
    """The energies' own scale: the range ``high - low``; a branch's, unbounded, what its first
    orbit trades in a radian of its period. Never ``max(1, |E|)``: a constant added to ``H``
    moved that, and in units of ``1e-16`` of energy it was ``1e16`` times the whole family."""
    if np.isfinite(high - low):
        return float(high - low)
    return energy_traded(first.t, np.hstack([first.q, first.p]),
                         float(first.t[-1] - first.t[0]) / (2 * np.pi))


def _first_steps(walker) -> tuple[float, float]:
    """The first and the longest step in the arclength from the energy steps and the first
    member's slope ``dE/ds``, at most ``FIRST_SHARE`` of the first point's own length in the
    arclength's measure (a fold at the start has no slope). A floor of ``1e-12`` on the slope
    made a family in energy units of ``1e-16`` (a swing in lengths of ``1e-8``, slope ``3e-16``)
    walk in steps of ``1e-6`` of its range until ``max_orbits``."""
    slope = abs(walker.members[0].slope)
    cap = FIRST_SHARE * float(np.sqrt(np.sum(walker.arc.weights * walker.points[0] ** 2)))
    if slope == 0:
        return cap, cap
    return min(walker.first_step / slope, cap), min(walker.max_step / slope, cap)


@dataclass
class _Arc:
    """The data of one corrector solve: the closure (its energy is replaced by the unknown),
    the weighted tangent row, the point the arclength is measured from and the arclength."""

    closure: Closure
    row: np.ndarray
    origin: np.ndarray
    length: float


class ArclengthSystem:
    """``F(x; E)`` with ``E`` the last unknown, and the arclength row (module docstring): a
    ``grid.GridProblem`` for the grid's Newton (sparse LU)."""

    def __init__(self, assembly: PeriodicAssembly):
        self.base = assembly
        self.layout = BorderedLayout(assembly.layout)
        N, m, h = assembly.layout.intervals, assembly.layout.m, assembly.header
        rows = h + np.arange(N) * m + m - 1  # the rows H(Q_k, P_k) - E
        self.energy_column = sp.csc_matrix((-np.ones(N), (rows, np.zeros(N, int))),
                                           (assembly.layout.size, 1))
        count = assembly.layout.nodes * m
        self.weights = np.r_[np.full(count, 1.0 / count), np.zeros(assembly.layout.unfoldings),
                             1.0]

    def evaluate(self, y: np.ndarray, arc: _Arc, jacobian: bool = True):
        closure = replace(arc.closure, energy=float(y[-1]))
        F, blocks = self.base.evaluate(y[:-1], closure, jacobian)
        F = np.r_[F, arc.row @ (y - arc.origin) - arc.length]
        if not jacobian:
            return F, None
        return F, self.bordered(blocks, arc.row)

    def bordered(self, blocks, row: np.ndarray) -> sp.csc_matrix:
        return sp.bmat([[self.base.sparse(blocks), self.energy_column],
                        [sp.csr_matrix(row[None, :-1]), sp.csr_matrix(row[None, -1:])]],
                       format="csc")

    def sparse(self, jacobian):
        return jacobian

    def release(self) -> None:
        self.base.release()

    def parameter_jacobian(self, y: np.ndarray, arc: _Arc) -> sp.csc_matrix:
        """``dF/dtheta`` at ``y``, ``(size + 1, len(theta))``: the periodic rows' at the energy
        ``y[-1]`` (``PeriodicAssembly.parameter_jacobian``, from the same CasADi rows as
        ``F``), then the arclength row's, zero (it does not depend on ``theta``)."""
        closure = replace(arc.closure, energy=float(y[-1]))
        rows = self.base.parameter_jacobian(y[:-1], closure)
        return sp.vstack([rows, sp.csc_matrix((1, rows.shape[1]))], format="csc")

    def tangent(self, y: np.ndarray, closure: Closure, previous: np.ndarray) -> np.ndarray:
        """The unit tangent at ``y`` oriented along ``previous`` (``<t, previous> > 0``)."""
        _, blocks = self.base.evaluate(y[:-1], replace(closure, energy=float(y[-1])), True)
        matrix = self.bordered(blocks, self.weights * previous)
        rhs = np.zeros(y.size)
        rhs[-1] = 1.0
        t = spla.splu(matrix).solve(rhs)
        return t / np.sqrt(np.sum(self.weights * t * t))


def follow_periodic_family(system, energies, *, nodes: int, section="p1=0", guess=None,
                           scheme="vddvp", params=None, start=None, integrals=(), angles=(),
                           options: GridOptions | None = None,
                           continuation: Continuation | None = None) -> Family:
    """The family of periodic orbits through the orbit at ``energies[0]``, followed by
    pseudo-arclength continuation until its energy leaves ``[min(energies), max(energies)]``
    (or ``max_orbits``), with every member's stability and the bifurcations between them
    located (module docstring).

    Args:
        system: an autonomous Hamiltonian system.
        energies: ``(E_start, E_end)``: the first orbit's energy and the end of the range
            (the continuation heads towards it).
        nodes, section, guess, scheme, params, start, integrals, angles, options: as for
            `solve_periodic` (``guess`` and ``start`` for the first orbit).
        continuation: the steps, the stopping rules, the tolerances and the branch switch
            (`Continuation`).

    Returns:
        A `Family`; a first orbit that is not found raises no error: the family is
        empty and its message says why.
    """
    started = time.perf_counter()
    settings = _checked(system, energies, nodes, section, guess, scheme, params, start, angles,
                        options, continuation)
    first_energy, last_energy, options, walk = settings
    common = {"section": section, "scheme": scheme, "params": params, "integrals": integrals,
              "angles": angles, "options": options}
    first = solve_periodic(system, energy=first_energy, nodes=nodes, guess=guess, start=start,
                           **common)
    if not first.success:
        return Family([], [], False, f"the first orbit was not found: {first.message}",
                      time.perf_counter() - started)
    walker = _Walker(system, first, nodes, common, walk, (first_energy, last_energy))
    members, message, complete = walker.walk()
    bifurcations, unlocated = walker.locate_all()
    if unlocated:
        message += (f"; {len(unlocated)} sign change(s) of a test function not located: "
                    + ", ".join(f"{u['kind']} after member {u['after_member']}"
                                for u in unlocated))
    family = Family(members, bifurcations, complete, message, time.perf_counter() - started,
                    unlocated)
    if walk.switch is not None:
        family.branches, family.switched = follow_branches(walker, bifurcations, walk.switch,
                                                           Family)
    return family


def _checked(system, energies, nodes, section, guess, scheme, params, start, angles, options,
             continuation):
    """The energies, options and continuation settings, checked before anything is built (the
    first orbit's arguments by `check_periodic`, its section point included when no
    guess is given)."""
    refuse_constrained(system, "follow_periodic_family")  # its predictor's rows are unconstrained
    try:
        first_energy, last_energy = (float(e) for e in energies)
    except (TypeError, ValueError):
        raise InputError(f"energies must be a pair (E_start, E_end), got {energies!r}") from None
    if not (np.isfinite(first_energy) and np.isfinite(last_energy)) \
            or first_energy == last_energy:
        raise InputError(f"energies must be two different finite numbers, got {energies!r}")
    options = coerce(options, GridOptions, "options")
    walk = coerce(continuation, Continuation, "continuation")
    check_integer("nodes", nodes, minimum=4)
    if guess is None:
        check_periodic(system, energy=first_energy, nodes=nodes, section=section,
                       scheme=scheme, params=params, start=start, angles=angles,
                       options=options)
    return first_energy, last_energy, options, walk


class _Walker:
    """The continuation's state: the assembly, the closure, the members and their tangents."""

    def __init__(self, system, first: Solution, nodes: int, common: dict, walk: Continuation,
                 energies, previous=None):
        # nodes of the closed grid (as solve_periodic takes them) and its intervals
        self.system, self.nodes, self.common, self.settings = system, nodes, common, walk
        self.intervals = nodes - 1
        self.theta = system.parameter_vector(common["params"])
        self.integrals = tuple(common["integrals"])
        self.low, self.high = min(energies), max(energies)
        self.energy_scale = _energy_scale(self.low, self.high, first)
        self.direction = np.sign(energies[1] - energies[0])
        span = self.high - self.low
        self.first_step = walk.step or span / 20
        self.max_step = walk.max_step or span / 10
        self.closure = self._closure(first)
        self.assembly = PeriodicAssembly(system, Scheme.coerce(common["scheme"]), self.intervals,
                                         self.integrals)
        self.arc = ArclengthSystem(self.assembly)
        self.sizes = orbit_sizes(system, self.theta, first.t, np.hstack([first.q, first.p]))
        self.members, self.points, self.tangents, self.steps = [], [], [], []
        self._accept(first, previous, 0.0)

    def _closure(self, orbit: Solution) -> Closure:
        n = self.system.n
        index, value, _ = parse_section(orbit.orbit.section, n)
        z = np.hstack([orbit.q, orbit.p])
        generators = np.zeros((len(self.integrals), 2 * n))
        if self.integrals:
            gradients = np.asarray(integral_gradients(self.system, self.integrals)(
                z[0, :n], z[0, n:], self.theta))[:, 1:].T
            generators = np.hstack([gradients[:, n:], -gradients[:, :n]])
        angles = tuple(i for i, w in enumerate(orbit.orbit.winding) if w)
        return Closure(float(orbit.orbit.energy), index, value, self.theta, z[0].copy(),
                       generators, closing_shift(z[0], z[-1], angles))

    def point(self, orbit: Solution) -> np.ndarray:
        x = self.assembly.layout.pack(orbit.t - orbit.t[0], orbit.q, orbit.p)
        return np.r_[x, float(orbit.orbit.energy)]

    def _accept(self, orbit: Solution, tangent_before, arclength: float) -> None:
        y = self.point(orbit)
        previous = tangent_before if tangent_before is not None else np.r_[
            np.zeros(y.size - 1), self.direction]
        tangent = self.arc.tangent(y, self.closure, previous)
        stability = periodic_stability(self.system, orbit, params=self.common["params"],
                                       integrals=self.integrals, tol=self.settings.tol,
                                       exact=self.settings.exact)
        self.members.append(Member(float(y[-1]), orbit, stability, arclength,
                                   float(tangent[-1])))
        self.points.append(y)
        self.tangents.append(tangent)

    def correct(self, i: int, length: float):
        """The point at arclength ``length`` from member ``i`` along its tangent, or
        ``None``; with the corrector's iterations."""
        return self.correct_from(self.points[i], self.tangents[i], length)

    def correct_from(self, y: np.ndarray, t: np.ndarray, length: float):
        """The point at arclength ``length`` from ``y`` along ``t``, or ``None``; with the
        corrector's iterations."""
        arc = _Arc(self.closure, self.arc.weights * t, y, length)
        guess = y + length * t
        target = _corrector_targets(self, arc, guess)
        period = guess[self.assembly.layout.time_index()[-1]]
        result = newton(self.arc, guess, arc, target, tau_floor=1e-3 * period / self.intervals,
                        max_iter=CORRECTOR_ITERATIONS, linear="sparse")
        if not result.converged:
            return None, result.iterations
        return result.x, result.iterations

    def verified(self, y: np.ndarray) -> Solution:
        """``solve_periodic`` started from the point ``y`` (its verification)."""
        t, q, p, _ = self.assembly.layout.unpack(y[:-1])
        return solve_periodic(self.system, energy=float(y[-1]), nodes=self.nodes,
                              guess={"t": t, "q": q, "p": p}, **self.common)

    def walk(self, ds: float | None = None, longest: float | None = None,
             turning: float | None = None):
        """Members until the energy leaves the range, ``max_orbits``, or a step fails below
        ``min_step``: ``(members, message, complete)``; the first and the longest step in the
        arclength are given (a branch) or from the energy steps and the first slope. The step
        grows by 1.5 after an easy corrector (``EASY_ITERATIONS``); with ``turning`` (a
        branch's halves), after a corrector of at most twice as many iterations, by at most what
        keeps the predictor's miss ``|y - (y_i + ds t_i)| / ds`` (about half the tangent's turn
        over the step) near ``turning``, and it shrinks when the miss is over twice that."""
        if ds is None:
            ds, longest = _first_steps(self)
        smallest = self.settings.min_step * ds
        arclength = 0.0
        while len(self.members) < self.settings.max_orbits:
            y, iterations = self.correct(len(self.members) - 1, ds)
            orbit = self.verified(y) if y is not None else None
            if orbit is None or not orbit.success:
                ds /= 2
                if ds < smallest:
                    said = "the corrector did not converge" if orbit is None else orbit.message
                    return self.members, (f"stopped at E = {self.members[-1].energy:.10g}: a "
                                          f"step below {smallest:.3g} failed ({said})"), False
                continue
            if not self.low <= float(y[-1]) <= self.high:
                return self.members, (f"left the energy range after {len(self.members)} "
                                      f"orbits"), True
            arclength += ds
            self.steps.append(ds)
            growth = 1.5 if turning is None else self._growth(y, ds, turning)
            self._accept(orbit, self.tangents[-1], arclength)
            easy = EASY_ITERATIONS if turning is None else 2 * EASY_ITERATIONS
            if iterations <= easy or growth < 1:
                ds = min(growth * ds, longest)
        return self.members, f"max_orbits = {self.settings.max_orbits} reached", False

    def _growth(self, y: np.ndarray, ds: float, turning: float) -> float:
        """The step's factor from the predictor's miss (`walk`): between 1/2 and 3/2."""
        miss = y - (self.points[-1] + ds * self.tangents[-1])
        relative = float(np.sqrt(np.sum(self.arc.weights * miss * miss))) / ds
        return float(np.clip(turning / max(relative, EPS), 0.5, 1.5))

    def locate_all(self):
        """``(located, unlocated)``: every sign change between neighbours (module
        docstring)."""
        found, unlocated = [], []
        for i in range(len(self.members) - 1):
            a, b = self.members[i], self.members[i + 1]
            before, after = tests(a.stability, a.slope), tests(b.stability, b.slope)
            fold = before["fold"] * after["fold"] < 0
            for kind in KINDS:
                if before[kind] * after[kind] >= 0 or (kind == "branch point" and fold):
                    continue
                located = self.locate(i, kind)
                if located is not None:
                    found.append(located)
                else:
                    unlocated.append({"kind": kind, "after_member": i,
                                      "energies": (a.energy, b.energy)})
        return found, unlocated

    def _test_at(self, i: int, length: float, kind: str):
        y, _ = self.correct(i, length)
        if y is None:
            raise _LostFamily(length)
        if kind == "fold":
            return float(self.arc.tangent(y, self.closure, self.tangents[i])[-1]), y
        t, q, p, _ = self.assembly.layout.unpack(y[:-1])
        stability = discrete_stability(self.system, self.assembly.scheme, t, q, p,
                                       energy=float(y[-1]),
                                       section_index=self.closure.section_index,
                                       theta=self.theta, integrals=self.integrals,
                                       tol=self.settings.tol)
        return tests(stability, 1.0)[kind], y

    def locate(self, i: int, kind: str):
        """The bifurcation of ``kind`` between members ``i`` and ``i + 1`` (module
        docstring)."""
        a, b = self.members[i], self.members[i + 1]
        tolerance = self.settings.locate_tol * self.energy_scale
        points, values = {}, {}

        def test(length):
            value, y = self._test_at(i, length, kind)
            points[length], values[length] = y, value
            return value
        slope = max(abs(a.slope), abs(b.slope))
        width = self.steps[i]
        xtol = min(tolerance / slope, width) if slope > 0 else FLAT_XTOL * width
        try:
            root = brentq(test, 0.0, width, xtol=xtol, rtol=4 * EPS, maxiter=100)
        except (_LostFamily, ValueError):
            return None
        y = points.get(root)
        if y is None:
            test(root)
            y = points[root]
        orbit = self.verified(y)
        if not orbit.success:
            return None
        stability = periodic_stability(self.system, orbit, params=self.common["params"],
                                       integrals=self.integrals, tol=self.settings.tol,
                                       exact=self.settings.exact)
        before = tests(a.stability, a.slope)[kind]
        after = tests(b.stability, b.slope)[kind]
        signs = {0.0: np.sign(before), width: np.sign(after)}
        signs.update({s: np.sign(v) for s, v in values.items()})
        left = max(s for s, sign in signs.items() if sign == signs[0.0] and s <= root)
        right = min(s for s, sign in signs.items() if sign != signs[0.0] and s >= root)
        energy = {0.0: a.energy, width: b.energy, **{s: float(p[-1]) for s, p in points.items()}}
        bracket = tuple(sorted((energy[left], energy[right])))
        extra = {}
        if self.settings.confirm:
            confirmed = confirm(self.system, self.theta, orbit, kind,
                                section_index=self.closure.section_index,
                                section_value=self.closure.section_value,
                                integrals=self.integrals, tol=self.settings.tol)
            extra = confirmed.as_dict() if confirmed is not None else {"exact_energy": None}
        return Bifurcation(kind, float(y[-1]), bracket, i, (before, after), orbit, stability,
                           extra)


class _LostFamily(Exception):
    """The corrector did not converge inside a bracket."""
