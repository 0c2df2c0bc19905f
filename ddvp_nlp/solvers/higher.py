"""Fixed-endpoint problems and marches for higher-derivative Lagrangians (``discrete/higher.py``).

A Lagrangian of order ``l`` couples ``2l + 1`` nodes in its Euler-Lagrange equation at a node, so
a fixed-endpoint problem fixes ``l`` nodes at each end and a march starts from ``2l`` nodes.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..cache import cached
from ..discrete.higher import _check_rule, action, energies
from ..errors import InputError
from ..physics.higher import HigherOrderSystem
from ..solution import Solution, Status
from ..validation import check_integer, check_real
from .driver import Advance, Nodes, drive

NEWTON_OPTIONS = {"abstol": 1e-13, "abstolStep": 1e-15, "max_iter": 50, "error_on_fail": False}


@dataclass
class _Ends:
    """The ``l`` fixed nodes at each end of a fixed-endpoint problem."""

    t_start: np.ndarray
    q_start: np.ndarray
    t_stop: np.ndarray
    q_stop: np.ndarray

    @property
    def times(self) -> np.ndarray:
        return np.concatenate([self.t_start, self.t_stop])


def _ends(system: HigherOrderSystem, t_start, q_start, t_stop, q_stop) -> _Ends:
    """The fixed nodes as arrays of shapes ``(l,)`` and ``(l, n)``; ``InputError`` if not
    finite."""
    l, n = system.order, system.n  # noqa: E741 (l is the order, as in the paper)
    t_start, t_stop = (np.asarray(x, float).reshape(l) for x in (t_start, t_stop))
    q_start, q_stop = (np.asarray(x, float).reshape(l, n) for x in (q_start, q_stop))
    for name, value in (("t_start", t_start), ("q_start", q_start), ("t_stop", t_stop),
                        ("q_stop", q_stop)):
        if not np.all(np.isfinite(value)):
            raise InputError(f"{name} must be finite, got {value.tolist()}")
    return _Ends(t_start, q_start, t_stop, q_stop)


@dataclass
class _Problem:
    """The NLP of a fixed-endpoint problem: unknowns the ``free`` interior positions (column
    ``j`` of an ``n x free`` matrix, stacked by column) and, for an energy rule, their times;
    constraints ``g = 0`` (the equations) and ``steps >= floor``."""

    solver: ca.Function
    unknowns: ca.SX
    g: ca.SX
    steps: ca.SX
    free: int
    uniform: np.ndarray  # the interior times of uniform steps
    mean: float  # the mean step


def _build_problem(system: HigherOrderSystem, rule: str, ends: _Ends, nodes: int, theta,
                   tol: float, max_iter: int) -> _Problem:
    """The Euler-Lagrange rows (scaled by the mean step to the power ``2l - 1``, the units of
    ``q``) and, for an energy rule, the energy rows, as an IPOPT problem."""
    l, n = system.order, system.n  # noqa: E741 (l is the order, as in the paper)
    free = nodes - 2 * l
    Q = ca.SX.sym("q", n, free)
    T = ca.SX.sym("t", free) if rule != "fixed" else None
    uniform = np.linspace(ends.t_start[-1], ends.t_stop[0], free + 2)[1:-1]
    q_nodes = [ca.DM(x) for x in ends.q_start] + [Q[:, j] for j in range(free)] + \
        [ca.DM(x) for x in ends.q_stop]
    t_free = [T[j] for j in range(free)] if T is not None else list(uniform)
    t_nodes = list(ends.t_start) + t_free + list(ends.t_stop)
    S = action(system, q_nodes, t_nodes, ca.DM(theta))
    unknowns = ca.vec(Q) if T is None else ca.vertcat(ca.vec(Q), T)
    mean = (ends.t_stop[0] - ends.t_start[-1]) / (free + 1)
    scale = mean ** (2 * l - 1)  # an Euler-Lagrange row ~ dq / tau^(2l-1)
    g = [ca.gradient(S, ca.vec(Q)) * scale]
    if T is not None:
        g.append(ca.gradient(S, T))
        steps = ca.vertcat(*[t_nodes[k + 1] - t_nodes[k] for k in range(nodes - 1)])
    else:
        steps = ca.SX(0, 1)
    g = ca.vertcat(*g)
    solver = ca.nlpsol("bvp_higher", "ipopt", {"x": unknowns, "f": 0,
                                                "g": ca.vertcat(g, steps)},
                       {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                        "ipopt.tol": tol * 1e-2, "ipopt.constr_viol_tol": tol * 1e-2,
                        "ipopt.max_iter": max_iter})
    return _Problem(solver, unknowns, g, steps, free, uniform, mean)


def _initial_guess(problem: _Problem, ends: _Ends, fixed: Solution | None, order: int,
                   nodes: int) -> np.ndarray:
    """Positions interpolated linearly between the ends on uniform times; for an energy rule
    (``fixed``: its warm start, the fixed-step solution) those of ``fixed`` where it succeeded,
    then the uniform times."""
    times, n = ends.times, ends.q_start.shape[1]
    guess_q = np.array([np.interp(problem.uniform, times,
                                  np.concatenate([ends.q_start[:, i], ends.q_stop[:, i]]))
                        for i in range(n)])
    if fixed is not None and fixed.success:
        guess_q = fixed.q[order:nodes - order].T
    return guess_q.T.ravel() if fixed is None else np.concatenate([guess_q.T.ravel(),
                                                                   problem.uniform])


def _solve(problem: _Problem, x0: np.ndarray) -> tuple[np.ndarray, dict]:
    """IPOPT from ``x0``: the equations as equalities, every step at least ``1e-3`` times the
    mean step."""
    floor = 1e-3 * problem.mean
    g_size, step_count = problem.g.numel(), problem.steps.numel()
    result = problem.solver(x0=x0, lbg=np.concatenate([np.zeros(g_size),
                                                       np.full(step_count, floor)]),
                            ubg=np.concatenate([np.zeros(g_size), np.full(step_count, np.inf)]))
    return np.asarray(result["x"]).ravel(), problem.solver.stats()


def _verify(problem: _Problem, ends: _Ends, x: np.ndarray, stats: dict, tol: float, order: int,
            variable: bool):
    """The nodes of IPOPT's point ``x``, its status (``SUCCESS`` only if IPOPT succeeded, the
    unscaled residuals are under ``tol`` and every step is positive), message and residuals."""
    n, free = ends.q_start.shape[1], problem.free
    q_free = x[:n * free].reshape(free, n)
    t_all = np.concatenate([ends.t_start, x[n * free:] if variable else problem.uniform,
                            ends.t_stop])
    q_all = np.vstack([ends.q_start, q_free, ends.q_stop])
    residual = ca.Function("g", [problem.unknowns], [problem.g])(x)
    residual = np.abs(np.asarray(residual)).ravel()
    el, energy = residual[:n * free], residual[n * free:]
    ok = (stats.get("success") and el.max(initial=0) <= tol * max(1.0, np.abs(q_all).max())
          and energy.max(initial=0) <= tol * max(1.0, abs(problem.mean))
          and np.all(np.diff(t_all) > 0))
    status = Status.SUCCESS if ok else (Status.NOT_VERIFIED if stats.get("success")
                                        else Status.SOLVER_FAILED)
    detail = (f"largest residuals: Euler-Lagrange {el.max(initial=0):.3e} (times "
              f"mean step^{2 * order - 1}), energy {energy.max(initial=0):.3e}; IPOPT: "
              f"{stats.get('return_status')}, {stats.get('iter_count')} iterations")
    message = ("solved and verified: " if ok else f"{status.value}: ") + detail
    return t_all, q_all, status, message, {"euler_lagrange_residual": el,
                                           "energy_equation_residual": energy}


def solve_bvp_higher(system: HigherOrderSystem, t_start, q_start, t_stop, q_stop, *,
                     nodes: int, scheme: str = "vddvp", params=None, tol: float = 1e-9,
                     max_iter: int = 500) -> Solution:
    """The fixed-endpoint problem: ``l`` nodes fixed at each end (``t_start``, ``q_start`` of
    shapes ``(l,)``, ``(l, n)``; likewise at the stop), ``nodes`` nodes in all; unknown the free
    positions (and for an energy rule the free node times, starting uniform). IPOPT solves the
    Euler-Lagrange (and energy) equations; the result is verified by its unscaled residuals
    (scaled by the mean step to the power ``2l - 1`` for the Euler-Lagrange rows, the units of
    ``q``) and every step must be positive."""
    rule = _check_rule(system, scheme)
    ends = _ends(system, t_start, q_start, t_stop, q_stop)
    nodes = check_integer("nodes", nodes, minimum=2 * system.order + 1)
    tol = check_real("tol", tol, positive=True)
    if np.any(np.diff(ends.times) <= 0):
        raise InputError(f"the fixed node times must increase, got {ends.times.tolist()}")
    theta = system.parameter_vector(params)
    started = time.perf_counter()
    problem = _build_problem(system, rule, ends, nodes, theta, tol, max_iter)
    built = time.perf_counter()
    variable = rule != "fixed"
    # an energy rule starts from the fixed-step solution on uniform times, then releases them
    fixed = solve_bvp_higher(system, ends.t_start, ends.q_start, ends.t_stop, ends.q_stop,
                             nodes=nodes, scheme="fixed", params=params, tol=tol,
                             max_iter=max_iter) if variable else None
    x, stats = _solve(problem, _initial_guess(problem, ends, fixed, system.order, nodes))
    t_all, q_all, status, message, residuals = _verify(problem, ends, x, stats, tol,
                                                       system.order, variable)
    return _higher_solution(system, t_all, q_all, theta, status, message, rule,
                            {"build_s": built - started,
                             "solve_s": time.perf_counter() - built},
                            {**residuals, "iterations": int(stats.get("iter_count", 0))})


def _higher_solution(system, t, q, theta, status, message, rule, timing, stats):
    """A :class:`Solution` whose ``p`` is the multiplier ``lambda_1`` (the momentum conjugate to
    ``q``) at the nodes where the recursion defines it (``k = l-1 .. N-1-l``; the others repeat
    the nearest defined value and are listed in ``stats["p_defined"]``)."""
    first, E = energies(system, t, q, theta) if t.size > 2 * system.order else (
        np.zeros((0, system.n)), np.zeros(0))
    p = np.zeros_like(q)
    lo = system.order - 1
    if first.shape[0]:
        p[lo:lo + first.shape[0]] = first
        p[:lo] = first[0]
        p[lo + first.shape[0]:] = first[-1]
    return Solution(t=t, q=q, p=p, status=status, message=message, scheme=rule,
                    energy_residual=np.diff(E) if E.size else np.zeros(0),
                    canonical_residual=np.zeros(0), timing=timing,
                    stats={**stats, "energy": E, "p_defined": [lo, lo + first.shape[0]]})



def _check_start(system: HigherOrderSystem, rule: str, t_init, q_init, t_end, max_steps):
    """The start nodes as arrays ``(2l,)``, ``(2l, n)``, ``t_end`` and ``max_steps``, checked."""
    l, n = system.order, system.n  # noqa: E741 (l is the order, as in the paper)
    t_init = np.asarray(t_init, float).reshape(-1)
    if t_init.size != 2 * l:
        raise InputError(f"t_init must hold 2*order = {2 * l} node times, got {t_init.size}")
    q_init = np.asarray(q_init, float).reshape(2 * l, n)
    if not (np.all(np.isfinite(t_init)) and np.all(np.isfinite(q_init))):
        raise InputError("t_init and q_init must be finite")
    if np.any(np.diff(t_init) <= 0):
        raise InputError(f"t_init must increase, got {t_init.tolist()}")
    t_end = check_real("t_end", t_end)
    if t_end <= t_init[-1]:
        raise InputError(f"t_end must be > the last given node time {t_init[-1]!r}, got "
                         f"{t_end!r}")
    max_steps = check_integer("max_steps", max_steps)
    if rule != "fixed" and l < 2:
        raise InputError("march_higher's energy rule needs order >= 2; first-order Lagrangians "
                         "march with ddvp_nlp.march (LagrangianSystem)")
    return t_init, q_init, t_end, max_steps


class _HigherSteps:
    """Stepper (``driver.py``) of :func:`march_higher`, one step per call; the nodes' ``z`` is
    ``q``.

    With the energy rule the newest node is *pending*: only its difference
    ``u = (q_{k+l} - q_{k+l-1}) / tau`` is known, kept here with the step ``tau`` that produced
    it; the driver's nodes are the complete ones. A step is accepted only if finite, ``tau > 0``
    and its residuals are under ``tol``."""

    def __init__(self, system: HigherOrderSystem, rule: str, theta, tol: float, h: float,
                 pending=None):
        self.root, self.check = _step_functions(system, rule)
        self.l, self.n, self.theta, self.tol, self.h = system.order, system.n, theta, tol, h
        self.variable = rule != "fixed"
        self.u, self.tau = pending if pending is not None else (None, None)

    def describe(self, z: np.ndarray) -> str:
        return f"q = {z}"

    def advance(self, nodes: Nodes, budget: int) -> Advance:
        t, q = nodes.t[:nodes.count], nodes.z[:nodes.count]
        x, w, step = self._solve(t, q)
        failure = self._failure(x, w, step)
        if failure is not None:
            return Advance.failed(*failure, width=self.n)
        if self.variable:
            q_new = q[-1] + step * self.u
            self.u, self.tau = x[:self.n], step
        else:
            q_new = x[:self.n]
        return Advance(np.array([t[-1] + step]), q_new[None, :])

    def _solve(self, t, q):
        """Newton's point ``x`` for the next step, the known data ``w`` and the step length."""
        l = self.l  # noqa: E741 (l is the order, as in the paper)
        if self.variable:
            w = np.concatenate([t[-(2 * l - 1):], np.ravel(q[-(2 * l - 1):]), self.u,
                                self.theta])
            x = np.asarray(self.root(np.concatenate([self.u, [self.tau]]), w)).ravel()
            return x, w, x[-1]
        w = np.concatenate([t[-2 * l:], np.ravel(q[-2 * l:]), self.theta])
        x = np.asarray(self.root(_extrapolate(t[-2 * l:], q[-2 * l:], t[-1] + self.h),
                                 w)).ravel()
        return x, w, self.h

    def _failure(self, x, w, step) -> tuple[Status, str] | None:
        """``(status, detail)`` if the step is not acceptable, else ``None``."""
        if not np.all(np.isfinite(x)):
            return Status.NON_FINITE, ""
        if step <= 0:
            return Status.NO_ADMISSIBLE_STEP, f"Newton found tau = {step:.6g}"
        el, energy, size = (float(v) for v in self.check(x, w))
        if el > self.tol * max(1.0, size) or abs(energy) > self.tol * max(1.0, size):
            converged = self.root.stats().get("return_status") == "success"
            return (Status.RESIDUAL_TOO_LARGE if converged else Status.NEWTON_FAILED,
                    f"Euler-Lagrange residual {el:.3e}, energy residual {energy:.3e}")
        return None


def march_higher(system: HigherOrderSystem, t_init, q_init, *, t_end: float,
                 scheme: str = "vddvp", params=None, tol: float = 1e-9,
                 max_steps: int = 1_000_000, time_limit: float | None = None) -> Solution:
    """March from ``2l`` given nodes (``t_init`` ``(2l,)``, ``q_init`` ``(2l, n)``) until the
    first node at or past ``t_end``.

    Fixed steps (the spacing of the last two given nodes): step ``k`` solves the Euler-Lagrange
    equation at node ``k`` for node ``k + l``.

    Energy rule (``l >= 2``): node ``k + l`` enters the equations at node ``k`` only through
    the last difference ``u = (q_{k+l} - q_{k+l-1}) / tau_{k+l-1}``, so the equations at node
    ``k`` (Euler-Lagrange and energy) are solved for ``u`` and the time ``t_{k+l-1}`` of the node
    before it, whose position follows from the previous ``u``. The last given node therefore
    fixes only the first ``u``, not a time: its time is recomputed by the first step.

    Newton (CasADi's rootfinder) starts from the previous ``u`` and step; a step is accepted
    only if finite, ``tau > 0`` and its residuals are under ``tol`` (the Euler-Lagrange rows
    scaled by ``tau^(2l-1)``, in the units of ``q``). Steps are counted from the last given
    node: ``max_steps`` bounds the nodes after the first ``2l``.
    """
    rule = _check_rule(system, scheme)
    t_init, q_init, t_end, max_steps = _check_start(system, rule, t_init, q_init, t_end,
                                                    max_steps)
    theta = system.parameter_vector(params)
    started = time.perf_counter()
    h = t_init[-1] - t_init[-2]
    if rule != "fixed":  # the last given node is pending: only its difference is kept
        stepper = _HigherSteps(system, rule, theta, tol, h, ((q_init[-1] - q_init[-2]) / h, h))
        nodes = Nodes(t_init[:-1], q_init[:-1])
    else:
        stepper = _HigherSteps(system, rule, theta, tol, h)
        nodes = Nodes(t_init, q_init)
    built = time.perf_counter()
    outcome = drive(stepper, nodes, t_end=t_end, max_steps=max_steps, time_limit=time_limit,
                    step_offset=2 * system.order - 1)
    return _higher_solution(system, outcome.t, outcome.z, theta, outcome.status,
                            outcome.message, rule, {"build_s": built - started,
                                                    "solve_s": time.perf_counter() - built}, {})


def _extrapolate(t, q, t_new):
    """Polynomial through the window's nodes, evaluated at ``t_new`` (the predictor)."""
    degree = min(len(t) - 1, 3)
    return np.array([np.polyval(np.polyfit(t - t[-1], q[:, i], degree), t_new - t[-1])
                     for i in range(q.shape[1])])


def _step_functions(system: HigherOrderSystem, rule: str):
    """Newton for one march step (see :func:`march_higher`) and its residual check."""
    return cached(system, ("higher_march", rule), lambda: _build_step_functions(system, rule))


def _build_step_functions(system: HigherOrderSystem, rule: str):
    l, n = system.order, system.n  # noqa: E741 (l is the order, as in the paper)
    theta = ca.SX.sym("theta", system.theta.numel())
    variable = rule != "fixed"
    known = 2 * l - 1 if variable else 2 * l  # complete nodes k-l .. in the window
    tw, qw = ca.SX.sym("t", known), ca.SX.sym("q", known * n)
    q_nodes = [qw[i * n:(i + 1) * n] for i in range(known)]
    t_nodes = [tw[i] for i in range(known)]
    if variable:
        u_prev, u, tau = ca.SX.sym("u_prev", n), ca.SX.sym("u", n), ca.SX.sym("tau")
        q_nodes.append(q_nodes[-1] + tau * u_prev)  # node k+l-1, its time unknown
        t_nodes.append(t_nodes[-1] + tau)
        q_nodes.append(q_nodes[-1] + tau * u)  # node k+l: only u matters (any step works)
        t_nodes.append(t_nodes[-1] + tau)
        x, w = ca.vertcat(u, tau), ca.vertcat(tw, qw, u_prev, theta)
    else:
        q_new = ca.SX.sym("q_new", n)
        q_nodes.append(q_new)
        t_nodes.append(tw[-1] + (tw[-1] - tw[-2]))
        x, w = q_new, ca.vertcat(tw, qw, theta)
    # The equations at node k = l of the window, from the action's gradient in q_k and t_k.
    q_k, t_k = ca.SX.sym("q_k", n), ca.SX.sym("t_k")
    at = ca.vertcat(q_nodes[l], t_nodes[l])
    q_nodes[l], t_nodes[l] = q_k, t_k
    S = action(system, q_nodes, t_nodes, theta)
    el = ca.substitute(ca.gradient(S, q_k), ca.vertcat(q_k, t_k), at)
    energy = ca.substitute(ca.gradient(S, t_k), ca.vertcat(q_k, t_k), at)
    scaled = el * (tw[-1] - tw[-2]) ** (2 * l - 1)  # in the units of q, O(1) in tau
    g = ca.vertcat(scaled, energy) if variable else scaled
    root = ca.rootfinder("higher_step", "newton", ca.Function("g", [x, w], [g]), NEWTON_OPTIONS)
    check = ca.Function("check", [x, w], [ca.norm_inf(scaled),
                                         energy if variable else ca.SX(0), ca.norm_inf(qw)])
    return root, check
