"""Lagrangians with higher derivatives, ``L(q, v_1, ..., v_l, t)``: the paper's case 1.

Forward differences on the variable grid, evaluated at the left node (THEORY.md section 3)::

    v_1^(k) = (q_{k+1} - q_k) / tau_k,   v_m^(k) = (v_{m-1}^(k+1) - v_{m-1}^(k)) / tau_k,
    L^(k) = L(q_k, v_1^(k), ..., v_l^(k), t_k),   S_D = sum_k tau_k L^(k),

the sum running over the intervals whose differences the grid defines (``k <= N - 1 - l``).

The paper introduces the ``v_m`` as independent variables with Lagrange multipliers for
``v_m = Delta v_{m-1}``; eliminating the multipliers (its eq. n-order) leaves the stationarity of
``S_D`` in the free node positions (the discrete Euler-Lagrange equations, here the gradient of
the assembled action by automatic differentiation) and, for the energy rule, in the free node
times. The multipliers are recovered on a solution from the recursion

    lambda_l^(k) = dL/dv_l^(k),
    lambda_m^(k) = dL/dv_m^(k) - (lambda_{m+1}^(k) - lambda_{m+1}^(k-1)) / tau_k,

that is ``lambda_m = sum_h (-Delta R^-1)^h dL/dv_{m+h}``, and the energy is
``E^(k) = sum_m lambda_m^(k) . v_m^(k) - L^(k)``. For an autonomous ``L`` the node-time
stationarity keeps ``E^(k)`` constant: the tests measure it to round-off along variable-step
solutions, which checks the recursion and the equations against each other. The energy rule
here is that stationarity (``lee``); ``vddvp`` differs from it only through the paper's hatted
time derivative of a time-dependent ``L``, which is not implemented: it is accepted for
autonomous ``L`` (where the two coincide) and refused otherwise.

Fixed-endpoint problems fix ``l`` nodes (times and positions) at each end; marches start from
``2l`` given nodes and solve, per step, the Euler-Lagrange equation at node ``k`` (and the energy
equation at node ``k``) for node ``k + l``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cached_property

import casadi as ca
import numpy as np

from .checks import check_integer, check_real
from .errors import InputError
from .solution import Solution, Status, bound_reached
from .system import check_parameter_values

RULES = ("vddvp", "lee", "fixed")
NEWTON_OPTIONS = {"abstol": 1e-13, "abstolStep": 1e-15, "max_iter": 50, "error_on_fail": False}


class HigherOrderSystem:
    """``L(q, v, t, **params)`` with ``v[m-1]`` the ``m``-th difference, ``m = 1 .. order``.

    Attributes:
        lagrangian, n, order, params, name: as given.
        time_dependent: whether ``L`` depends on ``t`` (read off the expression).
    """

    def __init__(self, lagrangian: Callable[..., object], n: int, order: int,
                 params: Mapping[str, float] | None = None, name: str = "system"):
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise InputError(f"n must be a positive integer, got {n!r}")
        self.order = check_integer("order", order)
        self.n, self.name, self.lagrangian = int(n), name, lagrangian
        self.params = check_parameter_values(dict(params or {}),
                                             {k: 0.0 for k in dict(params or {})},
                                             owner=f"system {name!r}")
        self.q = ca.SX.sym("q", self.n)
        self.v = [ca.SX.sym(f"v{m}", self.n) for m in range(1, self.order + 1)]
        self.t = ca.SX.sym("t")
        self.theta = ca.SX.sym("theta", len(self.params))
        symbols = {k: self.theta[i] for i, k in enumerate(self.params)}
        try:
            value = lagrangian(self.q, self.v, self.t, **symbols)
        except Exception as exc:
            raise InputError(f"lagrangian of {name!r} failed on symbolic input: "
                             f"{type(exc).__name__}: {exc}") from exc
        from .system import _as_scalar_expression

        self.L = _as_scalar_expression(value, name, "lagrangian")
        given = ca.vertcat(self.q, *self.v, self.t, self.theta)
        stray = [s.name() for s in ca.symvar(self.L) if not ca.depends_on(s, given)]
        if stray:
            raise InputError(f"lagrangian of {name!r} depends on symbols it was not given: "
                             f"{', '.join(stray)}")
        self.time_dependent = bool(ca.depends_on(self.L, self.t))
        inputs = [self.q, *self.v, self.t, self.theta]
        self.L_function = ca.Function("L", inputs, [self.L])
        self.L_v_function = ca.Function("L_v", inputs, [ca.gradient(self.L, v) for v in self.v])
        self._check_regular()
        self._cache: dict = {}

    def _check_regular(self):
        from .lagrangian import is_regular

        top = self.v[-1]
        hessian = ca.Function("L_top", [self.q, *self.v, self.t, self.theta],
                              [ca.jacobian(ca.gradient(self.L, top), top)])
        if not is_regular(hessian, vectors=self.order + 1, n=self.n,
                          theta=list(self.params.values())):
            raise InputError(
                f"lagrangian of {self.name!r} is singular in its highest derivative v{self.order}"
                f": d2L/dv{self.order}^2 is not invertible, so the discrete Euler-Lagrange "
                "equations do not determine the next node")

    def parameter_vector(self, values: Mapping[str, object] | None = None) -> np.ndarray:
        resolved = check_parameter_values(dict(values or {}), self.params,
                                          owner=f"system {self.name!r}")
        return np.array([resolved[k] for k in self.params], dtype=float)


def differences(order: int, q_nodes: list, t_nodes: list) -> list[list]:
    """``[[v_1^(k), ..., v_l^(k)] for each k]`` over the intervals the nodes define."""
    levels = [q_nodes]
    for _ in range(order):
        previous = levels[-1]
        levels.append([(previous[k + 1] - previous[k]) / (t_nodes[k + 1] - t_nodes[k])
                       for k in range(len(previous) - 1)])
    count = len(q_nodes) - order
    return [[levels[m][k] for m in range(1, order + 1)] for k in range(count)]


def action(system: HigherOrderSystem, q_nodes: list, t_nodes: list, theta) -> ca.SX:
    """``S_D = sum_k tau_k L(q_k, v^(k), t_k)`` over the given nodes."""
    total = 0
    for k, v in enumerate(differences(system.order, q_nodes, t_nodes)):
        total += (t_nodes[k + 1] - t_nodes[k]) * system.L_function(q_nodes[k], *v, t_nodes[k],
                                                                    theta)
    return total


def _check_rule(system: HigherOrderSystem, rule: str) -> str:
    if rule not in RULES:
        raise InputError(f"unknown scheme {rule!r} (choose from {', '.join(RULES)})")
    if rule == "vddvp" and system.time_dependent:
        raise InputError("the vddvp rule for a time-dependent higher-order Lagrangian (the "
                         "paper's hatted time derivative) is not implemented; use lee or fixed")
    return rule


def energies(system: HigherOrderSystem, t, q, theta) -> tuple[np.ndarray, np.ndarray]:
    """Multipliers ``lambda_1^(k)`` (shape ``(K, n)``) and energies ``E^(k)`` (``(K,)``) on a
    grid, for ``k = l-1 .. N-1-l`` (where the recursion has what it needs)."""
    l, n = system.order, system.n  # noqa: E741 (l is the order, as in the paper)
    t = np.asarray(t, float)
    q = np.asarray(q, float).reshape(t.size, n)
    v = differences(l, list(q), list(t))
    partials = [[np.asarray(d, float).ravel() for d in system.L_v_function(q[k], *v[k], t[k],
                                                                          theta)]
                for k in range(len(v))]
    lam = [[None] * l for _ in range(len(v))]
    for k in range(len(v)):
        lam[k][l - 1] = partials[k][l - 1]
    for m in range(l - 2, -1, -1):  # lambda_m from lambda_{m+1} at k and k - 1
        for k in range(len(v)):
            if k == 0 or lam[k - 1][m + 1] is None or lam[k][m + 1] is None:
                continue
            lam[k][m] = partials[k][m] - (lam[k][m + 1] - lam[k - 1][m + 1]) / (t[k + 1] - t[k])
    first, E = [], []
    for k in range(len(v)):
        if any(x is None for x in lam[k]):
            continue
        L = float(system.L_function(q[k], *v[k], t[k], theta))
        E.append(sum(float(np.dot(lam[k][m], np.asarray(v[k][m], float))) for m in range(l))
                 - L)
        first.append(lam[k][0])
    return np.array(first).reshape(-1, n), np.array(E)


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
    l, n = system.order, system.n  # noqa: E741 (l is the order, as in the paper)
    t_start, t_stop = (np.asarray(x, float).reshape(l) for x in (t_start, t_stop))
    q_start, q_stop = (np.asarray(x, float).reshape(l, n) for x in (q_start, q_stop))
    for name, value in (("t_start", t_start), ("q_start", q_start), ("t_stop", t_stop),
                        ("q_stop", q_stop)):
        if not np.all(np.isfinite(value)):
            raise InputError(f"{name} must be finite, got {value.tolist()}")
    nodes = check_integer("nodes", nodes, minimum=2 * l + 1)
    tol = check_real("tol", tol, positive=True)
    times = np.concatenate([t_start, t_stop])
    if np.any(np.diff(times) <= 0):
        raise InputError(f"the fixed node times must increase, got {times.tolist()}")
    theta = system.parameter_vector(params)
    started = time.perf_counter()
    free = nodes - 2 * l
    Q = ca.SX.sym("q", n, free)
    T = ca.SX.sym("t", free) if rule != "fixed" else None
    uniform = np.linspace(t_start[-1], t_stop[0], free + 2)[1:-1]
    q_nodes = [ca.DM(x) for x in q_start] + [Q[:, j] for j in range(free)] + \
        [ca.DM(x) for x in q_stop]
    t_free = [T[j] for j in range(free)] if T is not None else list(uniform)
    t_nodes = list(t_start) + t_free + list(t_stop)
    S = action(system, q_nodes, t_nodes, ca.DM(theta))
    unknowns = ca.vec(Q) if T is None else ca.vertcat(ca.vec(Q), T)
    mean = (t_stop[0] - t_start[-1]) / (free + 1)
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
    built = time.perf_counter()
    guess_q = np.array([np.interp(uniform, times, np.concatenate([q_start[:, i], q_stop[:, i]]))
                        for i in range(n)])
    if T is not None:  # start from the fixed-step solution on uniform times, then release them
        fixed = solve_bvp_higher(system, t_start, q_start, t_stop, q_stop, nodes=nodes,
                                 scheme="fixed", params=params, tol=tol, max_iter=max_iter)
        if fixed.success:
            guess_q = fixed.q[l:nodes - l].T
    x0 = guess_q.T.ravel() if T is None else np.concatenate([guess_q.T.ravel(), uniform])
    floor = 1e-3 * mean
    result = solver(x0=x0, lbg=np.concatenate([np.zeros(g.numel()),
                                               np.full(steps.numel(), floor)]),
                    ubg=np.concatenate([np.zeros(g.numel()), np.full(steps.numel(), np.inf)]))
    stats = solver.stats()
    x = np.asarray(result["x"]).ravel()
    q_free = x[:n * free].reshape(free, n)
    t_all = np.concatenate([t_start, x[n * free:] if T is not None else uniform, t_stop])
    q_all = np.vstack([q_start, q_free, q_stop])
    residual = ca.Function("g", [unknowns], [g])(x)
    residual = np.abs(np.asarray(residual)).ravel()
    el, energy = residual[:n * free], residual[n * free:]
    ok = (stats.get("success") and el.max(initial=0) <= tol * max(1.0, np.abs(q_all).max())
          and energy.max(initial=0) <= tol * max(1.0, abs(mean)) and np.all(np.diff(t_all) > 0))
    status = Status.SUCCESS if ok else (Status.NOT_VERIFIED if stats.get("success")
                                        else Status.SOLVER_FAILED)
    detail = (f"largest residuals: Euler-Lagrange {el.max(initial=0):.3e} (times "
              f"mean step^{2 * l - 1}), energy {energy.max(initial=0):.3e}; IPOPT: "
              f"{stats.get('return_status')}, {stats.get('iter_count')} iterations")
    message = (("solved and verified: " if ok else f"{status.value}: ") + detail)
    return _higher_solution(system, t_all, q_all, theta, status, message, rule,
                            {"build_s": built - started,
                             "solve_s": time.perf_counter() - built},
                            {"euler_lagrange_residual": el, "energy_equation_residual": energy,
                             "iterations": int(stats.get("iter_count", 0))})


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
    scaled by ``tau^(2l-1)``, in the units of ``q``).
    """
    rule = _check_rule(system, scheme)
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
    variable = rule != "fixed"
    if variable and l < 2:
        raise InputError("march_higher's energy rule needs order >= 2; first-order Lagrangians "
                         "march with ddvp_nlp.march (LagrangianSystem)")
    theta = system.parameter_vector(params)
    started = time.perf_counter()
    root, check = _step_functions(system, rule)
    built = time.perf_counter()
    h = t_init[-1] - t_init[-2]
    if variable:  # complete nodes: all but the last; pending: the last interval's difference
        t, q = list(t_init[:-1]), list(q_init[:-1])
        u = (q_init[-1] - q_init[-2]) / h
        tau = h
    else:
        t, q = list(t_init), list(q_init)
    status, detail = Status.SUCCESS, ""
    while t[-1] < t_end:
        reached = bound_reached(len(t) - 2 * l, max_steps, built, time_limit)
        if reached:
            status, detail = reached
            break
        if variable:
            w = np.concatenate([t[-(2 * l - 1):], np.ravel(q[-(2 * l - 1):]), u, theta])
            x = np.asarray(root(np.concatenate([u, [tau]]), w)).ravel()
            step = x[-1]
        else:
            w = np.concatenate([t[-2 * l:], np.ravel(q[-2 * l:]), theta])
            x = np.asarray(root(_extrapolate(np.array(t[-2 * l:]), np.array(q[-2 * l:]),
                                             t[-1] + h), w)).ravel()
            step = h
        if not np.all(np.isfinite(x)):
            status, detail = Status.NON_FINITE, ""
            break
        if step <= 0:
            status, detail = Status.NO_ADMISSIBLE_STEP, f"Newton found tau = {step:.6g}"
            break
        el, energy, size = (float(v) for v in check(x, w))
        if el > tol * max(1.0, size) or abs(energy) > tol * max(1.0, size):
            converged = root.stats().get("return_status") == "success"
            status = Status.RESIDUAL_TOO_LARGE if converged else Status.NEWTON_FAILED
            detail = f"Euler-Lagrange residual {el:.3e}, energy residual {energy:.3e}"
            break
        if variable:
            t.append(t[-1] + step)
            q.append(q[-1] + step * u)
            u, tau = x[:n], step
        else:
            t.append(t[-1] + step)
            q.append(x[:n])
    t_arr, q_arr = np.array(t), np.array(q)
    if status is Status.SUCCESS:
        message = f"{status.value} = {t_end:.6g} in {t_arr.size - 1} steps"
    else:
        message = (f"{status.value}: step {t_arr.size - 1} from t = {t_arr[-1]:.10g}, "
                   f"q = {q_arr[-1]}" + (f"; {detail}" if detail else ""))
    return _higher_solution(system, t_arr, q_arr, theta, status, message, rule,
                            {"build_s": built - started,
                             "solve_s": time.perf_counter() - built}, {})


def _extrapolate(t, q, t_new):
    """Polynomial through the window's nodes, evaluated at ``t_new`` (the predictor)."""
    degree = min(len(t) - 1, 3)
    return np.array([np.polyval(np.polyfit(t - t[-1], q[:, i], degree), t_new - t[-1])
                     for i in range(q.shape[1])])


def _step_functions(system: HigherOrderSystem, rule: str):
    """Newton for one march step (see :func:`march_higher`) and its residual check."""
    key = ("march", rule)
    if key in system._cache:
        return system._cache[key]
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
    system._cache[key] = (root, check)
    return root, check


@dataclass(eq=False)
class HigherOrderScene:
    """A scene declared by ``L(q, v, t, **params)`` with ``v[m-1]`` the ``m``-th difference.

    Attributes:
        lagrangian, n, order, params: the system.
        exact: ``exact(t, **params) -> q`` of shape ``(N, n)``: the motion the scene follows. The
            march starts from ``2 * order`` of its nodes spaced ``tau0`` from ``t0``; the
            fixed-endpoint problem takes ``order`` of its nodes at each end of ``t_span`` on the
            uniform grid of ``nodes`` nodes.
        tau0, t_end, t0: march defaults; ``boundary``: ``{"t_span": (t0, t1), "nodes": N}``.
    """

    lagrangian: Callable[..., object]
    n: int
    order: int
    exact: Callable[..., np.ndarray]
    tau0: float
    t_end: float
    t0: float = 0.0
    params: Mapping[str, float] = field(default_factory=dict)
    boundary: Mapping[str, object] | None = None
    name: str = "scene"
    source: str = ""
    description: str = ""

    @cached_property
    def system(self) -> HigherOrderSystem:
        return HigherOrderSystem(self.lagrangian, self.n, self.order, dict(self.params),
                                 name=self.name)

    def resolve(self, overrides=None) -> dict:
        """Parameters, ``t0``, ``tau0``, ``t_end``, ``nodes`` with ``overrides`` applied."""
        overrides = dict(overrides or {})
        settings = {k: overrides.pop(k) for k in ("t0", "tau0", "t_end") if k in overrides}
        params = check_parameter_values(overrides, dict(self.params),
                                        owner=f"scene {self.name!r}")
        values = {"t0": self.t0, "tau0": self.tau0, "t_end": self.t_end, **settings}
        for key, value in values.items():
            check_real(key, value)
        return {"params": params, **{k: float(v) for k, v in values.items()}}

    def start(self, config) -> tuple[np.ndarray, np.ndarray]:
        t = config["t0"] + config["tau0"] * np.arange(2 * self.order)
        return t, self._exact(t, config["params"])

    def ends(self, config, nodes: int, t_span):
        grid = np.linspace(t_span[0], t_span[1], nodes)
        l = self.order  # noqa: E741 (l is the order, as in the paper)
        q = self._exact(grid, config["params"])
        return grid[:l], q[:l], grid[-l:], q[-l:]

    def _exact(self, t, params):
        return np.asarray(self.exact(np.asarray(t, float), **params), float).reshape(
            np.size(t), self.n)


__all__ = ["HigherOrderScene", "HigherOrderSystem", "action", "differences", "energies",
           "march_higher", "solve_bvp_higher"]
