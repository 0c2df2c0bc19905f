"""The solves and the verification of a higher-order fixed-endpoint problem (``stepping.py``).

A `GridRequest` whose ``data`` is a `FixedNodes`
holds the validated inputs; `solve_rule` solves the system of one rule (``fixed`` on
uniform times, or an energy rule with the interior times released) from a point by

- ``"newton"``: the grid's Newton (``grid/newton.py``: line search with the
  ``DecreaseOrMonotonicity`` test, ``tau_floor`` safeguard, banded LU) on the window assembly of
  ``windows.py``, through a Newton homotopy where plain Newton does not converge
  (`continuation`);
- ``"ipopt"``: the grid's IPOPT build on an MX graph of the window gradient mapped over the
  grid (``window_nlp.py``: no expression grows with ``N``; CasADi's derivatives of it), the
  equations as equalities and ``t_{k+1} - t_k >= tau_floor``;
- ``"auto"``: Newton, then IPOPT from the same start if Newton's point fails the verification.

Verification decides, whatever the solver said (`verify`): a point is a solution when every
Euler-Lagrange row (scaled by the mean step to the power ``2l - 1``) and every energy row (the
action's derivative in a node time) is below ``max(tol r_i, c_i)``, ``r_i = |F_i'(x)| s`` how
far the row moves when the unknowns move by their sizes ``s`` in the data (a position by its
coordinate's range over the fixed nodes, a time by the mean step: `fixed_nodes.data_sizes`), in
the row's own units whatever those of ``q``, of time or of ``L``; and every step is positive
(``max(1, |q_data|)`` and ``max(1, tau_mean)`` had stopped Pais-Uhlenbeck in lengths of ``1e-8``
``3e-6`` of its motion short, verified). ``c_i`` is
``ROUND_OFF_BOUNDS`` times a bound on row ``i``'s round-off: machine epsilon times the sum of
the terms added into the row plus ``|F'(x)|`` times the data's magnitudes (each input's rounding
carried through the row's differences, whose ``1/tau`` factors amplify it: at N = 1e3 of the
spline the energy rows' derivatives in the node times are ~1e9); the magnitudes are the data's
(``max(|q_start|, |q_stop|)`` for positions, ``max |t|`` of the fixed nodes for times), not
the point's, so that a diverged iterate does not excuse itself. The message quotes what the
solver said.
"""

from __future__ import annotations

import time

import numpy as np

from ...solution import Status
from ..grid.linear import band_kernel
from ..grid.maps import chunked
from ..grid.newton import DECREASE_OR_MONOTONICITY, newton
from ..grid.policy import Attempt, Stage, failure_status, solve_in_order, solver_order
from ..grid.problem import GridRequest
from .fixed_nodes import (
    FixedNodes,
    data_scale,
    data_sizes,
    el_scale,
    ends,
    magnitudes,
    order,
)
from .window_nlp import higher_ipopt
from .windows import HigherAssembly, HigherEnds

EPS = np.finfo(float).eps
# The round-off bound of a row (``HigherAssembly.round_off`` times machine epsilon: every input's
# rounding carried through the row in absolute value) is a worst case, not a typical error:
# Newton aims at TARGET_BOUNDS of it, verification allows ROUND_OFF_BOUNDS. With 1024 (the
# first-order allowance of ``solvers/bvp/phases.py``, whose scale is |E|, not a bound) IPOPT's
# last iterate
# on the spline's released times at N = 1e3 (500 iterations, Maximum_Iterations_Exceeded), its
# steps still uniform to 1 % and its energy rows at 2.7e-5, passed: 15 times the bound there.
TARGET_BOUNDS = 1
ROUND_OFF_BOUNDS = 16
# Newton's iterations per homotopy stage, and the smallest stage in lambda (``continuation``).
STAGE_ITERATIONS = 25
SMALLEST_STAGE = 1e-4
# An intermediate stage (lambda < 1) is solved to this many targets only: its point is a start.
STAGE_SLACK = 1e4
# A point whose positions exceed the data's magnitude this many times has diverged.
DIVERGED = 1e8


def assembly(request: GridRequest[FixedNodes], rule: str) -> HigherAssembly:
    variable = rule != "fixed"
    scale = el_scale(request)
    return request.built(("higher_assembly", variable, request.nodes, scale),
                         lambda: HigherAssembly(request.system, rule, request.nodes, scale))


def solve_rule(request: GridRequest[FixedNodes], rule: str, x0: np.ndarray, *,
               stage_iterations: int = STAGE_ITERATIONS):
    """``(x, phase, outcome)``: the system of ``rule`` solved from ``x0`` by the request's
    solver (``"auto"``: Newton, then IPOPT if Newton's point fails the verification); the
    outcome is `verify`'s."""
    def attempt(solver: str) -> Attempt:
        x, stage = _run(request, rule, x0, solver, stage_iterations)
        return Attempt(x, stage, verify(request, rule, x, stage))

    chosen, tried, _ = solve_in_order(solver_order(request.solver), attempt)
    outcome = chosen.outcome
    for other in tried[1:]:
        if chosen is not other:
            outcome = (outcome[0], f"{outcome[1]}; the IPOPT fallback failed too "
                       f"({other.status.code}: {other.stage.quoted})", outcome[2])
    return chosen.x, chosen.stage, outcome


def _run(request: GridRequest[FixedNodes], rule: str, x0: np.ndarray, solver: str,
         stage_iterations: int):
    """One solver on one rule's system; its `Stage` records what the solver said."""
    started = time.perf_counter()
    if solver == "newton":
        grid = assembly(request, rule)
        pinned = ends(request, rule)
        x, converged, said, iterations = continuation(request, grid, pinned, x0, rule,
                                                      stage_iterations)
        x = np.where(grid.derived, x, pinned.given)  # the pins' own rows, held exactly
    else:
        x, converged, said, iterations = higher_ipopt(request, rule, x0)
    stage = Stage(rule, solver, converged, said, iterations, time.perf_counter() - started)
    request.phases.append(stage)
    return x, stage


def continuation(request: GridRequest[FixedNodes], grid: HigherAssembly, pinned: HigherEnds,
                 x0, rule: str, stage_iterations: int = STAGE_ITERATIONS):
    """``(x, converged, said, iterations)``: `newton` on ``F(x) = 0`` from ``x0``,
    through the Newton homotopy ``F(x) = (1 - lambda) F(x0)`` when a full step in ``lambda``
    does not converge within ``stage_iterations``.

    ``lambda`` starts at 0 (``x0`` solves it) and advances by ``d``, starting at 1 (plain
    Newton); a stage that converges doubles ``d``, one that does not divides it by 4 and
    restarts from the last converged point. On the spline's released times plain Newton crawled
    (the ``tau_floor`` safeguard cut the steps: the released steps end far from uniform, 0.032
    to 0.16); the homotopy converges (see the tests for the counts)."""
    target = TARGET_BOUNDS * EPS * grid.round_off(x0, pinned, magnitudes(request))
    tau_floor = request.tau_floor if rule != "fixed" else -np.inf
    F0, _ = grid.evaluate(x0, pinned, jacobian=False)
    kernel = band_kernel(request.compilation)
    lam, d, x, total, stages, said = 0.0, 1.0, np.array(x0, float), 0, 0, ""
    limit = min(request.max_iter, stage_iterations)
    closest = (np.inf, x)
    while lam < 1.0 and d >= SMALLEST_STAGE and total < request.max_iter:
        trial = min(1.0, lam + d)
        stage_target = target if trial == 1.0 else STAGE_SLACK * target
        result = newton(grid, x, pinned, stage_target, tau_floor=tau_floor,
                        max_iter=min(limit, request.max_iter - total), linear=request.linear,
                        kernel=kernel, deadline=request.deadline,
                        test=DECREASE_OR_MONOTONICITY, offset=(1.0 - trial) * F0)
        total, stages, said = total + result.iterations, stages + 1, result.outcome
        if trial == 1.0 and min(result.residual_norms, default=np.inf) < closest[0]:
            closest = (min(result.residual_norms), result.x)  # the nearest to a root yet
        if result.converged:
            lam, x, d = trial, result.x, 2 * d
        else:
            d /= 4
    if lam < 1.0:
        x = closest[1]
        said = (f"not converged: the homotopy reached lambda = {lam:.6g} of 1 in {stages} "
                f"stages (last: {said}); the point returned is the closest to a root met")
    elif stages > 1:
        said = f"{said} (homotopy from the start: {stages} stages)"
    return x, lam == 1.0, said, total


def verify(request: GridRequest[FixedNodes], rule: str, x: np.ndarray, phase: Stage):
    """``(status, message, residuals)`` of the point ``x`` (module docstring)."""
    said = phase.quoted
    if "iterations" not in phase.said:  # Newton's own words count them already
        said += f", {phase.iterations} iterations"
    n = request.system.n
    N, m, l = request.nodes, n + 1, order(request)  # noqa: E741 (the order)
    empty = {"euler_lagrange_residual": np.full((N - 2 * l) * n, np.nan),
             "energy_equation_residual": np.full(N - 2 * l if rule != "fixed" else 0, np.nan)}
    if not np.all(np.isfinite(x)):
        return Status.NON_FINITE, f"diverged: the solver returned non-finite values ({said})", \
            empty
    t = x.reshape(N, m)[:, 0]
    size = float(np.max(np.abs(x.reshape(N, m)[:, 1:])))
    scale = data_scale(request)
    if size > DIVERGED * scale:
        return Status.SOLVER_FAILED, (f"diverged: |q| reached {size:.3e} where the data's "
                                      f"magnitude is {scale:.3g} ({said})"), empty
    grid, pinned = assembly(request, rule), ends(request, rule)
    F, _ = grid.evaluate(x, pinned, jacobian=False)
    values = magnitudes(request)
    allowance = ROUND_OFF_BOUNDS * EPS * grid.round_off(x, pinned, values)
    limit = np.maximum(request.tol * grid.response(x, pinned, data_sizes(request)), allowance)
    el, energy = np.abs(F[grid.free_q]), np.abs(F[grid.free_t]) if rule != "fixed" else \
        np.zeros(0)
    residuals = {"euler_lagrange_residual": el, "energy_equation_residual": energy,
                 "euler_lagrange_limit": float(np.max(limit[grid.free_q])),
                 "energy_limit": float(np.max(limit[grid.free_t], initial=0.0))
                 if rule != "fixed" else 0.0}
    moved = np.abs(x - pinned.given)[~grid.derived] / (
        ROUND_OFF_BOUNDS * EPS * values[~grid.derived])
    problems = _problems(t, el, limit[grid.free_q], energy, limit[grid.free_t], moved, l)
    detail = (f"largest residuals: Euler-Lagrange {el.max(initial=0):.3e} (times mean "
              f"step^{2 * l - 1}), energy {energy.max(initial=0):.3e}; {said}")
    if not problems:
        return Status.SUCCESS, f"solved and verified: {detail}", residuals
    status = failure_status(phase, np.diff(t))
    return status, f"{status.value}: {'; '.join(problems)}; {detail}", residuals


def _problems(t, el, el_limit, energy, energy_limit, pinned, order) -> list[str]:
    """What the point fails, in words."""
    problems = []
    tau = np.diff(t)
    if np.min(tau) <= 0:
        k = int(np.argmin(tau))
        problems.append(f"step {k} is not positive: tau = {tau[k]:.6g} (t = {t[k]:.10g})")
    if np.any(el > el_limit):
        i = int(np.argmax(el / el_limit))
        problems.append(f"Euler-Lagrange residual {el[i]:.3e} above its limit "
                        f"{el_limit[i]:.3e}")
    if energy.size and np.any(energy > energy_limit):
        k = int(np.argmax(energy / energy_limit))
        problems.append(f"energy residual {energy[k]:.3e} at node {k + order} above its limit "
                        f"{energy_limit[k]:.3e}")
    if pinned.size and np.max(pinned) > 1:
        problems.append(f"a fixed value moved by {np.max(pinned):.3g} times its round-off "
                        f"allowance")
    return problems


def grid_energies(system, t, q, theta) -> tuple[np.ndarray, np.ndarray]:
    """``discrete.higher.energies`` vectorised over the grid: multipliers ``lambda_1^(k)``
    ``(K, n)`` and energies ``E^(k)`` ``(K,)`` for ``k = l-1 .. N-1-l``, with ``L`` and its
    partials evaluated by one mapped call per window of blocks (``ChunkedMap``) instead of one
    CasADi call per node (6.3 s of a 7 s solve at N = 3e4, measured)."""
    l, n = system.order, system.n  # noqa: E741 (l is the order, as in the paper)
    t = np.asarray(t, float)
    q = np.asarray(q, float).reshape(t.size, n)
    count = t.size - l
    if count < l:
        return np.zeros((0, n)), np.zeros(0)
    tau = np.diff(t)
    levels = [q]
    for _ in range(l):
        levels.append(np.diff(levels[-1], axis=0) / tau[:levels[-1].shape[0] - 1, None])
    v = [levels[m][:count] for m in range(1, l + 1)]
    blocks = [q[:count], *v, t[:count, None]]
    theta = np.asarray(theta, float)
    partials = [p.reshape(count, n) for p in
                chunked(system, ("higher_L_v",), system.L_v_function)(blocks, theta, count)]
    L = chunked(system, ("higher_L",), system.L_function)(blocks, theta, count)[0].ravel()
    lam = [None] * l
    lam[l - 1] = partials[l - 1]
    for m in range(l - 2, -1, -1):  # lambda_m from lambda_{m+1} at k and k - 1
        lam[m] = np.full((count, n), np.nan)
        lam[m][1:] = partials[m][1:] - (lam[m + 1][1:] - lam[m + 1][:-1]) / tau[1:count, None]
    defined = slice(l - 1, count)
    E = sum(np.einsum("ki,ki->k", lam[m][defined], v[m][defined]) for m in range(l)) - \
        L[defined]
    return lam[0][defined].copy(), E
