"""Fixed-endpoint problems: the whole discrete action as one NLP (THEORY.md sections 2, 4, 5).

Given ``q(t_0)``, ``q(t_end)``, ``t_0``, ``t_end`` and ``N`` nodes, the unknowns are the interior
``q``, all ``p`` and (energy rules) the interior node times; the equations are the canonical
equations of every interval (``2n(N-1)``) and the energy equation of every interior node
(``N-2``): a square system. The node times stay variables (a cumulative sum of steps would make
the Jacobian dense), and every step is bounded below by ``tau_floor > 0``, which excludes the
time-reversed root. IPOPT (MUMPS) solves it by default; ``solver="newton"`` solves the same square
system with CasADi's Newton rootfinder (sparse QR, no line search), without the step bounds: the
verification below then rejects any step ``<= 0``.

Default start, for grids of any length (THEORY.md section 4's count of equations is square, but
its Jacobian's condition number grows like N^2, so the start must be close):

1. the ``fixed`` problem on uniform times, from uniform motion between the endpoints;
2. the ``fixed`` problem on times with the predicted site density
   ``tau ~ (f' H_zz f)^(-1/3)``, ``f`` the Hamiltonian vector field (the paper's section 4 for
   ``H = p^2/2 + V``: ``f' H_zz f = V'' p^2 + V'^2``; the expansion ``H(z_mid) = H(z) -
   tau^2 f' H_zz f / 8`` gives the same weight for any ``H``);
3. the scheme's equations with the times released.

Released directly from uniform times, Newton diverged at N = 1e5 on the pendulum; from the
predicted times it took 3-4 iterations at N = 1e3, 1e4 and 1e5 (measured).

The discrete action ``S_D = sum_k [P_k . (q_{k+1} - q_k) - tau_k H_k]`` (for a Lagrangian system
``sum_k tau_k L_k``, whose Euler-Lagrange equations enter as each interval's discrete Legendre
transform; ``lagrangian.py``) is assembled over the grid and reported; the ``lee`` energy
equations are its gradient in the interior node times (computed per node by automatic
differentiation in ``equations.py``).

Every returned point is verified by its own unscaled residuals (IPOPT's default ``constr_viol_tol``
once accepted node times off by 3e-2): success means the solver converged, the largest canonical
residual (increment form) is below ``tol`` and the largest energy residual below
``tol * (t_end - t_0)/(N-1)`` (the energy equation's derivative in a node time is ``O(tau)``, so
this makes ``tol`` a tolerance on node times whatever ``N``), and every step is positive.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..cache import PROBLEMS, cached
from ..discrete import equations
from ..discrete.scheme import Scheme
from ..errors import InputError
from ..physics.hamiltonian import HamiltonianSystem, site_density_weight_function
from ..solution import Solution, Status
from ..validation import check_finite_array, check_integer, check_real, check_state

SOLVERS = ("ipopt", "newton")

@dataclass
class _Layout:
    """Where each node value sits in the NLP's flat vector: interior ``q`` (n, N-2) column by
    column, then ``p`` (n, N), then (energy rules) the interior times (N-2)."""

    n: int
    nodes: int
    free_times: bool

    @property
    def size(self) -> int:
        n, N = self.n, self.nodes
        return n * (N - 2) + n * N + (N - 2 if self.free_times else 0)

    def split(self, x):
        """``(q_interior, p, t_interior)`` as (n, N-2), (n, N), (1, N-2) blocks of ``x``."""
        n, N = self.n, self.nodes
        a, b = n * (N - 2), n * (N - 2) + n * N
        q = ca.reshape(x[:a], n, N - 2)
        p = ca.reshape(x[a:b], n, N)
        t = ca.reshape(x[b:], 1, N - 2) if self.free_times else None
        return q, p, t

    def pack(self, t, q, p) -> np.ndarray:
        """Flat vector from node arrays ``t`` (N,), ``q``, ``p`` (N, n)."""
        parts = [q[1:-1].ravel(), p.ravel()]
        if self.free_times:
            parts.append(t[1:-1])
        return np.concatenate(parts)

    def unpack(self, x, t_fixed, q_start, q_end):
        """Node arrays ``t`` (N,), ``q``, ``p`` (N, n) from a flat vector."""
        n, N = self.n, self.nodes
        x = np.asarray(x, float).ravel()
        a, b = n * (N - 2), n * (N - 2) + n * N
        q = np.vstack([q_start, x[:a].reshape(N - 2, n), q_end])
        p = x[a:b].reshape(N, n)
        t = np.concatenate([[t_fixed[0]], x[b:], [t_fixed[-1]]]) if self.free_times \
            else np.asarray(t_fixed, float)
        return t, q, p


def _grid_equations(system, scheme, layout, x, q_start, q_end, times, theta, energy_scale):
    """Equality constraints (canonical of every interval, then scaled energy of every interior
    node), the assembled action and the row of node times, as MX expressions of ``x``.
    ``times`` is ``(t_0, t_end)`` for energy rules and all N node times for ``fixed``."""
    N = layout.nodes
    q_int, p, t_int = layout.split(x)
    q = ca.horzcat(q_start, q_int, q_end)
    t = ca.horzcat(times[0], t_int, times[1]) if layout.free_times else ca.reshape(times, 1, N)
    canonical = equations.canonical_function(system, scheme).map(N - 1)
    g = [ca.vec(canonical(t[:, :-1], t[:, 1:], q[:, :-1], p[:, :-1], q[:, 1:], p[:, 1:],
                          theta))]
    if scheme.variable_steps:
        energy = equations.energy_function(system, scheme).map(N - 2)
        g.append(ca.vec(energy(t[:, :-2], t[:, 1:-1], t[:, 2:], q[:, :-2], p[:, :-2],
                               q[:, 1:-1], p[:, 1:-1], q[:, 2:], p[:, 2:], theta))
                 / energy_scale)
    action = _action_function(system, scheme).map(N - 1)
    S = ca.sum2(action(t[:, :-1], t[:, 1:], q[:, :-1], p[:, :-1], q[:, 1:], p[:, 1:], theta))
    return ca.vertcat(*g), S, t


def _action_function(system, scheme):
    def build():
        t_a, t_b = ca.SX.sym("t_a"), ca.SX.sym("t_b")
        q_a, p_a, q_b, p_b = (ca.SX.sym(s, system.n) for s in ("q_a", "p_a", "q_b", "p_b"))
        S = equations.interval_action_expression(system, scheme, t_a, t_b, q_a, p_a, q_b, p_b,
                                                 system.theta)
        return ca.Function("action", [t_a, t_b, q_a, p_a, q_b, p_b, system.theta], [S])
    return cached(system, ("action", scheme), build)


def _straight_line_guess(q_start, q_end, times):
    """Uniform motion between the endpoints: ``q`` linear in ``t``, ``p`` its slope."""
    s = (times - times[0]) / (times[-1] - times[0])
    q = q_start[None, :] + s[:, None] * (q_end - q_start)[None, :]
    p = np.repeat(((q_end - q_start) / (times[-1] - times[0]))[None, :], times.size, axis=0)
    return q, p


class _Problem:
    """One assembled NLP (IPOPT) or square system (Newton) for a system, scheme and grid size."""

    def __init__(self, system, scheme, nodes, solver, verbose, max_iter, tol):
        self.layout = _Layout(system.n, nodes, scheme.variable_steps)
        n = system.n
        x = ca.MX.sym("x", self.layout.size)
        q_start, q_end = ca.MX.sym("q_start", n), ca.MX.sym("q_end", n)
        times = ca.MX.sym("times", 2 if scheme.variable_steps else nodes)
        theta = ca.MX.sym("theta", system.theta.numel())
        scale = ca.MX.sym("energy_scale")
        par = ca.vertcat(q_start, q_end, times, theta, scale)
        g, S, t = _grid_equations(system, scheme, self.layout, x, q_start, q_end, times, theta,
                                  scale)
        self.equations = g.numel()
        self.action = ca.Function("action", [x, par], [S])
        self.solver_name = solver
        steps = ca.vec(t[:, 1:] - t[:, :-1]) if scheme.variable_steps else ca.MX(0, 1)
        self.steps = steps.numel()
        if solver == "newton":
            # CasADi's Newton line search (on by default) took 136 iterations where plain
            # Newton took 5 (N = 1000, measured).
            self.solver = ca.rootfinder(
                "bvp", "newton", ca.Function("g", [x, par], [g]).expand(),
                {"linear_solver": "qr", "line_search": False, "abstol": tol * 1e-2,
                 "abstolStep": 1e-15, "max_iter": max_iter, "error_on_fail": False})
            return
        options = {"print_time": verbose, "ipopt.print_level": 5 if verbose else 0,
                   "ipopt.sb": "yes", "ipopt.linear_solver": "mumps", "ipopt.max_iter": max_iter,
                   # SX evaluation of the mapped equations: about 20x faster per call than MX.
                   "expand": True,
                   "ipopt.tol": tol * 1e-2, "ipopt.constr_viol_tol": tol * 1e-2,
                   # The start is close (module docstring) and the step bounds are inactive at
                   # the solution: start the barrier small and the bound multipliers from it.
                   # IPOPT's defaults (mu 0.1, multipliers 1) pushed the iterate away first:
                   # 7-13 iterations instead of 2-3 at N = 1e4 (measured).
                   "ipopt.mu_init": 1e-9, "ipopt.bound_push": 1e-12, "ipopt.bound_frac": 1e-12,
                   "ipopt.bound_mult_init_method": "mu-based"}
        self.solver = ca.nlpsol("bvp", "ipopt",
                                {"x": x, "p": par, "f": 0, "g": ca.vertcat(g, steps)}, options)

    def solve(self, x0, par, tau_floor):
        if self.solver_name == "newton":
            x = np.asarray(self.solver(x0, par)).ravel()
            stats = self.solver.stats()
            return x, {"return_status": stats.get("return_status"),
                       "converged": stats.get("return_status") == "success",
                       "iterations": int(stats.get("iter_count", 0))}
        result = self.solver(x0=x0, p=par,
                             lbg=np.concatenate([np.zeros(self.equations),
                                                 np.full(self.steps, tau_floor)]),
                             ubg=np.concatenate([np.zeros(self.equations),
                                                 np.full(self.steps, np.inf)]))
        stats = self.solver.stats()
        return np.asarray(result["x"]).ravel(), {
            "return_status": stats.get("return_status"), "converged": bool(stats.get("success")),
            "iterations": int(stats.get("iter_count", 0))}


def predicted_times(system: HamiltonianSystem, t, q, p, theta) -> np.ndarray:
    """Node times with the site density of the energy rules, ``tau_k ~ w^(-1/3)`` evaluated at
    the interval midpoints of the grid ``t``, ``q``, ``p``; same first and last time."""
    N = t.size
    w = np.asarray(site_density_weight_function(system).map(N - 1)(
        ((q[:-1] + q[1:]) / 2).T, ((p[:-1] + p[1:]) / 2).T, ((t[:-1] + t[1:]) / 2)[None, :],
        np.asarray(theta, float)[:, None])).ravel()
    # Where w <= 0 the energy rules have no positive step anyway (THEORY.md section 5); keep the
    # prediction finite there and let the solve report it.
    floor = 1e-3 * np.median(np.abs(w)) if np.any(w != 0) else 1.0
    tau = np.maximum(w, floor) ** (-1 / 3)
    tau *= (t[-1] - t[0]) / tau.sum()
    times = t[0] + np.concatenate([[0.0], np.cumsum(tau)])
    times[-1] = t[-1]
    return times


def _problem(system, scheme, nodes, solver, verbose, max_iter, tol):
    key = ("bvp", scheme, nodes, solver, verbose, max_iter, tol)
    return PROBLEMS.get(system, key, lambda: _Problem(system, scheme, nodes, solver, verbose,
                                                      max_iter, tol))


def solve_bvp(system: HamiltonianSystem, q_start, q_end, t_span, *, nodes: int,
              scheme: str | Scheme = "vddvp", params: Mapping[str, float] | None = None,
              guess: Solution | Mapping | None = None, times=None, tol: float = 1e-9,
              tau_floor: float | None = None, solver: str = "ipopt", max_iter: int = 200,
              verbose: bool = False) -> Solution:
    """Solve the fixed-endpoint problem ``q(t_0) = q_start``, ``q(t_end) = q_end`` on ``nodes``.

    Args:
        system: the Hamiltonian system.
        q_start, q_end: fixed positions at the two ends, each of shape ``(n,)``.
        t_span: ``(t_0, t_end)``.
        nodes: number of nodes ``N >= 3``.
        scheme: ``"vddvp"``, ``"lee"``, ``"fixed"`` or a :class:`Scheme`.
        params: the system's parameter values.
        guess: a starting point: a :class:`Solution` (for example a march) or a mapping with
            ``t``, ``q``, ``p`` arrays of ``nodes`` rows. Default: the three phases of the
            module docstring.
        times: node times of the ``fixed`` rule (default uniform); ignored by energy rules.
        tol: verification tolerance (module docstring).
        tau_floor: smallest allowed step (default ``1e-3 (t_end - t_0)/(N-1)``).
        solver: ``"ipopt"`` (default) or ``"newton"``.
        max_iter: iteration limit of the solver.
        verbose: show IPOPT's output.

    Returns:
        A :class:`Solution` whose ``stats`` hold the solver's statistics, the largest residuals
        and the action; failures are a status on it.
    """
    scheme = Scheme.coerce(scheme)
    if not isinstance(system, HamiltonianSystem):
        raise InputError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
    n = system.n
    q_start = check_state("q_start", q_start, n)
    q_end = check_state("q_end", q_end, n)
    t0, t1 = _check_span(t_span)
    nodes = check_integer("nodes", nodes, minimum=3)
    tol = check_real("tol", tol, positive=True)
    if solver not in SOLVERS:
        raise InputError(f"unknown solver {solver!r} (choose from {', '.join(SOLVERS)})")
    max_iter = check_integer("max_iter", max_iter)
    mean_step = (t1 - t0) / (nodes - 1)
    tau_floor = check_real("tau_floor", 1e-3 * mean_step if tau_floor is None else tau_floor,
                            positive=True)
    if tau_floor >= mean_step:
        raise InputError(f"tau_floor must be < (t_end - t_0)/(nodes - 1) = {mean_step!r}, "
                         f"got {tau_floor!r}")
    grid_times = _check_times(times, nodes, t0, t1)
    start = _check_guess(guess, nodes, n) if guess is not None else None
    theta = system.parameter_vector(params)

    started = time.perf_counter()
    problem = _problem(system, scheme, nodes, solver, verbose, max_iter, tol)
    fixed = problem if not scheme.variable_steps else _problem(
        system, Scheme("fixed", alpha=scheme.alpha, clock=scheme.clock), nodes, solver, verbose,
        max_iter, tol)
    built = time.perf_counter()
    stats: dict = {"solver": solver, "phases": []}
    ends_fixed = (q_start, q_end, theta, tau_floor)
    if start is None:
        start = _three_phase_start(system, scheme, fixed, grid_times, ends_fixed, stats)
    ends = np.array([t0, t1]) if scheme.variable_steps else grid_times
    par = np.concatenate([q_start, q_end, ends, theta, [mean_step]])
    layout = problem.layout
    x0 = layout.pack(np.asarray(start["t"], float), np.asarray(start["q"], float),
                     np.asarray(start["p"], float))
    x, phase = problem.solve(x0, par, tau_floor)
    phase["phase"] = f"{scheme.rule} equations"
    stats["phases"].append(phase)
    solved = time.perf_counter()

    t, q, p = layout.unpack(x, ends, q_start, q_end)
    canonical, energy = equations.grid_residuals(system, scheme, t, q, p, theta)
    stats.update(return_status=phase["return_status"], iterations=phase["iterations"],
                 iterations_total=sum(ph["iterations"] for ph in stats["phases"]),
                 action=float(problem.action(x, par)) if np.all(np.isfinite(x)) else math.nan,
                 energy_scale=mean_step, tau_floor=tau_floor)
    status, message = _verify(phase, t, canonical, energy, scheme, tol, mean_step, stats)
    return Solution(
        t=t, q=q, p=p, status=status, message=message, scheme=scheme.rule,
        energy_residual=energy, canonical_residual=np.max(np.abs(canonical), axis=1),
        newton_iterations=stats["iterations_total"],
        timing={"build_s": built - started, "solve_s": solved - built}, stats=stats)


def _check_span(t_span) -> tuple[float, float]:
    try:
        t0, t1 = (float(v) for v in t_span)
    except (TypeError, ValueError):
        raise InputError(f"t_span must be a pair (t_0, t_end), got {t_span!r}") from None
    check_real("t_span[0]", t0)
    check_real("t_span[1]", t1)
    if t1 <= t0:
        raise InputError(f"t_span must have t_end > t_0, got {t_span!r}")
    return t0, t1


def _check_times(times, nodes: int, t0: float, t1: float) -> np.ndarray:
    """The fixed rule's node times: uniform by default, else ``nodes`` increasing values from
    ``t0`` to ``t1``."""
    if times is None:
        return np.linspace(t0, t1, nodes)
    grid_times = np.asarray(times, float)
    if grid_times.shape != (nodes,) or not np.all(np.isfinite(grid_times)) \
            or grid_times[0] != t0 or grid_times[-1] != t1 or np.any(np.diff(grid_times) <= 0):
        raise InputError(f"times must be {nodes} increasing finite values from t_0 to "
                         f"t_end, got {times!r}")
    return grid_times


def _three_phase_start(system, scheme, fixed, grid_times, ends_fixed, stats) -> dict:
    """The default starting point (module docstring): the straight line; for an energy rule
    then the fixed-step solution on uniform times, then on the times the site density predicts
    from it. Each phase that fails leaves the previous one's point."""
    q_start, q_end, theta, tau_floor = ends_fixed

    def solve_fixed(times, q, p, phase_name):
        par = np.concatenate([q_start, q_end, times, theta, [1.0]])
        x, phase = fixed.solve(fixed.layout.pack(times, q, p), par, tau_floor)
        phase["phase"] = phase_name
        stats["phases"].append(phase)
        if phase["converged"] and np.all(np.isfinite(x)):
            return fixed.layout.unpack(x, times, q_start, q_end)
        return None

    q, p = _straight_line_guess(q_start, q_end, grid_times)
    start = {"t": grid_times, "q": q, "p": p}
    if not scheme.variable_steps:
        return start
    first = solve_fixed(grid_times, q, p, "fixed steps, uniform times")
    if first is None:
        return start
    t, q, p = first
    start = {"t": t, "q": q, "p": p}
    times = predicted_times(system, t, q, p, theta)
    second = solve_fixed(times, _interpolate(times, t, q), _interpolate(times, t, p),
                         "fixed steps, predicted times")
    if second is not None:
        start = dict(zip(("t", "q", "p"), second, strict=True))
    return start


def _verify(phase, t, canonical, energy, scheme, tol, mean_step, stats):
    """Status and message from the solver's flag and the point's own residuals: the solver's
    failure first, then non-finite values, a step ``<= 0``, residuals above tolerance."""
    tau = np.diff(t)
    finite = bool(np.all(np.isfinite(canonical)) and np.all(np.isfinite(energy))
                  and np.all(np.isfinite(t)))
    worst_canonical = float(np.max(np.abs(canonical))) if finite else math.inf
    worst_energy = float(np.max(np.abs(energy), initial=0.0)) if finite else math.inf
    stats.update(canonical_residual_max=worst_canonical, energy_residual_max=worst_energy,
                 tau_min=float(np.min(tau)))
    problems = []
    if not finite:
        problems.append("non-finite values")
    elif np.min(tau) <= 0:
        k = int(np.argmin(tau))
        problems.append(f"step {k} is not positive: tau = {tau[k]:.6g} (t = {t[k]:.10g})")
    if finite and worst_canonical > tol:
        k = int(np.argmax(np.max(np.abs(canonical), axis=1)))
        problems.append(f"canonical residual {worst_canonical:.3e} on interval {k} "
                        f"(t = {t[k]:.6g})")
    if finite and scheme.variable_steps and worst_energy > tol * mean_step:
        k = int(np.argmax(np.abs(energy))) + 1
        problems.append(f"energy residual {worst_energy:.3e} at node {k} (t = {t[k]:.6g}), "
                        f"tolerance {tol * mean_step:.3e}")
    if not phase["converged"]:
        return Status.SOLVER_FAILED, (f"{Status.SOLVER_FAILED.value} ({phase['return_status']})"
                                      + "".join(f"; {p}" for p in problems))
    if not finite:
        return Status.NON_FINITE, "the solver returned non-finite values"
    if np.min(tau) <= 0:
        return Status.NO_ADMISSIBLE_STEP, problems[0]
    if problems:
        return Status.NOT_VERIFIED, f"{Status.NOT_VERIFIED.value}: {'; '.join(problems)}"
    return Status.SUCCESS, (f"solved and verified: largest residuals canonical "
                            f"{worst_canonical:.3e}, energy {worst_energy:.3e}; "
                            f"{phase['iterations']} iterations")


def _interpolate(times, t, values):
    return np.column_stack([np.interp(times, t, column) for column in values.T])


def _check_guess(guess, nodes, n):
    if isinstance(guess, Solution):
        guess = {"t": guess.t, "q": guess.q, "p": guess.p}
    if not isinstance(guess, Mapping) or not {"t", "q", "p"} <= set(guess):
        raise InputError("guess must be a Solution or a mapping with t, q and p")
    shapes = {"t": (nodes,), "q": (nodes, n), "p": (nodes, n)}
    result = {}
    for key, shape in shapes.items():
        result[key] = check_finite_array(f"guess[{key!r}]", guess[key], shape)
    return result
