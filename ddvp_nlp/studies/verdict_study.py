"""The accuracy check's verdicts on systems nobody chose, set beside the true error of each run.

A *case* is a random Hamiltonian in ``n = 1 .. 3`` degrees of freedom (`RandomSystem`:
a polynomial or trigonometric potential with couplings, masses, a non-separable term, a forcing
``F cos(Omega t) q_1`` and a gauge term ``A sin(Omega' t)``), a start, a first step and a
horizon, all in the system's own units, and the units it is marched in (`Units`: ``q``,
``p`` and ``t`` rescaled, a constant added to ``H``, a translation of ``q`` where ``H`` is
translation-invariant, a shift of the clock). In the marched variables

    H(q, p, t) = (u_q u_p / u_t) H~((q - shift) / u_q, p / u_p, (t - t_shift) / u_t) + offset,

the same motion as ``H~``'s in other units: the verdict must not depend on them
(tests/library/accuracy/test_units.py).

Each case is marched (``march``, its verdict by ``accuracy/judgement.py``) and measured against
scipy's DOP853 at ``rtol = 1e-12`` with dense output, an integrator that shares nothing with the
check but the vector field; a second run at ``rtol = 1e-10`` bounds the first's error, and a case
where the two differ by more than ``global_tol / 20`` of the motion's size at some node has no
trusted truth and is left out (counted). The true error is ``max_k max_i |z_k,i - z_i(t_k)| /
S_i`` with ``S`` the motion's scales (``motion_scales``): for the verdict (``true_all``) over
every node and every true state; for the ratio to the verdict's own figure (``true``), over the
nodes the verdict covered (up to ``reference_until``, where the check's scan stopped) with the
scales of every node and of the true states up to there, as the check's own.

How a verdict is judged (`classify`, ``MARGIN = 2``):

- a **false success**: the verdict is ``accurate`` and the true error is above
  ``MARGIN * global_tol``;
- a **false refusal**: the verdict is ``drifted`` or ``inaccurate`` and the true error is below
  ``global_tol / MARGIN``;
- between ``global_tol / MARGIN`` and ``MARGIN * global_tol`` either verdict is consistent (the
  band is where the check's reference, held to a tenth of the tolerance, and the truth's own
  error could swap them).

The true error judged is the larger of the trajectory's and, for an energy rule, the first
step's energy level against ``H`` of the truth at the level's clock in units of the state's
tolerance (``true_level * global_tol / energy_tol``, `true_level_error`): the check refuses a
run whose level is off by more than ``energy_tol`` however close its first nodes are, and the
truth measures that test too (a Lee march of a time-dependent ``H`` whose first step set a
level 14 % off, then failed, had been counted a false refusal by its trajectory alone).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import asdict, dataclass, field

import casadi as ca
import numpy as np

from ..discrete import Scheme
from ..physics import HamiltonianSystem
from ..solvers import Compilation, StepControl, Tolerance, march, motion_scales

MARGIN = 2.0
TRUTH_RTOL = 1e-12
CHECK_RTOL = 1e-10
SCHEMES = ("vddvp", "vddvp", "vddvp", "lee", "fixed")
MAX_STEPS = 4000
# The truth's bounds (``_dense_truth``): its steps, and how far past the run's own size a state
# may go before the truth is not trusted.
TRUTH_MAX_STEPS = 50_000
TRUTH_ESCAPE = 1e6


@dataclass(frozen=True)
class RandomSystem:
    """``H~(Q, P, T) = sum P_i^2 / (2 m_i) + mixing term + V(Q) + F Q_1 cos(Omega T) + A sin(
    Omega' T)`` in the system's own units (module docstring). ``V`` is ``polynomial``
    (``k Q^2/2 + c Q^3/3 + d Q^4/4`` per coordinate, ``e (Q_i - Q_j)^2/2 + e (Q_i - Q_j)^4/4``
    per pair) or ``trigonometric`` (``k (1 - cos Q)`` per coordinate, ``e (1 - cos(Q_i -
    Q_j))`` per pair); with ``translation_invariant`` the per-coordinate terms are left out, so
    that ``H`` depends on differences of ``Q`` only. The mixing term: ``mu (Q_1 P_2 - Q_2 P_1)``
    for ``n >= 2`` (a rotating frame), ``mu Q_1^2 P_1^2 / 2`` for ``n = 1``."""

    n: int
    potential: str
    stiffness: tuple
    cubic: tuple
    quartic: tuple
    coupling: tuple
    masses: tuple
    mixing: float = 0.0
    forcing: float = 0.0
    frequency: float = 1.0
    gauge: float = 0.0
    gauge_frequency: float = 1.0
    translation_invariant: bool = False

    def hamiltonian(self, Q, P, T):
        """``H~`` on CasADi symbols (or numbers)."""
        n = self.n
        H = sum(P[i] ** 2 / (2 * self.masses[i]) for i in range(n))
        if n >= 2:
            H += self.mixing * (Q[0] * P[1] - Q[1] * P[0])
        else:
            H += self.mixing * Q[0] ** 2 * P[0] ** 2 / 2
        pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
        if self.potential == "polynomial":
            if not self.translation_invariant:
                H += sum(self.stiffness[i] * Q[i] ** 2 / 2 + self.cubic[i] * Q[i] ** 3 / 3
                         + self.quartic[i] * Q[i] ** 4 / 4 for i in range(n))
            H += sum(e * ((Q[i] - Q[j]) ** 2 / 2 + (Q[i] - Q[j]) ** 4 / 4)
                     for e, (i, j) in zip(self.coupling, pairs, strict=False))
        else:
            if not self.translation_invariant:
                H += sum(self.stiffness[i] * (1 - ca.cos(Q[i])) for i in range(n))
            H += sum(e * (1 - ca.cos(Q[i] - Q[j]))
                     for e, (i, j) in zip(self.coupling, pairs, strict=False))
        H += self.forcing * Q[0] * ca.cos(self.frequency * T)
        H += self.gauge * ca.sin(self.gauge_frequency * T)
        return H

    @property
    def time_dependent(self) -> bool:
        return self.forcing != 0 or self.gauge != 0


@dataclass(frozen=True)
class Units:
    """The units a case is marched in (module docstring): ``z = (u_q Q + shift, u_p P)``,
    ``t = u_t T + t_shift``, ``H = (u_q u_p / u_t) H~ + offset``."""

    q: float = 1.0
    p: float = 1.0
    t: float = 1.0
    offset: float = 0.0
    shift: float = 0.0
    t_shift: float = 0.0


@dataclass(frozen=True)
class DrawnCase:
    """A random system, a start ``(Q0, P0)``, a first step and a horizon in its own units, a
    scheme, and the units it is marched in."""

    system: RandomSystem
    Q0: tuple
    P0: tuple
    tau0: float
    t_end: float
    scheme: str = "vddvp"
    units: Units = field(default_factory=Units)

    def in_units(self, units: Units) -> DrawnCase:
        """The same case marched in ``units``."""
        return DrawnCase(self.system, self.Q0, self.P0, self.tau0, self.t_end, self.scheme, units)

    def hamiltonian_system(self) -> HamiltonianSystem:
        u, base = self.units, self.system

        def hamiltonian(q, p, t):
            H = base.hamiltonian((q - u.shift) / u.q, p / u.p, (t - u.t_shift) / u.t)
            return u.q * u.p / u.t * H + u.offset
        return HamiltonianSystem(hamiltonian, base.n, name="random")

    def start(self) -> tuple[np.ndarray, np.ndarray, tuple[float, float], float]:
        """``q0``, ``p0``, ``(t0, t_end)`` and ``tau0`` in the marched units."""
        u = self.units
        q0 = np.asarray(self.Q0, float) * u.q + u.shift
        p0 = np.asarray(self.P0, float) * u.p
        return q0, p0, (u.t_shift, u.t_shift + u.t * self.t_end), u.t * self.tau0

    def describe(self) -> dict:
        return asdict(self)


def draw_case(rng: np.random.Generator, *, scaled: bool = True) -> DrawnCase:
    """A random case (module docstring); with ``scaled`` its units are random too (``q``,
    ``p``, ``t`` from ``1e-4`` to ``1e4``, an offset of ``H`` up to ``1e4`` of its scale, a
    translation up to ``1e4`` of ``q``'s unit where ``H`` allows it)."""
    n = int(rng.integers(1, 4))
    pairs = n * (n - 1) // 2
    invariant = bool(n >= 2 and rng.random() < 0.2)
    system = RandomSystem(
        n=n, potential=str(rng.choice(["polynomial", "trigonometric"])),
        stiffness=tuple(rng.uniform(0.2, 3.0, n).tolist()),
        cubic=tuple((rng.uniform(-0.5, 0.5, n) * (rng.random(n) < 0.5)).tolist()),
        quartic=tuple(rng.uniform(0.05, 1.0, n).tolist()),
        coupling=tuple((rng.uniform(0.0, 1.0, pairs) * (rng.random(pairs) < 0.7)).tolist()),
        masses=tuple(rng.uniform(0.5, 2.0, n).tolist()),
        mixing=float(rng.uniform(-0.3, 0.3)) if rng.random() < 0.3 else 0.0,
        forcing=float(rng.uniform(-0.5, 0.5)) if rng.random() < 0.25 else 0.0,
        frequency=float(rng.uniform(0.3, 3.0)),
        gauge=float(rng.uniform(-10, 10)) if rng.random() < 0.15 else 0.0,
        gauge_frequency=float(rng.uniform(0.3, 3.0)),
        translation_invariant=invariant)
    if invariant and not any(system.coupling):
        system = RandomSystem(**{**asdict(system), "coupling": (1.0,) * pairs})
    amplitude = 10 ** rng.uniform(-1.0, 0.2)
    tau0 = 10 ** rng.uniform(-2.5, 0.0)
    t_end = min(float(rng.uniform(2.0, 20.0)), MAX_STEPS / 2 * tau0)
    units = Units()
    if scaled:
        units = draw_units(rng, invariant=invariant)
    return DrawnCase(system, tuple(rng.uniform(-1, 1, n) * amplitude),
                     tuple(rng.uniform(-1, 1, n) * amplitude), float(tau0), float(max(t_end, tau0)),
                     str(rng.choice(SCHEMES)), units)


def draw_units(rng: np.random.Generator, *, invariant: bool) -> Units:
    """Random units (see `draw_case`)."""
    q, p, t = (10 ** rng.uniform(-4, 4) for _ in range(3))
    return Units(q=float(q), p=float(p), t=float(t),
                 offset=float(rng.uniform(-1, 1) * 10 ** rng.uniform(0, 4) * q * p / t),
                 shift=float(rng.uniform(-1, 1) * 10 ** rng.uniform(0, 4) * q) if invariant
                 else 0.0,
                 t_shift=float(rng.uniform(-1, 1) * 10 ** rng.uniform(0, 3) * t))


def run_case(case: DrawnCase, *, tolerance: Tolerance | None = None,
             compilation: Compilation | None = None):
    """The case marched (every accepted node kept, whatever its status) and judged."""
    system = case.hamiltonian_system()
    q0, p0, span, tau0 = case.start()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return system, march(system, q0, p0, span, tau0=tau0, scheme=case.scheme,
                             steps=StepControl(max_steps=MAX_STEPS),
                             accuracy=tolerance or Tolerance(),
                             compilation=compilation or Compilation(compiler=None, fast=False))


def true_error(system, solution, covered: float | None = None) -> dict:
    """The run's true error against scipy's DOP853 (module docstring): ``error`` over the nodes
    up to ``covered`` (all if ``None``), ``error_all`` over every node, ``truth_error`` (the
    bound of the truth's own error, same units) and ``trusted``."""

    from ..solvers import flow_callable

    t = solution.t
    z = np.hstack([solution.q, solution.p])
    n = system.n
    if t.size < 2:
        return {"error": 0.0, "error_all": 0.0, "truth_error": 0.0, "trusted": True}
    flow = flow_callable(system, system.parameter_vector({}))
    # The truth's absolute tolerance from the motion's scales (a component at rest at 0, which
    # drawn starts give, would otherwise get none and make DOP853's steps shrink without end).
    size = motion_scales(z.min(axis=0), z.max(axis=0), np.abs(z).max(axis=0), n)
    states = []
    for rtol in (TRUTH_RTOL, CHECK_RTOL):
        path = _dense_truth(flow, t, z[0], rtol, rtol * 1e-2 * size)
        if path is None:
            return {"error": math.nan, "error_all": math.nan, "truth_error": math.nan,
                    "trusted": False}
        states.append(path)
    truth = states[0]
    rows = slice(None) if covered is None else t <= covered

    def errors(states_seen):
        both = np.vstack([z, states_seen])
        scale = motion_scales(both.min(axis=0), both.max(axis=0), np.abs(both).max(axis=0), n)
        return scale, np.max(np.abs(z - truth) / scale, axis=1)

    # over the whole run: the scales of every node and every true state; over the covered
    # nodes: the true states up to the last covered node only, as the verdict's own scales
    # (a true orbit that moves off after the drift does not shrink the error before it)
    scale, error_all = errors(truth)
    _, error = errors(truth[rows])
    own = np.max(np.abs(states[1] - truth) / scale, axis=1)
    return {"error": float(np.max(error[rows])), "error_all": float(np.max(error_all)),
            "truth_error": float(np.max(own)), "trusted": bool(np.all(np.isfinite(own)))}


def _dense_truth(flow, t, z0, rtol: float, atol: np.ndarray):
    """DOP853 (scipy) from ``z0`` over ``[t_0, t_N]`` at ``rtol``, its dense output at the node
    times ``t``; ``None`` where it cannot be trusted: a failed step, more than
    ``TRUTH_MAX_STEPS`` steps (an orbit that escapes to infinity in finite time makes the
    steps shrink without end), or a state ``TRUTH_ESCAPE`` times the run's own size."""
    from scipy import integrate

    solver = integrate.DOP853(flow, t[0], z0, t[-1], rtol=rtol, atol=atol)
    times, pieces = [t[0]], []
    bound = TRUTH_ESCAPE * float(np.max(atol)) / (rtol * 1e-2)
    for _ in range(TRUTH_MAX_STEPS):
        if solver.status != "running":
            break
        if solver.step() is not None or not np.all(np.isfinite(solver.y)) \
                or float(np.max(np.abs(solver.y))) > bound:
            return None
        times.append(solver.t)
        pieces.append(solver.dense_output())
    if solver.status != "finished":
        return None
    return integrate.OdeSolution(times, pieces)(t).T


def classify(verdict: str, true: float, tol: float) -> str:
    """``false success``, ``false refusal``, ``consistent`` (the verdict agrees with the true
    error outside the band) or ``band`` (module docstring)."""
    if verdict == "accurate":
        if true > MARGIN * tol:
            return "false success"
        return "consistent" if true <= tol else "band"
    if true < tol / MARGIN:
        return "false refusal"
    return "consistent" if true > tol else "band"


def judge_case(case: DrawnCase, **options) -> dict:
    """One case, marched, judged and measured: a row of the study."""
    system, solution = run_case(case, **options)
    verdict = solution.verdict
    tol = verdict.global_tol
    truth = true_error(system, solution, covered=verdict.reference_until)
    trusted = truth["trusted"] and truth["truth_error"] <= tol / 20
    row = {"verdict": verdict.name, "status": solution.status.code,
           "steps": solution.steps, "estimate": verdict.error_max, "true": truth["error"],
           "true_all": truth["error_all"], "truth_error": truth["truth_error"],
           "trusted": trusted, "n": case.system.n, "potential": case.system.potential,
           "scheme": case.scheme, "time_dependent": case.system.time_dependent,
           "t_drift": verdict.t_drift,
           "failure": verdict.first_failure.test if verdict.first_failure else ""}
    # the energy level's test measured against the truth too, in units of the state's
    # tolerance: a refusal for an energy level the truth confirms is not a false one
    level = true_level_error(system, solution, case.scheme)
    row["true_level"] = level
    judged = truth["error_all"] if level is None else \
        max(truth["error_all"], level * tol / verdict.energy_tol)
    row["class"] = classify(verdict.name, judged, tol) if trusted else "untrusted"
    return row


def true_level_error(system, solution, scheme: str) -> float | None:
    """The energy level the first step of an energy rule sets (``verdict.level``) against
    ``H`` of scipy's truth at the level's clock, relative to the verdict's energy scale: the
    check's "energy level of the first step" measured by a reference that shares nothing with
    it but ``H``; ``None`` for fixed steps or a run without a step."""
    from ..solvers import flow_callable

    verdict, t = solution.verdict, solution.t
    if verdict.level is None or not verdict.energy_scale or t.size < 2:
        return None
    clock = float(t[0] + (t[1] - t[0]) / 2) if Scheme.coerce(scheme).clock == "midpoint" \
        else float(t[0])
    theta = system.parameter_vector({})
    z0 = np.concatenate([solution.q[0], solution.p[0]])
    z = z0
    if clock != t[0]:
        size = np.maximum(np.abs(z0), np.max(np.abs(np.hstack([solution.q, solution.p])), 0))
        path = _dense_truth(flow_callable(system, theta), np.array([t[0], clock]), z0,
                            TRUTH_RTOL, TRUTH_RTOL * 1e-2 * np.where(size > 0, size, 1e-300))
        if path is None:
            return None
        z = path[-1]
    n = system.n
    exact = float(system.energy(z[None, :n], z[None, n:], np.array([clock]), theta)[0])
    return abs(verdict.level - exact) / verdict.energy_scale
