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
- **The march runs the whole span at the first step** and its nodes are handed out one per
  ``_step_impl``: the cost of the march is paid by the first step (a terminal event does not
  save it). The nodes are `march`'s bit for bit (the same ``tau0`` and options); the march's
  last node lies up to one step past ``t_bound``, so the last step handed out ends on
  ``t_bound`` with the state of the dense output there (``Solution.at_end``).
- **Dense output** is ``Solution.at``'s: on each interval the cubic Hermite polynomial through
  the two march nodes with the exact slopes ``f(t_k, z_k)`` (``solution.hermite``).
- **The first step** ``tau0`` (it sets the energy level and so every step of an energy rule):
  given, or with ``rtol``/``atol`` given and no ``tau0`` the march's ``target_error = rtol +
  atol / |y0|_inf`` (scipy's defaults ``1e-3``, ``1e-6`` for the one not given: a bound on the
  error ``atol + rtol |y|`` relative to the start's size, read as the whole trajectory's error,
  ``target.py``), else `derived_tau0`: ``TAU0_FRACTION |y0|_inf / |f(t0, y0)|_inf``, at most a
  ``MIN_STEPS``-th of the span. ``rtol``/``atol`` given with ``tau0`` are not used, and a
  ``UserWarning`` says so.
- **A failed march** (its status not a success) hands out its accepted nodes, then fails the
  next step with the march's message: ``solve_ivp`` returns ``success=False`` and that message.
- Other keyword options (``first_step``, ``max_step``, ``jac``, ...) have no effect and are
  warned about as scipy's own methods warn (``UserWarning``).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping

import numpy as np
from scipy.integrate import DenseOutput, OdeSolver

from ...discrete.scheme import Scheme
from ...physics.hamiltonian import HamiltonianSystem
from ...solution import Solution, hermite
from ...validation import check_integer, check_real
from ..accuracy.judgement import SMALLEST_GLOBAL_TOL
from ..dense import DenseField
from ..options import DEFAULT_TOLERANCE, Compilation, StepControl, Tolerance
from .initial_value import march

__all__ = ["DDVP", "derived_tau0"]

FUN_AGREEMENT = 1e-8  # fun(t0, y0) against (H_p, -H_q), relative to the larger of the two
TAU0_FRACTION = 1e-2  # the derived first step: this share of the start's time scale |y| / |f|
MIN_STEPS = 4  # the derived first step: at most this share of the span
SCIPY_RTOL, SCIPY_ATOL = 1e-3, 1e-6  # scipy's defaults, for the one of rtol/atol not given


class DDVP(OdeSolver):
    """The march of ``hamiltonian`` as a ``solve_ivp`` method (module docstring).

    Args (beside scipy's ``fun, t0, y0, t_bound, vectorized``, passed by ``solve_ivp``):
        hamiltonian: a `HamiltonianSystem`, or a function ``H(q, p, t, **params)`` on CasADi
            symbols (then ``n``, default ``len(y0) / 2``).
        n: the degrees of freedom of a function ``hamiltonian``.
        tau0: the first step (module docstring for its default).
        scheme: ``"vddvp"``, ``"lee"``, ``"fixed"`` (or a `Scheme`), as in `march`.
        params: the system's parameter values.
        steps, accuracy, compilation: as in `march`.
        rtol, atol: mapped to ``target_error`` where ``tau0`` is not given (module docstring).

    Attributes:
        solution: the march's `Solution` once the first step was taken (its verdict, stats).
    """

    def __init__(self, fun, t0, y0, t_bound, vectorized=False, *, hamiltonian=None, n=None,
                 tau0=None, scheme: str | Scheme = "vddvp",
                 params: Mapping[str, float] | None = None, steps: StepControl | None = None,
                 accuracy: Tolerance | None = DEFAULT_TOLERANCE,
                 compilation: Compilation | None = None, **extraneous):
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
        field = DenseField.of(self.system, self.theta)
        slope = check_fun(self.fun, field, float(t0), self.y)
        self.tau0, self.target_error = first_step(tau0, tolerances, self.y, slope,
                                                  float(t_bound) - float(t0))
        self.solution: Solution | None = None
        self._field, self._nodes, self._next = field, None, 0

    def _step_impl(self):
        if self._nodes is None:
            self._nodes = self._march()
        t, z = self._nodes["t"], self._nodes["z"]
        if self._next + 1 >= t.size:  # every node handed out: the march stopped short
            return False, self.solution.message
        k = self._next
        self._next += 1
        self.t, self.y = float(t[k + 1]), z[k + 1].copy()
        return True, None

    def _dense_output_impl(self):
        k, nodes = self._next - 1, self._nodes
        return HermiteStep(self.t_old, self.t, nodes["march_t"][k:k + 2],
                           nodes["march_z"][k:k + 2], nodes["slopes"][k:k + 2])

    def _march(self) -> dict:
        """The march over the whole span (module docstring) and the nodes handed out."""
        size = self.n // 2
        self.solution = solution = march(
            self.system, self.y[:size], self.y[size:], (self.t, self.t_bound), tau0=self.tau0,
            scheme=self.scheme, params=self.params, target_error=self.target_error,
            **self.options)
        return handed_out(solution, self.t_bound, self._field)


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


def handed_out(solution: Solution, t_bound: float, field) -> dict:
    """The march's nodes ``march_t``, ``march_z`` with their exact slopes, and the nodes handed
    out (``t``, ``z``): a march that reached ``t_end`` (its last node at or up to one step past
    it; ``fixed`` steps: on it up to round-off) hands out every node but its last and then
    ``t_bound`` with the dense output's state there (``Solution.at_end``); a failed one every
    node it accepted."""
    march_t = solution.t
    march_z = np.hstack([solution.q, solution.p])
    t, z = march_t, march_z
    if solution.success:
        q, p = solution.at_end()
        t = np.append(march_t[:-1], t_bound)
        z = np.vstack([march_z[:-1], np.concatenate([q, p])[None, :]])
    return {"t": t, "z": z, "march_t": march_t, "march_z": march_z,
            "slopes": field(march_t, march_z)}


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
               span: float) -> tuple[float, float | None]:
    """``(tau0, target_error)`` from the arguments (module docstring)."""
    if tau0 is not None:
        tau0 = check_real("tau0", tau0, positive=True)
        if tolerances:
            warnings.warn(f"{' and '.join(tolerances)} not used by DDVP: tau0 = {tau0!r} "
                          f"sets every step through the energy level (give rtol/atol without "
                          f"tau0 to have the march aim at an error)", stacklevel=4)
        return tau0, None
    tau0 = derived_tau0(y0, slope, span)
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


def derived_tau0(y0: np.ndarray, slope: np.ndarray, span: float) -> float:
    """``TAU0_FRACTION |y0|_inf / |f(t0, y0)|_inf`` (the start's time scale), at most
    ``|span| / MIN_STEPS``; a ``ValueError`` asking for ``tau0`` where the start is at rest or
    at the origin."""
    size, speed = float(np.max(np.abs(y0))), float(np.max(np.abs(slope)))
    if size == 0 or speed == 0 or not math.isfinite(size / speed):
        raise ValueError(f"tau0 cannot be derived from the start (|y0| = {size:g}, |f(t0, y0)| "
                         f"= {speed:g}: no time scale): give tau0")
    return min(TAU0_FRACTION * size / speed, abs(span) / MIN_STEPS)
