"""Initial-value problems: march node by node with a CasADi rootfinder (THEORY.md section 4).

Step 0 is a plain implicit step of length ``tau0``: the ``2n`` canonical equations of interval 0
are solved for ``z_1``. Every later step ``k`` solves ``2n + 1`` equations, the canonical equations
of interval ``k`` and the energy equation at node ``k``, for ``(z_{k+1}, tau_k)``. ``tau0`` thus
fixes the discrete energy level and every later step. With ``rule="fixed"`` every step solves the
canonical equations only, on uniform steps that end on ``t_end``.

A step is accepted only if Newton converged, every value is finite, ``tau_k > 0`` (the
time-reversed root ``(z_{k-1}, -tau_{k-1})`` solves the midpoint step equations for every state),
the step's own unscaled residuals are below ``tol`` (relative to ``max(1, |z|)`` and
``max(1, |H|)``) and the optional step bounds hold. The first step that fails ends the march
with a status; every accepted node is kept.

By default the steps run in compiled chunks (``fast.py``); each step of a chunk goes through the
same checks (``_Marcher._residuals_ok``, ``_bounds_ok``), and the first that fails is redone here,
on the careful path, so both paths accept the same steps.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Mapping

import casadi as ca
import numpy as np

from ..cache import cached
from ..discrete import equations
from ..discrete.runge_kutta import rk4
from ..discrete.scheme import Scheme
from ..errors import InputError
from ..physics.hamiltonian import (
    HamiltonianSystem,
    site_density_weight_function,
    vector_field_function,
)
from ..solution import Solution, Status, bound_reached
from ..validation import check_integer, check_real, check_state

NEWTON_OPTIONS = {"abstol": 1e-14, "abstolStep": 1e-14, "max_iter": 30, "error_on_fail": False}
# Starting guesses for tau, as multiples of the previous step, tried in order when Newton from the
# predictor fails or lands on tau <= 0. The spurious root sits at -tau_{k-1}; these start far
# from it.
RETRY_FACTORS = (1.0, 0.5, 2.0, 0.25)
BREAKDOWNS = ("stop", "least_squares")
LEAST_SQUARES_CASES = (Status.NO_ADMISSIBLE_STEP, Status.NEWTON_FAILED,
                       Status.RESIDUAL_TOO_LARGE, Status.STEP_BELOW_MIN, Status.STEP_ABOVE_MAX,
                       Status.STEP_RATIO)
# The solvability monitor warns once |ln(w_k / w_{k-1})| passes this. Measured on kepler
# (tau0 = 0.01): at most 0.36 per step for e = 0.7 (which runs), 0.6-0.9 in the 3-4 steps before
# the breakdown at e = 0.78 and 0.8; rotating pendulum (p0 = 2): 0.74 two steps before.
MONITOR_LIMIT = 0.5


class _StepFunctions:
    """The CasADi functions of one march step, built once per system and scheme."""

    def __init__(self, system: HamiltonianSystem, scheme: Scheme):
        n = system.n
        theta = system.theta
        canonical = equations.canonical_function(system, scheme)
        field = vector_field_function(system)

        def flow(z, t):
            return field(z, t, theta)

        # Fixed-length step (also step 0 of every rule): unknown z_b; parameters t_a, t_b, z_a.
        t_a, t_b = ca.SX.sym("t_a"), ca.SX.sym("t_b")
        z_a, z_b = ca.SX.sym("z_a", 2 * n), ca.SX.sym("z_b", 2 * n)
        w = ca.vertcat(t_a, t_b, z_a, theta)
        g = canonical(t_a, t_b, z_a[:n], z_a[n:], z_b[:n], z_b[n:], theta)
        self.fixed_residual = ca.Function("g", [z_b, w], [g])
        self.fixed_root = ca.rootfinder("fixed_step", "newton", self.fixed_residual,
                                        NEWTON_OPTIONS)
        self.fixed_predict = ca.Function("predict", [w], [rk4(flow, z_a, t_a, t_b - t_a)])
        # H and the site-density weight w = f' H_zz f = -8 c(z) at a node: the energy guard and
        # the solvability monitor. The step checks return them for the new node too, so neither
        # path pays an extra call.
        weight = site_density_weight_function(system)
        z, t = ca.SX.sym("z", 2 * n), ca.SX.sym("t")
        self.node_monitor = ca.Function(
            "node_monitor", [z, t, theta],
            [system.H_function(z[:n], z[n:], t, theta), weight(z[:n], z[n:], t, theta)])
        self.fixed_check = ca.Function("check", [z_b, w], [
            ca.norm_inf(g), ca.norm_inf(z_a), *self.node_monitor(z_b, t_b, theta)])

        if not scheme.variable_steps:
            return
        # Energy-determined step k >= 1: unknowns (z_next, tau); parameters t_prev, t_mid,
        # z_prev, z_mid.
        energy = equations.energy_function(system, scheme)
        interval_energy = equations.midpoint_energy_function(system, scheme)
        t_prev, t_mid = ca.SX.sym("t_prev"), ca.SX.sym("t_mid")
        z_prev, z_mid, z_next = (ca.SX.sym(s, 2 * n) for s in ("z_prev", "z_mid", "z_next"))
        tau = ca.SX.sym("tau")
        x = ca.vertcat(z_next, tau)
        # drift: the sum of the energy residuals accepted so far. Solving for
        # residual_k = -drift keeps that sum at round-off, so the round-off of single steps
        # (seen biased, about 3e-16 per step on fpu) does not add up to a drift of the energy
        # level; every node still satisfies its own equation to round-off.
        drift = ca.SX.sym("drift")
        w = ca.vertcat(t_prev, t_mid, z_prev, z_mid, theta, drift)
        t_next = t_mid + tau
        g_canonical = canonical(t_mid, t_next, z_mid[:n], z_mid[n:], z_next[:n], z_next[n:], theta)
        g_energy = energy(t_prev, t_mid, t_next, z_prev[:n], z_prev[n:], z_mid[:n], z_mid[n:],
                          z_next[:n], z_next[n:], theta)
        # The energy equation's derivative in tau is O(tau) (THEORY.md section 5); dividing by the
        # previous step makes its Newton tolerance an absolute tolerance on tau.
        g = ca.vertcat(g_canonical, (g_energy + drift) / (t_mid - t_prev))
        self.energy_residual = ca.Function("g", [x, w], [g])
        self.energy_root = ca.rootfinder("energy_step", "newton", self.energy_residual,
                                         NEWTON_OPTIONS)
        guess = ca.SX.sym("tau_guess")
        self.energy_predict = ca.Function(
            "predict", [w, guess], [ca.vertcat(rk4(flow, z_mid, t_mid, guess), guess)])
        H_k = interval_energy(t_mid, t_next, z_mid[:n], z_mid[n:], z_next[:n], z_next[n:], theta)
        self.energy_check = ca.Function(
            "check", [x, w], [ca.norm_inf(g_canonical), g_energy, ca.norm_inf(z_mid),
                              ca.fabs(H_k), *self.node_monitor(z_next, t_next, theta)])


def _step_functions(system: HamiltonianSystem, scheme: Scheme) -> _StepFunctions:
    return cached(system, ("march", scheme), lambda: _StepFunctions(system, scheme))


def march(system: HamiltonianSystem, q0, p0=None, *, v0=None, tau0: float, t_end: float,
          t0: float = 0.0,
          scheme: str | Scheme = "vddvp", params: Mapping[str, float] | None = None,
          tol: float = 1e-10, max_steps: int = 10_000_000, tau_min: float | None = None,
          tau_max: float | None = None, max_step_ratio: float | None = 10.0,
          progress: bool = False, fast: bool = True, chunk: int = 1024,
          compiler: str | None = "auto", cache_dir=None, time_limit: float | None = None,
          energy_guard: float | None = None, breakdown: str = "stop") -> Solution:
    """March ``z_0 = (q0, p0)`` from ``t0`` until the first node at or past ``t_end``.

    Args:
        system: the Hamiltonian or Lagrangian system.
        q0, p0: initial state, each of shape ``(n,)``.
        v0: instead of ``p0``, for a Lagrangian system: the first interval's velocity; the
            march takes ``q_1 = q_0 + tau0 v0`` and ``p_0`` by the discrete Legendre transform.
        tau0: first step; for energy rules it sets the discrete energy level, for ``fixed`` the
            step is ``(t_end - t0) / ceil((t_end - t0) / tau0)``, so the march ends on ``t_end``.
        t_end: end time; energy rules stop at the first node with ``t >= t_end``.
        t0: initial time.
        scheme: ``"vddvp"``, ``"lee"``, ``"fixed"`` or a :class:`Scheme`.
        params: values of the system's parameters (defaults filled in).
        tol: acceptance tolerance of each step's unscaled residuals, relative to ``max(1, |z|)``
            (canonical) and ``max(1, |H|)`` (energy).
        max_steps: bound on the number of steps.
        tau_min, tau_max: optional bounds on every step length.
        max_step_ratio: bound on ``max(tau_k/tau_{k-1}, tau_{k-1}/tau_k)`` (``None``: none).
            The default 10 stops a march whose energy equation jumped to a far root: on
            ``kepler`` with ``e = 0.99`` and ``tau0 = 0.01``, without it, the fourth step was 235
            time units, past the whole horizon, and every equation held.
        progress: show a progress bar on stderr.
        fast: run the steps in compiled chunks (``fast.py``); ``False`` forces the careful
            per-step path. Both accept exactly the same steps.
        chunk: steps per compiled call.
        compiler: C compiler for the fast path: ``"auto"`` (``$CC``, ``gcc``, ``cc``), a
            command, or ``None`` for CasADi's virtual machine.
        cache_dir: folder of compiled chunks (default ``$DDVP_NLP_CACHE`` or
            ``~/.cache/ddvp_nlp``).
        time_limit: optional bound in seconds on the stepping (status ``time_limit``).
        energy_guard: optional bound on ``|H(z_k, t_k) - H(z_0, t_0)| / max(1, |H(z_0, t_0)|)``
            at every node (status ``energy_guard``).
        breakdown: what an energy rule does when a step has no admissible root: ``"stop"``
            (default) or ``"least_squares"``, the step of Kane, Marsden and Ortiz: the ``tau`` in
            ``[tau_min, tau_max]`` (default ``[tau_prev/10, 10 tau_prev]``) that minimises the
            energy residual subject to the canonical equations (a bounded scalar search). Each
            such step is listed in ``stats["least_squares"]`` with its energy defect, and the
            march goes on.

    The solvability monitor (energy rules): at every node the site-density weight
    ``w = f' H_zz f = -8 c(z)`` (THEORY.md section 5). A positive step needs ``c`` to keep its
    sign and the step to be short against the change of ``w``; the march warns (a
    ``RuntimeWarning`` and ``stats["solvability_warning"]``) at the first node where ``w``
    changes sign or ``|ln(w_k / w_{k-1})|`` exceeds ``MONITOR_LIMIT``. ``Solution.solvability``
    holds ``c(z_k)`` at every node.

    Returns:
        A :class:`Solution`; failures are a status on it, never an exception.
    """
    scheme = Scheme.coerce(scheme)
    if not isinstance(system, HamiltonianSystem):
        raise InputError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
    q0 = check_state("q0", q0, system.n)
    if (p0 is None) == (v0 is None):
        raise InputError("give exactly one of p0 and v0")
    if v0 is not None and not system.lagrangian_form:
        raise InputError(f"v0 needs a Lagrangian system; {system.name!r} is Hamiltonian: "
                         "give p0")
    p0 = check_state("p0", p0, system.n) if p0 is not None else None
    v0 = check_state("v0", v0, system.n) if v0 is not None else None
    t0 = check_real("t0", t0)
    t_end = check_real("t_end", t_end)
    if t_end <= t0:
        raise InputError(f"t_end must be > t0 = {t0!r}, got {t_end!r}")
    tau0 = check_real("tau0", tau0, positive=True)
    if tau0 > t_end - t0:
        raise InputError(f"tau0 must not exceed t_end - t0 = {t_end - t0!r}, got {tau0!r}")
    tol = check_real("tol", tol, positive=True)
    max_steps = check_integer("max_steps", max_steps)
    tau_min = check_real("tau_min", tau_min, positive=True, allow_none=True)
    tau_max = check_real("tau_max", tau_max, positive=True, allow_none=True)
    if tau_min is not None and tau_max is not None and tau_min >= tau_max:
        raise InputError(f"tau_min must be < tau_max = {tau_max!r}, got {tau_min!r}")
    if (tau_min is not None and tau0 < tau_min) or (tau_max is not None and tau0 > tau_max):
        raise InputError(f"tau0 must lie in [tau_min, tau_max] = [{tau_min}, {tau_max}], "
                         f"got {tau0!r}")
    max_step_ratio = check_real("max_step_ratio", max_step_ratio, positive=True,
                                 allow_none=True)
    if max_step_ratio is not None and max_step_ratio <= 1:
        raise InputError(f"max_step_ratio must be > 1, got {max_step_ratio!r}")
    chunk = check_integer("chunk", chunk)
    time_limit = check_real("time_limit", time_limit, positive=True, allow_none=True)
    energy_guard = check_real("energy_guard", energy_guard, positive=True, allow_none=True)
    if breakdown not in BREAKDOWNS:
        raise InputError(f"breakdown must be one of {', '.join(BREAKDOWNS)}, got {breakdown!r}")
    if breakdown == "least_squares" and not scheme.variable_steps:
        raise InputError("breakdown='least_squares' needs an energy rule (vddvp or lee), got "
                         f"scheme {scheme.rule!r}")
    if fast:
        from .compiler import find_compiler
        compiler = find_compiler(compiler)
    theta = system.parameter_vector(params)
    if v0 is not None:
        from ..discrete.lagrangian import start_momentum

        p0 = start_momentum(system, scheme, q0, v0, t0=t0, tau0=tau0, theta=theta)
        if not np.all(np.isfinite(p0)):
            raise InputError(f"p0 from v0 = {v0.tolist()} is not finite: {p0.tolist()}")
    H0 = float(system.energy(q0[None, :], p0[None, :], np.array([t0]), theta)[0])
    if not math.isfinite(H0):
        raise InputError(f"H is not finite at the initial state q0={q0.tolist()}, "
                         f"p0={p0.tolist()}, t0={t0!r}: H = {H0!r}")

    started = time.perf_counter()
    functions = _step_functions(system, scheme)
    fast_chunk = None
    if fast:
        from .chunk import FastChunk
        fast_chunk = cached(system,
            ("fast", scheme, chunk, compiler, str(cache_dir)),
            lambda: FastChunk(system, scheme, functions, chunk=chunk, compiler=compiler,
                              cache_dir=cache_dir))
    built = time.perf_counter()
    stepper = _Marcher(system, scheme, functions, theta, tol=tol, tau_min=tau_min,
                       tau_max=tau_max, max_step_ratio=max_step_ratio, fast=fast_chunk,
                       energy_guard=energy_guard, H0=H0, breakdown=breakdown)
    nodes = stepper.run(np.concatenate([q0, p0]), t0=t0, tau0=tau0, t_end=t_end,
                        max_steps=max_steps, progress=progress, time_limit=time_limit)
    solved = time.perf_counter()
    t, z, status, message = nodes
    n = system.n
    canonical, energy = equations.grid_residuals(system, scheme, t, z[:, :n], z[:, n:], theta)
    verified = time.perf_counter()
    return Solution(
        t=t, q=z[:, :n].copy(), p=z[:, n:].copy(), status=status, message=message,
        scheme=scheme.rule, energy_residual=energy,
        canonical_residual=np.max(np.abs(canonical), axis=1) if canonical.size else np.zeros(0),
        newton_iterations=stepper.newton_iterations,
        timing={"build_s": built - started, "solve_s": solved - built,
                "compile_s": fast_chunk.compile_s if fast_chunk else 0.0,
                "verify_s": verified - solved},
        solvability=stepper.solvability(t.size),
        stats={"retries": stepper.retries, "theta": theta.tolist(),
               "path": fast_chunk.path if fast_chunk else "careful",
               "fast_steps": stepper.fast_steps, "careful_steps": stepper.careful_steps,
               "solvability_warning": stepper.warning, "least_squares": stepper.least_squares})


class _Marcher:
    """The step loop: state, acceptance checks and the grown node arrays."""

    def __init__(self, system, scheme, functions, theta, *, tol, tau_min, tau_max,
                 max_step_ratio, fast=None, energy_guard=None, H0=0.0, breakdown="stop"):
        self.system = system
        self.scheme = scheme
        self.functions = functions
        self.theta = theta
        self.tol = tol
        self.tau_min = tau_min
        self.tau_max = tau_max
        self.max_step_ratio = max_step_ratio
        self.newton_iterations = 0
        self.retries = 0
        self.drift = 0.0
        self.fast = fast
        self.fast_steps = 0
        self.careful_steps = 0
        self.energy_guard = energy_guard
        self.H0 = H0
        self.breakdown = breakdown
        self.least_squares = []  # one dict per least-squares step
        self.warning = None  # the first solvability warning
        self._w = []  # site-density weight at every accepted node (energy rules)

    def _solve(self, root, guess, w):
        x = np.asarray(root(guess, w)).ravel()
        stats = root.stats()
        self.newton_iterations += int(stats.get("iter_count", 0))
        # Read return_status: CasADi's "success" flag was seen False on converged calls.
        return x, stats.get("return_status") == "success"

    def _fixed_step(self, t_a, t_b, z_a):
        f = self.functions
        w = np.concatenate([[t_a, t_b], z_a, self.theta])
        z_b, converged = self._solve(f.fixed_root, f.fixed_predict(w), w)
        if not np.all(np.isfinite(z_b)):
            return None, Status.NON_FINITE, f"z = {z_b.tolist()}"
        if not converged:
            return None, Status.NEWTON_FAILED, ""
        residual, size, *monitor = (float(v) for v in f.fixed_check(z_b, w))
        if not self._residuals_ok(residual, size):
            return None, Status.RESIDUAL_TOO_LARGE, f"canonical residual {residual:.3e}"
        self._last_monitor = monitor  # H and w of the new node
        return z_b, Status.SUCCESS, ""

    def _energy_step(self, t_prev, t_mid, z_prev, z_mid, tau_prev):
        f = self.functions
        w = np.concatenate([[t_prev, t_mid], z_prev, z_mid, self.theta, [self.drift]])
        detail = ""
        worst = Status.NEWTON_FAILED
        for attempt, factor in enumerate(RETRY_FACTORS):
            if attempt:
                self.retries += 1
            x, converged = self._solve(f.energy_root, f.energy_predict(w, factor * tau_prev), w)
            if not np.all(np.isfinite(x)):
                worst, detail = Status.NON_FINITE, f"(z, tau) = {x.tolist()}"
                continue
            if not converged:
                continue
            tau = x[-1]
            if tau <= 0:
                if worst is not Status.RESIDUAL_TOO_LARGE:
                    worst, detail = Status.NO_ADMISSIBLE_STEP, f"Newton found tau = {tau:.6g}"
                continue
            canonical, energy, size, H, *monitor = (float(v) for v in f.energy_check(x, w))
            if not self._residuals_ok(canonical, size, energy, H):
                worst, detail = Status.RESIDUAL_TOO_LARGE, (
                    f"canonical residual {canonical:.3e}, energy residual {energy:.3e}")
                continue
            self.drift += energy
            self._last_monitor = monitor
            return x[:-1], tau, Status.SUCCESS, ""
        return None, None, worst, detail

    def _least_squares_step(self, t_prev, t_mid, z_prev, z_mid, tau_prev, status, detail):
        """Kane, Marsden and Ortiz's step: the tau in the bounds that minimises the energy
        residual subject to the canonical equations. ``z_next(tau)`` solves the canonical
        equations (the fixed-step Newton solve); ``|r(tau)|`` is sampled on a log grid over the
        bounds and its best sample refined by Brent's bounded search (scipy). The step is recorded
        with its energy defect; if none is found, the failure it replaces stands."""
        from scipy.optimize import minimize_scalar

        f = self.functions
        low = self.tau_min if self.tau_min is not None else tau_prev / 10
        high = self.tau_max if self.tau_max is not None else 10 * tau_prev
        if self.max_step_ratio is not None:
            low = max(low, tau_prev / self.max_step_ratio)
            high = min(high, tau_prev * self.max_step_ratio)
        w = np.concatenate([[t_prev, t_mid], z_prev, z_mid, self.theta, [self.drift]])
        if not 0 < low < high:
            return None, None, status, (f"{detail}; " if detail else "") + (
                f"least-squares step: empty step range [{low:.3g}, {high:.3g}]")

        def solve(tau):
            z_next, status, _ = self._fixed_step(t_mid, t_mid + tau, z_mid)
            if status is not Status.SUCCESS:
                return None, math.inf
            x = np.concatenate([z_next, [tau]])
            return x, abs(float(np.asarray(f.energy_residual(x, w)).ravel()[-1]))

        grid = np.geomspace(low, high, 16)
        values = [solve(tau)[1] for tau in grid]
        best = int(np.argmin(values))
        if not math.isfinite(values[best]):
            return None, None, status, (f"{detail}; " if detail else "") + (
                f"least-squares step: no step in [{low:.3g}, {high:.3g}] solves the canonical "
                "equations")
        bracket = (grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)])
        refined = minimize_scalar(lambda tau: solve(tau)[1], bounds=bracket, method="bounded",
                                  options={"xatol": 1e-14 * bracket[1]})
        tau = float(refined.x) if refined.fun <= values[best] else float(grid[best])
        x, _ = solve(tau)
        _, energy, _, _, *self._last_monitor = (float(v) for v in f.energy_check(x, w))
        # The defect stays out of the compensated sum: the shifted level is the new one. (Aiming
        # the next steps back at the old level was tried: on the rotating pendulum the nodal H
        # then sat on the wrong side of the level and the steps shrank to zero.)
        # Step k goes from node k to k + 1; its energy equation, at node k, has the defect.
        self.least_squares.append({"step": len(self._w) - 1, "t": t_mid, "tau": tau,
                                   "energy_defect": energy, "replaced": status.code})
        return x[:-1], tau, Status.SUCCESS, ""

    def _monitor_first_node(self, nodes):
        H, w = self.functions.node_monitor(nodes.z[0], nodes.t[0], self.theta)
        return np.array([float(H)]), np.array([float(w)])

    def _watch(self, nodes, first, H, w):
        """Energy guard and solvability monitor on the nodes accepted from ``first`` on
        (``H``, ``w`` of those nodes). A node beyond the guard is dropped with everything after
        it."""
        status, detail = Status.SUCCESS, ""
        if self.energy_guard is not None:
            limit = self.energy_guard * max(1.0, abs(self.H0))
            over = np.flatnonzero(np.abs(H - self.H0) > limit)
            if over.size:
                i = int(over[0])
                status, detail = Status.ENERGY_GUARD, (
                    f"at t = {nodes.t[first + i]:.10g} |H - H0| = {abs(H[i] - self.H0):.3e} > "
                    f"energy_guard * max(1, |H0|) = {limit:.3e}")
                nodes.count = first + i
                w = w[:i]
        if not self.scheme.variable_steps:
            return status, detail
        if self.warning is not None or not w.size:
            self._w.extend(w.tolist())
            return status, detail
        if w.size == 1 and self._w:  # the careful path's single node: plain floats are cheaper
            last, now = self._w[-1], float(w[0])
            if last * now > 0 and abs(math.log(now / last)) <= MONITOR_LIMIT:
                self._w.append(now)
                return status, detail
        previous = np.concatenate([[self._w[-1] if self._w else w[0]], w[:-1]])
        with np.errstate(divide="ignore", invalid="ignore"):
            jump = np.abs(np.log(np.abs(w) / np.abs(previous)))
        sign = np.sign(w) != np.sign(previous)
        alarm = np.flatnonzero(sign | ~(jump <= MONITOR_LIMIT))
        if alarm.size:
            i = int(alarm[0])
            reason = ("the site-density weight w = -8 c(z) changed sign" if sign[i] else
                      f"|ln(w_k / w_k-1)| = {jump[i]:.3g} > {MONITOR_LIMIT}: the step is long "
                      "against the change of c(z)")
            self.warning = {"step": len(self._w) + i, "t": float(nodes.t[first + i]),
                            "c": float(-w[i] / 8), "reason": reason}
            warnings.warn(f"solvability monitor at step {self.warning['step']}, t = "
                          f"{self.warning['t']:.10g}: {reason}; a breakdown of the energy "
                          "step may follow", RuntimeWarning, stacklevel=4)
        self._w.extend(w.tolist())
        return status, detail

    def solvability(self, count):
        """``c(z_k) = -w_k / 8`` at every kept node (energy rules), else empty."""
        if not self.scheme.variable_steps:
            return np.zeros(0)
        return -np.asarray(self._w[:count], dtype=float) / 8

    def _residuals_ok(self, canonical, size, energy=0.0, H=0.0):
        """The acceptance test on a step's unscaled residuals (arrays or scalars): canonical
        relative to ``max(1, |z|)``, energy relative to ``max(1, |H|)``."""
        return ((canonical <= self.tol * np.maximum(1.0, size))
                & (np.abs(energy) <= self.tol * np.maximum(1.0, H)))

    def _bounds_ok(self, tau, tau_prev):
        """Which steps keep tau_min, tau_max and max_step_ratio (arrays or scalars)."""
        ok = np.ones(np.shape(tau), dtype=bool)
        if self.tau_min is not None:
            ok &= tau >= self.tau_min
        if self.tau_max is not None:
            ok &= tau <= self.tau_max
        if self.max_step_ratio is not None and tau_prev is not None:
            with np.errstate(invalid="ignore", divide="ignore"):
                ok &= np.maximum(tau / tau_prev, tau_prev / tau) <= self.max_step_ratio
        return ok

    def _bounds(self, tau, tau_prev):
        """Status and detail of the first bound a step breaks."""
        if self._bounds_ok(tau, tau_prev):
            return Status.SUCCESS, ""
        if self.tau_min is not None and tau < self.tau_min:
            return Status.STEP_BELOW_MIN, f"tau = {tau:.6g} < tau_min = {self.tau_min:.6g}"
        if self.tau_max is not None and tau > self.tau_max:
            return Status.STEP_ABOVE_MAX, f"tau = {tau:.6g} > tau_max = {self.tau_max:.6g}"
        ratio = max(tau / tau_prev, tau_prev / tau)
        return Status.STEP_RATIO, (f"tau = {tau:.6g} after {tau_prev:.6g} (ratio "
                                   f"{ratio:.4g} > max_step_ratio {self.max_step_ratio})")

    def run(self, z0, *, t0, tau0, t_end, max_steps, progress, time_limit=None):
        from tqdm import tqdm

        started = time.perf_counter()
        nodes = _Nodes(t0, z0)
        self._watch(nodes, 0, *self._monitor_first_node(nodes))
        status, detail = Status.SUCCESS, ""
        fixed = not self.scheme.variable_steps
        steps_total = max(1, math.ceil((t_end - t0) / tau0 - 1e-9)) if fixed else None
        tau_fixed = (t_end - t0) / steps_total if fixed else None
        careful_left = 0  # steps the careful path owes after a fast step failed its checks
        bar = tqdm(total=t_end - t0, disable=not progress, unit="t", leave=False,
                   bar_format="{l_bar}{bar}| t={n:.4g}/{total:.4g} [{elapsed}<{remaining}]")
        reported = t0
        try:
            while True:
                k = nodes.count - 1  # the newest node
                t, z = nodes.t, nodes.z
                if (fixed and k == steps_total) or (not fixed and t[k] >= t_end):
                    break
                reached = bound_reached(k, max_steps, started, time_limit)
                if reached:
                    status, detail = reached
                    break
                if self.fast is not None and careful_left == 0 and (fixed or k >= 1):
                    accepted, failed = self._fast_chunk(
                        nodes, t_end=t_end, max_steps=max_steps, t0=t0, tau_fixed=tau_fixed,
                        steps_total=steps_total)
                    if failed:  # redo from the last good node on the careful path
                        careful_left = self.fast.chunk - accepted
                    if accepted:
                        status, detail = self._watch(nodes, nodes.count - accepted,
                                                     *self._chunk_monitor)
                        if status is not Status.SUCCESS:
                            break
                        if progress:
                            bar.update(min(nodes.t[nodes.count - 1], t_end) - reported)
                            reported = min(nodes.t[nodes.count - 1], t_end)
                        continue
                careful_left = max(careful_left - 1, 0)
                self.careful_steps += 1
                tau_prev = t[k] - t[k - 1] if k else None
                if k == 0 or fixed:
                    t_next = t0 + tau0 if not fixed else (
                        t_end if k + 1 == steps_total else t0 + (k + 1) * tau_fixed)
                    z_next, status, detail = self._fixed_step(t[k], t_next, z[k])
                else:
                    z_next, tau, status, detail = self._energy_step(t[k - 1], t[k], z[k - 1],
                                                                    z[k], tau_prev)
                    if status is Status.SUCCESS:
                        status, detail = self._bounds(tau, tau_prev)
                    if status in LEAST_SQUARES_CASES and self.breakdown == "least_squares":
                        z_next, tau, status, detail = self._least_squares_step(
                            t[k - 1], t[k], z[k - 1], z[k], tau_prev, status, detail)
                    t_next = t[k] + tau if tau is not None else None
                if status is not Status.SUCCESS:
                    break
                nodes.append(t_next, z_next)
                H, w = self._last_monitor
                status, detail = self._watch(nodes, nodes.count - 1, np.array([H]),
                                             np.array([w]))
                if status is not Status.SUCCESS:
                    break
                if progress and nodes.count % 256 == 0:
                    bar.update(min(t_next, t_end) - reported)
                    reported = min(t_next, t_end)
        except KeyboardInterrupt:
            status, detail = Status.INTERRUPTED, ""
        finally:
            bar.close()
        t, z = nodes.t[:nodes.count].copy(), nodes.z[:nodes.count].copy()
        count = nodes.count
        n2 = z.shape[1]
        if status is Status.SUCCESS:
            message = f"{status.value} = {t_end:.6g} in {count - 1} steps"
        else:
            k = count - 1
            message = (f"{status.value}: step {k} from t = {t[k]:.10g}, q = {z[k, :n2 // 2]}, "
                       f"p = {z[k, n2 // 2:]}" + (f"; {detail}" if detail else ""))
        return t, z, status, message

    def _fast_chunk(self, nodes, *, t_end, max_steps, t0, tau_fixed, steps_total):
        """Run one compiled chunk from the newest node; keep its steps up to the first that fails
        a check (or reaches the end). Returns (steps kept, whether a step failed)."""
        k = nodes.count - 1
        t, z = nodes.t, nodes.z
        n2 = z.shape[1]
        if self.scheme.variable_steps:
            state = np.concatenate([[t[k - 1], t[k]], z[k - 1], z[k], [self.drift]])
            states, out = self.fast(state, self.theta)
            t_next, z_next = out[:, 0], out[:, 1:1 + n2]
            canonical, energy, size, H = out[:, 1 + n2], out[:, 2 + n2], out[:, 3 + n2], \
                out[:, 4 + n2]
            t_mid = np.concatenate([[t[k]], t_next[:-1]])
            with np.errstate(invalid="ignore"):  # a diverged step is NaN; it fails the checks
                tau = t_next - t_mid
                tau_prev = np.concatenate([[t[k] - t[k - 1]], tau[:-1]])
                good = (np.all(np.isfinite(out), axis=1) & (tau > 0)
                        & self._residuals_ok(canonical, size, energy, H)
                        & self._bounds_ok(tau, tau_prev))
            ends = np.flatnonzero(t_next >= t_end)
        else:
            parameters = np.concatenate([self.theta, [t0, tau_fixed, t_end, steps_total]])
            states, out = self.fast(np.concatenate([[k], z[k]]), parameters)
            t_next, z_next = out[:, 0], out[:, 1:1 + n2]
            canonical, size = out[:, 1 + n2], out[:, 2 + n2]
            with np.errstate(invalid="ignore"):
                good = np.all(np.isfinite(out), axis=1) & self._residuals_ok(canonical, size)
            ends = np.flatnonzero(k + 1 + np.arange(self.fast.chunk) == steps_total)
        limit = min(self.fast.chunk, max_steps - k)
        if ends.size:
            limit = min(limit, int(ends[0]) + 1)
        bad = np.flatnonzero(~good[:limit])
        kept = int(bad[0]) if bad.size else limit
        self._chunk_monitor = (out[:kept, -2], out[:kept, -1])
        if kept:
            nodes.extend(t_next[:kept], z_next[:kept])
            if self.scheme.variable_steps:
                self.drift = float(states[kept - 1, -1])
            self.fast_steps += kept
        return kept, bool(bad.size)


class _Nodes:
    """The accepted nodes, in arrays that grow by doubling."""

    def __init__(self, t0, z0):
        self.t = np.empty(1024)
        self.z = np.empty((1024, z0.size))
        self.t[0], self.z[0] = t0, z0
        self.count = 1

    def _reserve(self, extra):
        if self.count + extra > self.t.size:
            size = max(2 * self.t.size, self.count + extra)
            self.t = np.resize(self.t, size)
            self.z = np.resize(self.z, (size, self.z.shape[1]))

    def append(self, t, z):
        self._reserve(1)
        self.t[self.count], self.z[self.count] = t, z
        self.count += 1

    def extend(self, t, z):
        self._reserve(t.size)
        self.t[self.count:self.count + t.size] = t
        self.z[self.count:self.count + t.size] = z
        self.count += t.size
