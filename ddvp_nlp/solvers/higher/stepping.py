"""Fixed-endpoint problems and marches for higher-derivative Lagrangians
(``discrete/higher_order_action.py``).

A Lagrangian of order ``l`` couples ``2l + 1`` nodes in its Euler-Lagrange equation at a node, so
a fixed-endpoint problem fixes ``l`` nodes at each end and a march starts from ``2l`` nodes. The
fixed-endpoint system is assembled window by window (``windows.py``) and solved and
verified in ``window_solve.py``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from types import MappingProxyType

import casadi as ca
import numpy as np

from ...cache import cached
from ...discrete.higher_order_action import action, check_rule, differences
from ...discrete.scheme import Scheme
from ...errors import InputError
from ...physics.higher_order import HigherOrderSystem
from ...solution import HigherRecord, Solution, Status
from ...validation import check_finite_array, check_integer, check_real
from ..accuracy.judgement import fixed_ends_report, judge
from ..compiler import find_compiler
from ..driver import Advance, Nodes, drive
from ..grid.problem import GridRequest
from ..options import (
    DEFAULT_TOLERANCE,
    Compilation,
    GridOptions,
    StepControl,
    Tolerance,
    answers_removed_keywords,
    coerce,
)
from .fixed_nodes import FixedNodes, mean_step, straight
from .window_solve import grid_energies, solve_rule

# The defaults of GridOptions' None fields for the fixed-endpoint problem.
DEFAULT_MAX_ITER = 500
# The march's step control when none is given; of a StepControl the higher-order march reads
# tol, max_steps and time_limit (its steps are the spacing of the given nodes, or the energy
# rule's: no bounds on them).
# The higher-order march's own step solve (one Euler-Lagrange/energy step in the last
# difference; not the first-order march's Newton of solvers/marching/step_newton.py).
HIGHER_STEP_NEWTON = MappingProxyType({"abstol": 1e-13, "abstolStep": 1e-15, "max_iter": 50,
                                       "error_on_fail": False, "show_eval_warnings": False})


def _check_system(system) -> None:
    if not isinstance(system, HigherOrderSystem):
        raise InputError(f"system must be a HigherOrderSystem, got {type(system).__name__}")


def _fixed_nodes(system: HigherOrderSystem, t_start, q_start, t_stop, q_stop) -> FixedNodes:
    """The fixed nodes as finite arrays of shapes ``(l,)`` and ``(l, n)``."""
    l, n = system.order, system.n  # noqa: E741 (l is the order, as in the paper)
    return FixedNodes(check_finite_array("t_start", t_start, (l,)),
                      _positions("q_start", q_start, l, n),
                      check_finite_array("t_stop", t_stop, (l,)),
                      _positions("q_stop", q_stop, l, n))


def _positions(name: str, value, rows: int, n: int) -> np.ndarray:
    """``rows`` positions, a finite ``(rows, n)`` array (for ``n = 1`` also a vector)."""
    array = check_finite_array(name, value)
    if n == 1 and array.shape == (rows,):
        return array.reshape(rows, 1)
    if array.shape != (rows, n):
        raise InputError(f"{name} must have shape ({rows}, {n}), got {array.shape}")
    return array


@answers_removed_keywords
def solve_bvp_higher(system: HigherOrderSystem, t_start, q_start, t_stop, q_stop, *,
                     nodes: int, scheme: str = "vddvp", params=None,
                     options: GridOptions | None = None,
                     compilation: Compilation | None = None) -> Solution:
    """The fixed-endpoint problem: ``l`` nodes fixed at each end (``t_start``, ``q_start`` of
    shapes ``(l,)``, ``(l, n)``; likewise at the stop), ``nodes`` nodes in all; unknown the free
    positions (and for an energy rule the free node times).

    Fixed steps are solved first on uniform times from the straight line between the ends; an
    energy rule then releases the times from that solution. Each solve is by
    ``options.solver``: ``"newton"`` (the grid's Newton on the window assembly,
    ``windows.py``: ``O(N)`` per iteration), ``"ipopt"`` (the grid's IPOPT build on an MX
    graph of the window's gradient mapped over the grid) or ``"auto"`` (Newton, then IPOPT from
    the same start if Newton's point fails the verification). Every point is verified by its
    unscaled residuals (``window_solve.py``): success is that verification, whatever the solver
    said, and the message quotes the solver.

    Args:
        options: ``tol``: verification tolerance (default 1e-10), relative to how far each
            row moves when the unknowns move by their sizes in the data
            (``window_solve.py``), round-off of the rows' own scale always allowed;
            ``max_iter``: iteration limit of each solve (default 500); ``tau_floor``: smallest
            step of an energy rule (default ``1e-3`` times the mean step); ``solver``;
            ``linear`` (the Newton's LU); ``time_limit`` (status ``time_limit``); ``verbose``
            (IPOPT's log).
        compilation: which compiled code the band LU runs.
    """
    request = bvp_request(system, t_start, q_start, t_stop, q_stop, nodes=nodes, scheme=scheme,
                          params=params, options=options, compilation=compilation)
    rule = request.scheme.rule
    started = request.start_clock()
    x, phase, outcome = solve_rule(request, "fixed", straight(request))
    if rule != "fixed":  # the times released from the fixed-step solution
        start = x if outcome[0] is Status.SUCCESS else straight(request)
        x, phase, outcome = solve_rule(request, rule, start)
    status, message, residuals = outcome
    z = x.reshape(nodes, system.n + 1)
    total = time.perf_counter() - started
    solution = _higher_solution(
        system, z[:, 0].copy(), z[:, 1:].copy(), request.theta, status, message, rule,
        {"build_s": request.build_s, "solve_s": total - request.build_s},
        {"iterations": phase.iterations,
         "iterations_total": sum(stage.iterations for stage in request.phases),
         "solver": phase.solver, "return_status": phase.said,
         "tau_floor": request.tau_floor},
        stages=tuple(replace(stage) for stage in request.phases), residuals=residuals)
    l = system.order  # noqa: E741 (l is the order, as in the paper)
    fixed = np.concatenate([np.arange(l), np.arange(nodes - l, nodes)])
    _judge(solution, system, request.theta, request.options.accuracy,
           data=fixed, compiler=find_compiler(request.compilation.compiler),
           cache_dir=request.compilation.cache_dir, fixed_ends=True)
    return solution


def _judge(solution, system, theta, tolerance, *, data=None, compiler=None, cache_dir=None,
           fixed_ends: bool = False):
    """The accuracy check of a higher-order trajectory (``accuracy/positions.py``) into
    ``solution.verdict`` and ``solution.local_error``, and its status (`judge`).
    ``fixed_ends``: a fixed-endpoint solve, whose trajectory error past the tolerance is
    ``inaccurate`` (`fixed_ends_report`), never ``drifted``."""
    from ..accuracy.positions import judge_higher

    if not np.all(np.isfinite(solution.q)) and solution.t.size:
        finite = np.all(np.isfinite(solution.q), axis=1)
        keep = int(np.argmin(finite)) if not finite.all() else solution.t.size
        t, q = solution.t[:keep], solution.q[:keep]
    else:
        t, q = solution.t, solution.q
    report, local = judge_higher(system, t, q, theta, tolerance, data=data,
                                 exact=tolerance.exact, compiler=compiler, cache_dir=cache_dir)
    if fixed_ends:
        report = fixed_ends_report(report, t)
    judge(solution, report, tolerance, local_error=local, advice="try a smaller tau0")


def bvp_request(system: HigherOrderSystem, t_start, q_start, t_stop, q_stop, *, nodes: int,
                scheme: str = "vddvp", params=None, options: GridOptions | None = None,
                compilation: Compilation | None = None) -> GridRequest[FixedNodes]:
    """The checked inputs of `solve_bvp_higher` (``InputError`` naming the argument and
    the value, before anything is built), with the defaults of ``options`` resolved."""
    _check_system(system)
    compilation = coerce(compilation, Compilation, "compilation")
    rule = check_rule(system, scheme)
    fixed = _fixed_nodes(system, t_start, q_start, t_stop, q_stop)
    nodes = check_integer("nodes", nodes, minimum=2 * system.order + 1)
    options = coerce(options, GridOptions, "options").resolved(
        max_iter=DEFAULT_MAX_ITER)
    if np.any(np.diff(fixed.times) <= 0):
        raise InputError(f"the fixed node times must increase, got {fixed.times.tolist()}")
    request = GridRequest(system, Scheme.coerce(rule), nodes, system.parameter_vector(params),
                          fixed, options, compilation)
    mean = mean_step(request)
    request.tau_floor = check_real("tau_floor", 1e-3 * mean if options.tau_floor is None
                                   else options.tau_floor, positive=True)
    if request.tau_floor >= mean:
        raise InputError(f"tau_floor must be < the mean step {mean!r}, got "
                         f"{request.tau_floor!r}")
    return request


def _higher_solution(system, t, q, theta, status, message, rule, timing, stats, **found):
    """A `Solution` whose ``p`` is the multiplier ``lambda_1`` (the momentum conjugate to
    ``q``) at the nodes where the recursion defines it (``k = l-1 .. N-1-l``; the others repeat
    the nearest defined value and are listed in ``higher.p_defined``)."""
    first, E = grid_energies(system, t, q, theta) if t.size > 2 * system.order else (
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
                    stats=dict(stats),
                    higher=HigherRecord(E, (lo, lo + first.shape[0]), **found))



def _check_steps(steps: StepControl) -> None:
    """The higher-order march has no step bounds, breakdown step or energy guard."""
    unused = {name: getattr(steps, name) for name in ("tau_min", "tau_max", "energy_guard")
              if getattr(steps, name) is not None}
    if steps.breakdown != "stop":
        unused["breakdown"] = steps.breakdown
    if unused:
        raise InputError(f"march_higher takes tol, max_steps and time_limit of StepControl; "
                         f"{', '.join(f'{k}={v!r}' for k, v in unused.items())} does not apply")


def _check_start(system: HigherOrderSystem, rule: str, t_init, q_init, t_end):
    """The start nodes as arrays ``(2l,)``, ``(2l, n)`` and ``t_end``, checked."""
    l, n = system.order, system.n  # noqa: E741 (l is the order, as in the paper)
    t_init = check_finite_array("t_init", t_init, (2 * l,))
    q_init = _positions("q_init", q_init, 2 * l, n)
    if np.any(np.diff(t_init) <= 0):
        raise InputError(f"t_init must increase, got {t_init.tolist()}")
    if t_end is None:
        raise InputError("give t_end, the time the march reaches")
    t_end = check_real("t_end", t_end)
    if t_end <= t_init[-1]:
        raise InputError(f"t_end must be > the last given node time {t_init[-1]!r}, got "
                         f"{t_end!r}")
    if rule != "fixed" and l < 2:
        raise InputError("march_higher's energy rule needs order >= 2; first-order Lagrangians "
                         "march with ddvp_nlp.march (LagrangianSystem)")
    return t_init, q_init, t_end


class _HigherSteps:
    """Stepper (``driver.py``) of `march_higher`, one step per call; the nodes' ``z`` is
    ``q``.

    With the energy rule the newest node is *pending*: only its difference
    ``u = (q_{k+l} - q_{k+l-1}) / tau`` is known, kept here with the step ``tau`` that produced
    it; the driver's nodes are the complete ones. A step is accepted only if finite, ``tau > 0``
    and its residuals are under ``tol`` relative to the magnitudes they are computed from (no
    floor of 1 in the units of ``q`` or of ``L``): the Euler-Lagrange rows (in the units of
    ``q``) against ``max(|q|_inf of the window, Z)``, ``Z`` the given nodes' ``|q|_inf`` joined
    with their largest difference (a start at ``q = 0`` is judged against its motion); the
    energy row against ``max(L_s, L_0)``, ``L_s`` the largest ``|L| + sum_j |v^(j) .
    dL/dv^(j)|`` of the window's intervals (at least ``|E|`` of a natural Lagrangian, and
    nonzero where ``L`` passes 0) and ``L_0`` that of the first step's window."""

    def __init__(self, system: HigherOrderSystem, rule: str, theta, tol: float, h: float,
                 pending=None, z_scale: float = 0.0):
        self.functions = _step_functions(system, rule)
        self.root, self.check = self.functions.root, self.functions.check
        self.l, self.n, self.theta, self.tol, self.h = system.order, system.n, theta, tol, h
        self.z_scale, self.energy_scale = z_scale, None
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
            x = self.functions.solve(np.concatenate([self.u, [self.tau]]), w)
            return x, w, x[-1]
        w = np.concatenate([t[-2 * l:], np.ravel(q[-2 * l:]), self.theta])
        x = self.functions.solve(_extrapolate(t[-2 * l:], q[-2 * l:], t[-1] + self.h), w)
        return x, w, self.h

    def _failure(self, x, w, step) -> tuple[Status, str] | None:
        """``(status, detail)`` if the step is not acceptable, else ``None``."""
        if not np.all(np.isfinite(x)):
            return Status.NON_FINITE, ""
        if step <= 0:
            return Status.NO_ADMISSIBLE_STEP, f"Newton found tau = {step:.6g}"
        el, energy, size, energy_size = (float(v) for v in self.check(x, w))
        if self.energy_scale is None:  # the first step's window: the run's scale of L
            self.energy_scale = energy_size if np.isfinite(energy_size) else 0.0
        if el > self.tol * max(size, self.z_scale) or \
                abs(energy) > self.tol * max(energy_size, self.energy_scale):
            converged = self.root.stats().get("return_status") == "success"
            return (Status.RESIDUAL_TOO_LARGE if converged else Status.NEWTON_FAILED,
                    f"Euler-Lagrange residual {el:.3e}, energy residual {energy:.3e}")
        return None


@answers_removed_keywords
def march_higher(system: HigherOrderSystem, t_init, q_init, t_end: float | None = None, *,
                 scheme: str = "vddvp", params=None, steps: StepControl | None = None,
                 accuracy: Tolerance | None = DEFAULT_TOLERANCE) -> Solution:
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
    only if finite, ``tau > 0`` and its residuals are under ``steps.tol`` (the Euler-Lagrange
    rows scaled by ``tau^(2l-1)``, in the units of ``q``). Steps are counted from the last
    given node: ``steps.max_steps`` bounds the nodes after the first ``2l``;
    ``steps.time_limit`` the seconds of stepping. ``steps`` defaults to ``StepControl()``, as
    for ``march``; its step bounds and breakdown do not apply here and are refused.

    ``accuracy``: the accuracy check (``accuracy/positions.py``: every step and the trajectory
    against the exact Euler-Lagrange flow through the start nodes, or ``accuracy.exact``);
    ``None`` leaves it out.
    """
    _check_system(system)
    steps = coerce(steps, StepControl, "steps")
    _check_steps(steps)
    rule = check_rule(system, scheme)
    t_init, q_init, t_end = _check_start(system, rule, t_init, q_init, t_end)
    tol, max_steps, time_limit = steps.tol, steps.max_steps, steps.time_limit
    if accuracy is not None:
        accuracy = coerce(accuracy, Tolerance, "accuracy")
    theta = system.parameter_vector(params)
    started = time.perf_counter()
    h = t_init[-1] - t_init[-2]
    z_scale = float(max(np.max(np.abs(q_init)), np.max(np.abs(np.diff(q_init, axis=0)))))
    if rule != "fixed":  # the last given node is pending: only its difference is kept
        stepper = _HigherSteps(system, rule, theta, tol, h, ((q_init[-1] - q_init[-2]) / h, h),
                               z_scale)
        nodes = Nodes(t_init[:-1], q_init[:-1])
    else:
        stepper = _HigherSteps(system, rule, theta, tol, h, z_scale=z_scale)
        nodes = Nodes(t_init, q_init)
    built = time.perf_counter()
    outcome = drive(stepper, nodes, t_end=t_end, max_steps=max_steps, time_limit=time_limit,
                    step_offset=2 * system.order - 1)
    solution = _higher_solution(system, outcome.t, outcome.z, theta, outcome.status,
                                outcome.message, rule, {"build_s": built - started,
                                                        "solve_s": time.perf_counter() - built},
                                {})
    if accuracy is not None:
        _judge(solution, system, theta, accuracy, compiler=find_compiler("auto"))
    return solution


def _extrapolate(t, q, t_new):
    """Polynomial through the window's nodes, evaluated at ``t_new`` (the predictor)."""
    degree = min(len(t) - 1, 3)
    return np.array([np.polyval(np.polyfit(t - t[-1], q[:, i], degree), t_new - t[-1])
                     for i in range(q.shape[1])])


@dataclass(frozen=True)
class _StepFunctions:
    """One march step's Newton in relative unknowns ``xi`` (``root(xi0, w) -> xi``), its
    residual check on ``x`` and the maps between ``x`` and ``xi``."""

    root: object
    check: object
    to_x: object
    to_xi: object

    def solve(self, x0: np.ndarray, w: np.ndarray) -> np.ndarray:
        xi = self.root(np.asarray(self.to_xi(x0, w)).ravel(), w)
        return np.asarray(self.to_x(xi, w)).ravel()


def _step_functions(system: HigherOrderSystem, rule: str):
    """Newton for one march step (see `march_higher`) and its residual check."""
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
    scaled = el * (tw[-1] - tw[-2]) ** (2 * l - 1)  # O(1) in tau
    # ... in the units of q: divided by its largest derivative in the new node's unknowns (a
    # number in the units of L per q^2 times powers of the step; a Lagrangian in other units of
    # q, time or energy scales it), so that the rows read as a position whatever the units
    reach = ca.norm_inf(ca.jacobian(scaled, x[:n]))
    positions = scaled / reach
    sizes = _energy_size(system, theta)
    energy_size = 0
    for k, v in enumerate(differences(l, q_nodes, t_nodes)):
        energy_size = ca.fmax(energy_size, sizes(q_nodes[k], *v, t_nodes[k], theta))
    energy_size = ca.substitute(energy_size, ca.vertcat(q_k, t_k), at)  # node l of the window
    # Newton's rows relative to the window's magnitudes (its |q| and the size of L), so that
    # its absolute tolerance is a relative one: 1e-13 of 1 had stopped every step in lengths
    # of 1e-8 or time units of 1e5 (RESIDUAL_TOO_LARGE at the fourth node)
    magnitude = ca.fmax(ca.norm_inf(qw), ca.norm_inf(qw[n:] - qw[:-n]) if known > 1 else 0)
    relative = positions / magnitude
    g = ca.vertcat(relative, energy / energy_size) if variable else relative
    # ... and its unknowns too, ``x = origin + scale xi`` (the last node, or the last difference
    # and step; the window's magnitude, per step for a difference), so that its step tolerance
    # (abstolStep, absolute) is a relative one as well
    if variable:
        h = tw[-1] - tw[-2]
        origin = ca.vertcat(u_prev, h)
        scale = ca.vertcat(ca.repmat(magnitude / h, n, 1), h)
    else:
        origin, scale = qw[-n:], ca.repmat(magnitude, n, 1)
    xi = ca.SX.sym("xi", x.numel())
    moved = origin + scale * xi
    root = ca.rootfinder("higher_step", "newton",
                         ca.Function("g", [xi, w], [ca.substitute(g, x, moved)]),
                         dict(HIGHER_STEP_NEWTON))
    check = ca.Function("check", [x, w], [ca.norm_inf(positions),
                                         energy if variable else ca.SX(0), ca.norm_inf(qw),
                                         energy_size])
    to_x = ca.Function("to_x", [xi, w], [moved])
    to_xi = ca.Function("to_xi", [x, w], [(x - origin) / scale])
    return _StepFunctions(root, check, to_x, to_xi)


def _energy_size(system: HigherOrderSystem, theta) -> ca.Function:
    """``|L| + sum_j |v^(j) . dL/dv^(j)|`` at one interval: the magnitudes the energy row
    (the action's derivative in a node time) is made of; for ``L = T - V`` with ``T``
    quadratic in ``v^(1)`` it is ``|T - V| + 2T >= |T + V|``, the energy."""
    n, l = system.n, system.order  # noqa: E741 (l is the order, as in the paper)
    q, t = ca.SX.sym("q", n), ca.SX.sym("t")
    vs = [ca.SX.sym(f"v{j + 1}", n) for j in range(l)]
    L = system.L_function(q, *vs, t, theta)
    size = ca.fabs(L)
    for v in vs:
        size = size + ca.fabs(ca.dot(v, ca.gradient(L, v)))
    return ca.Function("energy_size", [q, *vs, t, theta], [size])
