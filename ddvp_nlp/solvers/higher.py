"""Fixed-endpoint problems and marches for higher-derivative Lagrangians (``discrete/higher.py``).
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from ..cache import cached
from ..discrete.higher import _check_rule, action, energies
from ..errors import InputError
from ..physics.higher import HigherOrderSystem
from ..solution import Solution, Status, bound_reached
from ..validation import check_integer, check_real

NEWTON_OPTIONS = {"abstol": 1e-13, "abstolStep": 1e-15, "max_iter": 50, "error_on_fail": False}


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
