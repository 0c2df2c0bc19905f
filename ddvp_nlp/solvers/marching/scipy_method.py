"""The march as a method of scipy's ``solve_ivp``: ``solve_ivp(fun, t_span, y0, method=DDVP,
hamiltonian=H, tau0=...)``.

`DDVP` is a ``scipy.integrate.OdeSolver`` (the rules of its module,
``scipy.integrate._ivp.base``): scipy's loop asks it for one step at a time
(``_step_impl``) and for the interpolant of the last step (``_dense_output_impl``), and builds
``t_eval``, ``dense_output`` and ``events`` from them itself. The steps are the march's
(``initial_value.py``), not an error controller's:

- **The steps come from** ``H``. ``y0 = (q0, p0)`` stacked (length ``2n``); ``fun`` is taken
  because scipy requires it, checked once at the start against Hamilton's vector field
  ``(H_p, -H_q)`` at ``(t0, y0)`` (``|fun - f|_inf <= FUN_AGREEMENT max(|fun|_inf, |f|_inf)``,
  else a ``ValueError`` naming ``fun`` and ``hamiltonian``), and never called again: no
  Jacobian is used (``njev = nlu = 0``; ``nfev = 1``).
- **The march runs a chunk at a time** and its nodes are handed out one per ``_step_impl``:
  about ``chunk_steps`` steps (default ``CHUNK_STEPS``: a span of ``chunk_steps`` times the
  last chunk's mean step, the first chunk's ``tau0``), the next chunk continued from the last
  two nodes with what the loop carried (``continue_march``, ``resume.py``), so that the nodes
  are one uninterrupted `march`'s bit for bit (the same ``tau0`` and options) and a terminal
  event ends the work within a chunk. What a march measures from its start is measured from
  each chunk's first node: the accuracy check (the trajectory error over the whole span is a
  `march`'s verdict), ``StepControl.time_limit`` and the energy guard's band;
  ``max_steps`` and a failure's sentence count the steps of the whole march. A march that
  cannot be continued runs the whole span at the first step: ``fixed`` steps (their length
  is the span's), a backward span and a target error. The march's last node lies up to one
  step past ``t_bound``, so the last step handed out ends on ``t_bound`` with the state of
  the dense output there (``Solution.at``).
- **Dense output** is ``Solution.at``'s: on each interval the cubic Hermite polynomial through
  the two march nodes with the exact slopes ``f(t_k, z_k)`` (``solution.hermite``).
- **The first step** ``tau0`` (it sets the energy level and so every step of an energy rule):
  given, or with ``rtol``/``atol`` given and no ``tau0`` the march's ``target_error = rtol +
  atol / |y0|_inf`` (scipy's defaults ``1e-3``, ``1e-6`` for the one not given: a bound on the
  error ``atol + rtol |y|`` relative to the start's size, read as the whole trajectory's error,
  ``target.py``), else `derived_tau0`: ``TAU0_FRACTION`` of the flow's time scale at the
  start, ``1 / rho(df/dz)`` (``physics.hamiltonian.flow_time_scale``), at most a
  ``MIN_STEPS``-th of the span. ``rtol``/``atol`` given with ``tau0`` are not used, and a
  ``UserWarning`` says so.
- **A failed march** (its status not a success) hands out its accepted nodes, then fails the
  next step with the march's message: ``solve_ivp`` returns ``success=False`` and that message.
  A march that succeeds but whose check finds it ``drifted`` (a phase error past
  ``global_tol``) is said once as a ``RuntimeWarning`` with its ``t_drift``: the scipy result
  has no verdict, and its success alone would hide it.
- Other keyword options (``first_step``, ``max_step``, ``jac``, ...) have no effect and are
  warned about as scipy's own methods warn (``UserWarning``).
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Callable, Mapping
from dataclasses import replace

import numpy as np
from scipy.integrate import DenseOutput, OdeSolver

from ...discrete.scheme import Scheme
from ...physics.hamiltonian import HamiltonianSystem, flow_time_scale
from ...solution import Solution, hermite
from ...validation import check_integer, check_real
from ..accuracy.judgement import SMALLEST_GLOBAL_TOL
from ..dense import DenseField
from ..options import DEFAULT_TOLERANCE, Compilation, StepControl, Tolerance, coerce
from .initial_value import continue_march, march
from .resume import MarchState

__all__ = ["DDVP", "derived_tau0"]

FUN_AGREEMENT = 1e-8  # fun(t0, y0) against (H_p, -H_q), relative to the larger of the two
TAU0_FRACTION = 1e-2  # the derived first step: this share of the start's time scale
MIN_STEPS = 4  # the derived first step: at most this share of the span
SCIPY_RTOL, SCIPY_ATOL = 1e-3, 1e-6  # scipy's defaults, for the one of rtol/atol not given
# the step count in a failure's sentence (solvers/driver.py, message): a continued chunk counts
# from its first node, the march from its start
STEP_COUNT = re.compile(r"\bstep (\d+) from t = ")
CHUNK_STEPS = 10_000  # steps per chunk of a continued march (about: the chunk is a time span)


class DDVP(OdeSolver):
    """The march of ``hamiltonian`` as a ``solve_ivp`` method: ``solve_ivp(fun, t_span, y0,
    method=DDVP, hamiltonian=H, tau0=...)`` (the module docstring says what differs from
    scipy's own methods).

    Args:
        fun: ``f(t, y)`` as scipy asks for it, checked once against ``(H_p, -H_q)`` at the
            start and not called again.
        t0: the start time (``t_span[0]``).
        y0: ``(q0, p0)`` stacked, length ``2n``.
        t_bound: the end time (``t_span[1]``; below ``t0``: backwards).
        vectorized: whether ``fun`` is vectorized (scipy's meaning).
        hamiltonian: a `HamiltonianSystem`, or a function ``H(q, p, t, **params)`` on CasADi
            symbols (then ``n``, default ``len(y0) / 2``).
        n: the degrees of freedom of a function ``hamiltonian``.
        tau0: the first step (default: from ``rtol``/``atol`` or the start's time scale).
        scheme: ``"vddvp"``, ``"lee"``, ``"fixed"`` (or a `Scheme`), as in `march`.
        params: the system's parameter values.
        steps: as in `march`.
        accuracy: as in `march`.
        compilation: as in `march`.
        chunk_steps: about how many steps each chunk of the march takes.
        **extraneous: ``rtol``, ``atol`` (a target error where ``tau0`` is not given, else
            unused with a warning); any other option is warned about as having no effect.

    Attributes:
        solutions: the march's `Solution` of each chunk so far (verdicts, stats);
            ``solution`` the newest.
    """

    def __init__(self, fun, t0, y0, t_bound, vectorized=False, *, hamiltonian=None, n=None,
                 tau0=None, scheme: str | Scheme = "vddvp",
                 params: Mapping[str, float] | None = None, steps: StepControl | None = None,
                 accuracy: Tolerance | None = DEFAULT_TOLERANCE,
                 compilation: Compilation | None = None, chunk_steps: int = CHUNK_STEPS,
                 **extraneous):
        tolerances = {name: extraneous.pop(name) for name in ("rtol", "atol")
                      if name in extraneous}
        if extraneous:  # as scipy's own methods say it (common.warn_extraneous)
            warnings.warn(f"The following arguments have no effect for a chosen solver: "
                          f"{', '.join(f'`{name}`' for name in extraneous)}.", stacklevel=3)
        super().__init__(fun, t0, y0, t_bound, vectorized)
        self.system = as_system(hamiltonian, n, self.n)
        self.scheme = Scheme.coerce(scheme)
        self.theta = self.system.parameter_vector(params)
        self.params = params
        self.options = {"steps": steps, "accuracy": accuracy, "compilation": compilation}
        self.chunk_steps = check_integer("chunk_steps", chunk_steps, minimum=2)
        field = DenseField.of(self.system, self.theta)
        slope = check_fun(self.fun, field, float(t0), self.y)
        scale = flow_time_scale(self.system, self.y, float(t0), self.theta)
        self.tau0, self.target_error = first_step(tau0, tolerances, self.y, slope,
                                                  float(t_bound) - float(t0), scale)
        self.solutions: list[Solution] = []
        self._verdict_said = False  # a check that was not accurate is said once
        self._field, self._chunk = field, None

    @property
    def solution(self) -> Solution | None:
        """The newest chunk's `Solution` (``None`` before the first step)."""
        return self.solutions[-1] if self.solutions else None

    def _step_impl(self):
        chunk = self._chunk
        if chunk is None or chunk.k + 1 >= chunk.size and chunk.continues:
            self._chunk = chunk = self._next_chunk(chunk)
        k = chunk.k + 1
        if k >= chunk.size:  # every node handed out: the march stopped short of t_bound
            return False, chunk.solution.message
        chunk.k = k
        if k < chunk.inside:  # a node before t_bound, as the march gave it (rows not copied)
            self.t, self.y = chunk.times[k], chunk.z[k]
            return True, None
        q, p = chunk.solution.at_end() if chunk.final else chunk.solution.at(self.t_bound)
        self.t, self.y = self.t_bound, np.concatenate([q, p])
        return True, None

    def _dense_output_impl(self):
        chunk = self._chunk
        k = chunk.k
        return HermiteStep(self.t_old, self.t, chunk.t[k - 1:k + 1], chunk.z[k - 1:k + 1],
                           chunk.slopes[k - 1:k + 1])

    def _next_chunk(self, previous: Chunk | None) -> Chunk:
        """The march from the start (``previous`` is ``None``) or on from the last two nodes of
        ``previous`` with what its loop carried (``continue_march``), to the next chunk's end
        (module docstring)."""
        options = {"scheme": self.scheme, "params": self.params, **self.options}
        size = self.n // 2
        if previous is None:
            end = self._chunk_end(self.t, self.tau0)
            solution = march(self.system, self.y[:size], self.y[size:], (self.t, end),
                             tau0=self.tau0, target_error=self.target_error, **options)
            first = base = 0
        else:
            last, base = previous.solution, previous.base + previous.t.size - 2
            mean_step = (last.t[-1] - last.t[0]) / (last.t.size - 1)
            end = self._chunk_end(float(last.t[-1]), mean_step)
            state = MarchState.of(last.t[-2:], last.q[-2:], last.p[-2:], float(last.t[-1]),
                                  last.march.carried)
            asked = coerce(options.pop("steps"), StepControl, "steps")
            # max_steps counts the march's steps: this chunk's node j is the march's base + j
            steps = replace(asked, max_steps=max(asked.max_steps - base, 1))
            solution = continue_march(self.system, state, end, tau0=last_step(last.t),
                                      steps=steps, **options)
            solution.message = STEP_COUNT.sub(
                lambda found: f"step {int(found[1]) + base} from t = ", solution.message, 1
            ).replace(f"max_steps = {steps.max_steps}", f"max_steps = {asked.max_steps}")
            first = 1  # its first two nodes are the earlier chunk's last two
        self.solutions.append(solution)
        self._say_verdict(solution, previous is None)
        return Chunk.of(solution, self._field, final=end == self.t_bound, k=first, base=base,
                        t_bound=self.t_bound, direction=self.direction)

    def _say_verdict(self, solution, first: bool) -> None:
        """A chunk whose accuracy check did not find it ``accurate`` is said once, as a
        ``RuntimeWarning``: ``solve_ivp``'s result has no verdict, and its success would
        otherwise hide a trajectory that drifted (a failed check of an ``inaccurate`` march is
        already its failure)."""
        verdict = solution.verdict
        if self._verdict_said or verdict is None or verdict.accurate or not solution.success:
            return
        self._verdict_said = True
        where = "" if verdict.t_drift is None else f" from t = {verdict.t_drift:.6g}"
        judged = "" if first else (f", judged from the chunk that starts at t = "
                                   f"{solution.t[0]:.6g}")
        warnings.warn(f"DDVP: the accuracy check finds the trajectory {verdict.name}{where}"
                      f"{judged}: its error passes global_tol = {verdict.global_tol:g} of the "
                      "motion's size there (a phase error: every step follows the flow); "
                      "a smaller tau0 keeps it accurate longer, and march(...) gives the whole "
                      "run's verdict", RuntimeWarning, stacklevel=2)

    def _chunk_end(self, t: float, step: float) -> float:
        """``t_bound`` for a march that cannot be continued (``fixed`` steps, a backward span,
        a target error), or when less than half a chunk of ``step``s would be left after the
        next one; else ``chunk_steps`` steps of ``step`` on from ``t``."""
        chunked = self.scheme.variable_steps and self.direction > 0 and \
            self.target_error is None
        end = t + self.chunk_steps * step
        if not chunked or end + self.chunk_steps * step / 2 >= self.t_bound:
            return self.t_bound
        return end


class Chunk:
    """The nodes of one chunk's march (``t``, ``z = (q, p)``, the exact slopes ``slopes``), its
    `Solution`, whether it marched to ``t_bound`` (``final``) and the node handed out last
    (``k``); its node ``j`` is the march's node ``base + j``. The nodes from ``inside`` on are
    handed out as the state at ``t_bound`` (the first at or past it, and a final march's last
    node, which ``fixed`` steps put on ``t_bound`` up to round-off)."""

    def __init__(self, solution: Solution, z, slopes, *, final: bool, k: int, base: int,
                 t_bound: float, direction: float):
        self.solution, self.t, self.z, self.slopes = solution, solution.t, z, slopes
        self.final, self.k, self.base = final, k, base
        self.size = int(self.t.size)
        self.times = self.t.tolist()  # Python floats: scipy's loop reads one per step
        past = np.flatnonzero(direction * (self.t - t_bound) >= 0)
        self.inside = int(past[0]) if past.size else self.size
        if final and solution.success:
            self.inside = min(self.inside, self.size - 1)

    @classmethod
    def of(cls, solution: Solution, field, **where) -> Chunk:
        z = np.hstack([solution.q, solution.p])
        return cls(solution, z, field(solution.t, z), **where)

    @property
    def continues(self) -> bool:
        """Whether a next chunk follows this one (it succeeded short of ``t_bound``)."""
        return self.solution.success and not self.final


class HermiteStep(DenseOutput):
    """The dense output of one step: the cubic Hermite polynomial through the march's nodes
    ``t`` (2,), ``z`` (2, 2n) with the exact slopes ``slopes`` (``Solution.at``'s), on
    ``[t_old, t]`` (the last step ends on ``t_bound``, inside its march interval)."""

    def __init__(self, t_old, t, nodes_t, nodes_z, slopes):
        super().__init__(t_old, t)
        self.nodes_t, self.nodes_z, self.slopes = nodes_t, nodes_z, slopes

    def _call_impl(self, t):
        times = np.atleast_1d(np.asarray(t, float))
        values = hermite(self.nodes_t, self.nodes_z, self.slopes, times).T
        return values[:, 0] if np.ndim(t) == 0 else values


def last_step(t: np.ndarray) -> float:
    """The last step ``t[-1] - t[-2]`` as the ``tau0`` that makes it from ``t[-2]`` (what
    ``continue_march`` checks): the difference, or a neighbouring float where adding it back
    rounds differently (nodes on either side of ``t = 0``)."""
    step = float(t[-1] - t[-2])
    for candidate in (step, np.nextafter(step, np.inf), np.nextafter(step, -np.inf)):
        if t[-2] + candidate == t[-1]:
            return float(candidate)
    return step


def as_system(hamiltonian, n, size: int) -> HamiltonianSystem:
    """``hamiltonian`` as a `HamiltonianSystem` whose ``2n`` is ``size = len(y0)``."""
    if hamiltonian is None:
        raise ValueError("method=DDVP needs hamiltonian= (a HamiltonianSystem, or a function "
                         "H(q, p, t) with n): the steps come from H, not from fun")
    if isinstance(hamiltonian, HamiltonianSystem):
        system = hamiltonian
        if n is not None and check_integer("n", n) != system.n:
            raise ValueError(f"n = {n!r} differs from the hamiltonian's n = {system.n}")
    elif callable(hamiltonian):
        if n is None and size % 2:
            raise ValueError(f"y0 must be (q, p) stacked, of even length 2n, got length {size}")
        system = HamiltonianSystem(hamiltonian, size // 2 if n is None else n, name="solve_ivp")
    else:
        raise ValueError(f"hamiltonian must be a HamiltonianSystem or a function H(q, p, t), "
                         f"got {type(hamiltonian).__name__}")
    if size != 2 * system.n:
        raise ValueError(f"y0 must be (q, p) stacked, of length 2n = {2 * system.n}, got "
                         f"length {size}")
    return system


def check_fun(fun: Callable, field, t0: float, y0: np.ndarray) -> np.ndarray:
    """``f(t0, y0) = (H_p, -H_q)``, once ``fun(t0, y0)`` was found to agree with it (module
    docstring); a ``ValueError`` naming both where not."""
    slope = field(t0, y0)[0]
    given = np.asarray(fun(t0, y0), float)
    if given.shape != slope.shape:
        raise ValueError(f"fun(t0, y0) must have the shape of y0, {slope.shape}, got "
                         f"{given.shape}")
    scale = max(float(np.max(np.abs(slope))), float(np.max(np.abs(given))))
    gap = float(np.max(np.abs(given - slope)))
    if not gap <= FUN_AGREEMENT * scale:  # a NaN fails too
        raise ValueError(f"fun and hamiltonian disagree at (t0, y0): fun(t0, y0) = "
                         f"{given.tolist()}, Hamilton's (H_p, -H_q) = {slope.tolist()} "
                         f"(|difference| = {gap:.3g} > {FUN_AGREEMENT:g} x {scale:.3g}); "
                         f"DDVP steps by the hamiltonian, so fun must be its vector field")
    return slope


def first_step(tau0, tolerances: dict, y0: np.ndarray, slope: np.ndarray,
               span: float, time_scale: float = math.inf) -> tuple[float, float | None]:
    """``(tau0, target_error)`` from the arguments (module docstring)."""
    if tau0 is not None:
        tau0 = check_real("tau0", tau0, positive=True)
        if tolerances:
            warnings.warn(f"{' and '.join(tolerances)} not used by DDVP: tau0 = {tau0!r} "
                          f"sets every step through the energy level (give rtol/atol without "
                          f"tau0 to have the march aim at an error)", stacklevel=4)
        return tau0, None
    tau0 = derived_tau0(y0, slope, span, time_scale)
    if not tolerances:
        return tau0, None
    rtol = check_real("rtol", tolerances.get("rtol", SCIPY_RTOL), positive=True)
    atol = check_real("atol", tolerances.get("atol", SCIPY_ATOL), positive=True)
    target = rtol + atol / float(np.max(np.abs(y0)))
    if not SMALLEST_GLOBAL_TOL <= target < 1:
        raise ValueError(f"rtol = {rtol!r}, atol = {atol!r} ask for a trajectory error "
                         f"rtol + atol / |y0| = {target:.3g} relative to the motion's size, "
                         f"outside [{SMALLEST_GLOBAL_TOL:g}, 1) that the march can aim at")
    return tau0, target


def derived_tau0(y0: np.ndarray, slope: np.ndarray, span: float,
                 time_scale: float = math.inf) -> float:
    """``TAU0_FRACTION`` of the start's time scale, at most ``|span| / MIN_STEPS``: the flow's
    own, ``1 / rho(df/dz)`` (``time_scale``; it follows the units of time whatever those of
    the coordinates, and no offset of the origin moves it), or where that is infinite (a flow
    with no rate at the start) ``|y0|_inf / |f(t0, y0)|_inf``; a ``ValueError`` asking for
    ``tau0`` where neither gives one. With ``|y0| / |f|`` alone a swing in time units of
    ``1e5``, or offset by ``1e4``, took 5 steps for 20 of its periods, and in lengths of
    ``1e6`` and time units of ``1e-3`` 2 million."""
    if math.isfinite(time_scale) and time_scale > 0:
        return min(TAU0_FRACTION * time_scale, abs(span) / MIN_STEPS)
    size, speed = float(np.max(np.abs(y0))), float(np.max(np.abs(slope)))
    if size == 0 or speed == 0 or not math.isfinite(size / speed):
        raise ValueError(f"tau0 cannot be derived from the start (|y0| = {size:g}, |f(t0, y0)| "
                         f"= {speed:g}: no time scale): give tau0")
    return min(TAU0_FRACTION * size / speed, abs(span) / MIN_STEPS)
