"""The solves and the verification of a higher-order fixed-endpoint problem (``higher.py``).

A :class:`HigherRequest` holds the validated inputs; :func:`solve_rule` solves the system of one
rule (``fixed`` on uniform times, or an energy rule with the interior times released) from a
point by

- ``"newton"``: ``bvp_newton.newton`` (line search, ``tau_floor`` safeguard, banded LU) on the
  window assembly of ``higher_assembly.py``;
- ``"ipopt"``: IPOPT on an MX graph of the window gradient mapped over the grid (no expression
  grows with ``N``; CasADi's derivatives of it), the equations as equalities and ``t_{k+1} -
  t_k >= tau_floor``;
- ``"auto"``: Newton, then IPOPT from the same start if Newton's point fails the verification.

Verification decides, whatever the solver said (:func:`verify`): a point is a solution when every
Euler-Lagrange row (scaled by the mean step to the power ``2l - 1``, in the units of ``q``) is
below ``max(tol max(1, |q_data|), c_i)``, every energy row (the action's derivative in a node
time) below ``max(tol max(1, tau_mean), c_i)``, and every step is positive. ``c_i`` is
``ROUND_OFF_BOUNDS`` times a bound on row ``i``'s round-off: machine epsilon times the sum of
the terms added into the row plus ``|F'(x)|`` times the data's magnitudes (each input's rounding
carried through the row's differences, whose ``1/tau`` factors amplify it: at N = 1e3 of the
spline the energy rows' derivatives in the node times are ~1e9); the magnitudes are the data's
(``max(1, |q_start|, |q_stop|)`` for positions, ``max |t|`` of the fixed nodes for times), not
the point's, so that a diverged iterate does not excuse itself. The message quotes what the
solver said.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ...solution import Status
from ..bvp.assembly import chunked
from ..bvp.phase import EPS, built
from ..grid.newton import FLOOR_FACTOR, Factorization, NewtonResult, largest_admissible_step
from .assembly import HigherAssembly, HigherEnds, window_functions

SOLVERS = ("auto", "newton", "ipopt")
# The round-off bound of a row (``HigherAssembly.round_off`` times machine epsilon: every input's
# rounding carried through the row in absolute value) is a worst case, not a typical error:
# Newton aims at TARGET_BOUNDS of it, verification allows ROUND_OFF_BOUNDS. With 1024 (the
# first-order allowance of ``bvp_phase``, whose scale is |E|, not a bound) IPOPT's last iterate
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


@dataclass
class HigherRequest:
    """The validated inputs of one ``solve_bvp_higher`` call; ``t_start`` ... as in
    ``higher._Ends``."""

    system: object
    t_start: np.ndarray
    q_start: np.ndarray
    t_stop: np.ndarray
    q_stop: np.ndarray
    nodes: int
    theta: np.ndarray
    tol: float
    tau_floor: float
    solver: str
    max_iter: int
    build_s: float = 0.0
    phases: list = field(default_factory=list)

    @property
    def order(self) -> int:
        return self.system.order

    @property
    def n(self) -> int:
        return self.system.n

    @property
    def uniform(self) -> np.ndarray:
        """Every node time on uniform steps between the fixed ones."""
        l, N = self.order, self.nodes  # noqa: E741 (l is the order, as in the paper)
        inner = np.linspace(self.t_start[-1], self.t_stop[0], N - 2 * l + 2)[1:-1]
        return np.concatenate([self.t_start, inner, self.t_stop])

    @property
    def mean(self) -> float:
        return (self.t_stop[0] - self.t_start[-1]) / (self.nodes - 2 * self.order + 1)

    @property
    def el_scale(self) -> float:
        """The Euler-Lagrange rows' factor: an EL row ~ dq / tau^(2l-1)."""
        return self.mean ** (2 * self.order - 1)

    @property
    def data_scale(self) -> float:
        return float(max(1.0, np.max(np.abs(self.q_start)), np.max(np.abs(self.q_stop))))

    def straight(self) -> np.ndarray:
        """Positions interpolated linearly between the ends, on uniform times, packed."""
        t, times = self.uniform, np.concatenate([self.t_start, self.t_stop])
        q = np.column_stack([np.interp(t, times, np.concatenate([self.q_start[:, i],
                                                                  self.q_stop[:, i]]))
                             for i in range(self.n)])
        return np.column_stack([t, q]).ravel()

    def ends(self, rule: str) -> HigherEnds:
        """The pinned values: the ``l`` end nodes, and for ``fixed`` every node time."""
        l, m = self.order, self.n + 1  # noqa: E741 (l is the order, as in the paper)
        given = np.zeros((self.nodes, m))
        given[:l, 0], given[:l, 1:] = self.t_start, self.q_start
        given[-l:, 0], given[-l:, 1:] = self.t_stop, self.q_stop
        if rule == "fixed":
            given[:, 0] = self.uniform
        return HigherEnds(given.ravel(), self.theta)

    def magnitudes(self) -> np.ndarray:
        """Each value's magnitude for the round-off estimate (module docstring)."""
        m = self.n + 1
        values = np.full((self.nodes, m), self.data_scale)
        values[:, 0] = float(np.max(np.abs(np.concatenate([self.t_start, self.t_stop]))))
        return values.ravel()


def assembly(request: HigherRequest, rule: str) -> HigherAssembly:
    variable = rule != "fixed"
    return built(request, ("higher_assembly", variable, request.nodes, request.el_scale),
                  lambda: HigherAssembly(request.system, rule, request.nodes, request.el_scale))


def solve_rule(request: HigherRequest, rule: str, x0: np.ndarray):
    """``(x, phase, outcome)``: the system of ``rule`` solved from ``x0`` by the request's
    solver (``"auto"``: Newton, then IPOPT if Newton's point fails the verification); the
    outcome is :func:`verify`'s."""
    first = "ipopt" if request.solver == "ipopt" else "newton"
    x, phase = _run(request, rule, x0, first)
    outcome = verify(request, rule, x, phase)
    if request.solver == "auto" and outcome[0] is not Status.SUCCESS:
        x_ipopt, phase_ipopt = _run(request, rule, x0, "ipopt")
        fallback = verify(request, rule, x_ipopt, phase_ipopt)
        if fallback[0] is Status.SUCCESS:
            return x_ipopt, phase_ipopt, fallback
        outcome = (outcome[0], f"{outcome[1]}; the IPOPT fallback failed too "
                   f"({fallback[0].code}: ipopt: {phase_ipopt['return_status']})", outcome[2])
    return x, phase, outcome


def _run(request: HigherRequest, rule: str, x0: np.ndarray, solver: str):
    """One solver on one rule's system; ``phase`` records what the solver said."""
    started = time.perf_counter()
    if solver == "newton":
        grid = assembly(request, rule)
        ends = request.ends(rule)
        x, converged, said, iterations = continuation(request, grid, ends, x0, rule)
        x = np.where(grid.derived, x, ends.given)  # the pins' own rows, held exactly
    else:
        x, converged, said, iterations = _ipopt(request, rule, x0)
    phase = {"phase": rule, "solver": solver, "converged": converged, "return_status": said,
             "iterations": iterations, "seconds": time.perf_counter() - started}
    request.phases.append(phase)
    return x, phase


class _Shifted:
    """The assembly of ``F(x) - offset`` (the Newton homotopy's system at one ``lambda``)."""

    def __init__(self, grid: HigherAssembly, offset: np.ndarray):
        self.grid, self.offset, self.layout = grid, offset, grid.layout

    def evaluate(self, x, ends, jacobian=True):
        F, values = self.grid.evaluate(x, ends, jacobian)
        return F - self.offset, values

    def banded(self, values):
        return self.grid.banded(values)

    def sparse(self, values):
        return self.grid.sparse(values)


def newton(grid, x0: np.ndarray, ends: HigherEnds, target: np.ndarray, *, tau_floor: float,
           max_iter: int) -> NewtonResult:
    """Newton's method on ``F(x) = 0`` with the ``tau_floor`` safeguard of ``bvp_newton`` (the
    step ``alpha <= 0.99 alpha_max`` keeps every step above ``tau_floor``) and a backtracking
    line search (:func:`_line_search`); the LU factors are ``bvp_newton``'s. Returns the best
    iterate (weighted residual norm), converged when every row is at its target or, when no
    step decreases the residual any more, within ``FLOOR_FACTOR`` targets (its round-off floor).

    Not ``bvp_newton.newton``: its natural monotonicity test alone measures ``F(x + dx)``
    through ``F'(x)^-1``, and on these systems ``F'`` has condition ``~N^4`` (a fourth
    difference): at N = 1e5 of the spline the round-off of ``F`` at the exact step, carried
    through ``F'^-1``, exceeded the step itself, and every step was rejected from the straight
    line (residual left at 1e-5, measured), where the full step takes the residual to
    round-off. The weighted residual norm alone, in turn, took Pais-Uhlenbeck's released times
    through 19 homotopy stages (310 iterations) where either test takes 11."""
    x = np.array(x0, float)
    F, values = grid.evaluate(x, ends)
    weight = 1.0 / target
    norm = _weighted(F, weight)
    result = NewtonResult(x, False, "", 0, [norm])
    best = (norm, x, F)
    for iteration in range(1, max_iter + 1):
        if np.all(np.abs(F) <= target):
            result.x, result.converged = x, True
            result.outcome = f"converged: every residual at its target after {iteration - 1} " \
                             f"iterations"
            return result
        if values is None:  # the Jacobian at x, evaluated only once x is known not to be done
            F, values = grid.evaluate(x, ends)
        lu = Factorization(grid, values, "auto")
        dx = lu.solve(-F)
        if not np.all(np.isfinite(dx)):
            result.outcome = f"singular Jacobian at iteration {iteration}"
            break
        step = _line_search(grid, lu, x, dx, ends, weight, norm, tau_floor,
                            near_floor=bool(np.all(np.abs(F) <= FLOOR_FACTOR * target)))
        if step is None:
            result.outcome = f"stalled at iteration {iteration}: no step along the Newton " \
                             f"direction decreases the residual"
            break
        x, F_new, alpha = step
        norm = _weighted(F_new, weight)
        if norm < best[0]:
            best = (norm, x, F_new)
        result.iterations = iteration
        result.residual_norms.append(norm)
        result.step_lengths.append(alpha)
        F, values = F_new, None
    else:
        result.outcome = f"max_iter = {max_iter} reached"
    # the best iterate; at its round-off floor if every row is within FLOOR_FACTOR targets
    norm, result.x, F = best
    ratio = float(np.max(np.abs(F) * weight))
    result.converged = ratio <= FLOOR_FACTOR
    result.outcome = (f"converged: residual at its round-off floor (largest |F_i| / target = "
                      f"{ratio:.2g}) after {result.iterations} iterations" if result.converged
                      else f"{result.outcome}, largest |F_i| / target = {ratio:.3g}")
    return result


def _line_search(grid, lu, x, dx, ends, weight, norm, tau_floor, near_floor):
    """``(x_new, F_new, alpha)`` for the first ``alpha = a_0, a_0/2, ...`` down to 1e-10 that
    decreases the weighted residual norm (Armijo) or passes the natural monotonicity test
    ``|F'(x)^-1 F(x + alpha dx)| <= (1 - alpha/2) |dx|`` (``bvp_newton``'s); ``a_0 = min(1,
    0.99 alpha_max)`` (``tau_floor`` safeguard). ``None`` if none, or if ``a_0`` fails when the
    residual is already near its round-off floor (below that, decreases are noise)."""
    alpha = min(1.0, 0.99 * largest_admissible_step(grid, x, dx, tau_floor))
    size = _weighted(dx, 1.0)
    while alpha >= 1e-10:
        trial = x + alpha * dx
        F_trial, _ = grid.evaluate(trial, ends, jacobian=False)
        if np.all(np.isfinite(F_trial)) and (
                _weighted(F_trial, weight) <= (1 - 1e-4 * alpha) * norm
                or _weighted(lu.solve(-F_trial), 1.0) <= (1 - alpha / 2) * size):
            return trial, F_trial, alpha
        if near_floor:
            return None
        alpha /= 2
    return None


def _weighted(F, weight) -> float:
    with np.errstate(all="ignore"):
        v = F * weight
        return float(np.sqrt(np.einsum("i,i->", v, v)))


def continuation(request: HigherRequest, grid: HigherAssembly, ends: HigherEnds, x0, rule: str):
    """``(x, converged, said, iterations)``: :func:`newton` on ``F(x) = 0`` from ``x0``,
    through the Newton homotopy ``F(x) = (1 - lambda) F(x0)`` when a full step in ``lambda``
    does not converge within ``STAGE_ITERATIONS``.

    ``lambda`` starts at 0 (``x0`` solves it) and advances by ``d``, starting at 1 (plain
    Newton); a stage that converges doubles ``d``, one that does not divides it by 4 and
    restarts from the last converged point. On the spline's released times plain Newton crawled
    (the ``tau_floor`` safeguard cut the steps: the released steps end far from uniform, 0.032
    to 0.16); the homotopy converges (see the tests for the counts)."""
    target = TARGET_BOUNDS * EPS * grid.round_off(x0, ends, request.magnitudes())
    tau_floor = request.tau_floor if rule != "fixed" else -np.inf
    F0, _ = grid.evaluate(x0, ends, jacobian=False)
    lam, d, x, total, stages, said = 0.0, 1.0, np.array(x0, float), 0, 0, ""
    limit = min(request.max_iter, STAGE_ITERATIONS)
    closest = (np.inf, x)
    while lam < 1.0 and d >= SMALLEST_STAGE and total < request.max_iter:
        trial = min(1.0, lam + d)
        stage_target = target if trial == 1.0 else STAGE_SLACK * target
        result = newton(_Shifted(grid, (1.0 - trial) * F0), x, ends, stage_target,
                        tau_floor=tau_floor, max_iter=min(limit, request.max_iter - total))
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


def verify(request: HigherRequest, rule: str, x: np.ndarray, phase: dict):
    """``(status, message, residuals)`` of the point ``x`` (module docstring)."""
    said = f"{phase['solver']}: {phase['return_status']}"
    if "iterations" not in phase["return_status"]:  # Newton's own words count them already
        said += f", {phase['iterations']} iterations"
    N, m, l = request.nodes, request.n + 1, request.order  # noqa: E741 (the order)
    empty = {"euler_lagrange_residual": np.full((N - 2 * l) * request.n, np.nan),
             "energy_equation_residual": np.full(N - 2 * l if rule != "fixed" else 0, np.nan)}
    if not np.all(np.isfinite(x)):
        return Status.NON_FINITE, f"diverged: the solver returned non-finite values ({said})", \
            empty
    t = x.reshape(N, m)[:, 0]
    size = float(np.max(np.abs(x.reshape(N, m)[:, 1:])))
    if size > DIVERGED * request.data_scale:
        return Status.SOLVER_FAILED, (f"diverged: |q| reached {size:.3e} where the data's "
                                      f"magnitude is {request.data_scale:.3g} ({said})"), empty
    grid, ends = assembly(request, rule), request.ends(rule)
    F, _ = grid.evaluate(x, ends, jacobian=False)
    allowance = ROUND_OFF_BOUNDS * EPS * grid.round_off(x, ends, request.magnitudes())
    limit = np.maximum(np.where(grid.free_q, request.tol * request.data_scale,
                                request.tol * max(1.0, request.mean)), allowance)
    el, energy = np.abs(F[grid.free_q]), np.abs(F[grid.free_t]) if rule != "fixed" else \
        np.zeros(0)
    residuals = {"euler_lagrange_residual": el, "energy_equation_residual": energy,
                 "euler_lagrange_limit": float(np.max(limit[grid.free_q])),
                 "energy_limit": float(np.max(limit[grid.free_t], initial=0.0))
                 if rule != "fixed" else 0.0}
    pinned = np.abs(x - ends.given)[~grid.derived] / (
        ROUND_OFF_BOUNDS * EPS * request.magnitudes()[~grid.derived])
    problems = _problems(t, el, limit[grid.free_q], energy, limit[grid.free_t], pinned, l)
    detail = (f"largest residuals: Euler-Lagrange {el.max(initial=0):.3e} (times mean "
              f"step^{2 * l - 1}), energy {energy.max(initial=0):.3e}; {said}")
    if not problems:
        return Status.SUCCESS, f"solved and verified: {detail}", residuals
    if not phase["converged"]:
        status = Status.SOLVER_FAILED
    elif np.min(np.diff(t)) <= 0:
        status = Status.NO_ADMISSIBLE_STEP
    else:
        status = Status.NOT_VERIFIED
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


# --- IPOPT on the mapped window gradient -------------------------------------------------

def _ipopt(request: HigherRequest, rule: str, x0: np.ndarray):
    """``(x, converged, said, iterations)`` of IPOPT from ``x0`` (packed like Newton's)."""
    solver, free = built(request, ("higher_ipopt", rule != "fixed", request.nodes,
                                    request.tol, request.max_iter),
                          lambda: _ipopt_problem(request, rule))
    N, n, l = request.nodes, request.n, request.order  # noqa: E741 (the order)
    z = np.array(x0, float).reshape(N, n + 1)
    inner = z[l:N - l]
    guess = inner[:, 1:].ravel()
    variable = rule != "fixed"
    if variable:
        guess = np.concatenate([guess, inner[:, 0]])
    g_size, steps = free * n + (free if variable else 0), N - 1 if variable else 0
    result = solver(x0=guess, lbg=np.r_[np.zeros(g_size), np.full(steps, request.tau_floor)],
                    ubg=np.r_[np.zeros(g_size), np.full(steps, np.inf)])
    stats = solver.stats()
    found = np.asarray(result["x"]).ravel()
    z[l:N - l, 1:] = found[:free * n].reshape(free, n)
    if variable:
        z[l:N - l, 0] = found[free * n:]
    return z.ravel(), bool(stats.get("success")), str(stats.get("return_status")), \
        int(stats.get("iter_count", 0))


def _ipopt_problem(request: HigherRequest, rule: str):
    """The NLP: unknowns the free positions (node by node) then, for an energy rule, their
    times; constraints the Euler-Lagrange rows (scaled as in the verification), the energy rows
    and the steps. MX: the window gradient (``higher_assembly.window_functions``) mapped over the
    grid and added node by node by ``l + 1`` shifted slices, so that no expression grows with
    ``N`` (the SX expression of the whole action it replaces took 7.8 s to build at N = 1e4 of
    the spline, this 1.9 s, measured); IPOPT's derivatives are CasADi's of that graph."""
    l, n, N = request.order, request.n, request.nodes  # noqa: E741 (the order)
    m, free, K = n + 1, N - 2 * l, N - l
    variable = rule != "fixed"
    Q = ca.MX.sym("q", n, free)
    T = ca.MX.sym("t", 1, free) if variable else ca.DM(request.uniform[l:N - l]).T
    start = ca.DM(np.column_stack([request.t_start, request.q_start]).T)
    stop = ca.DM(np.column_stack([request.t_stop, request.q_stop]).T)
    Z = ca.horzcat(start, ca.vertcat(T, Q), stop)
    mapped = window_functions(request.system)[2].map(K)
    windows = mapped(*[Z[:, j:j + K] for j in range(l + 1)],
                     ca.repmat(ca.DM(request.theta), 1, K))
    G = 0
    for j in range(l + 1):  # window k's node j is node k + j
        G = G + ca.horzcat(ca.MX(m, j), windows[j * m:(j + 1) * m, :], ca.MX(m, l - j))
    g, unknowns, steps = [ca.vec(G[1:, l:N - l]) * request.el_scale], ca.vec(Q), ca.MX(0, 1)
    if variable:
        g.append(G[0, l:N - l].T)
        unknowns = ca.vertcat(unknowns, T.T)
        steps = (Z[0, 1:] - Z[0, :-1]).T
    solver = ca.nlpsol("bvp_higher", "ipopt",
                       {"x": unknowns, "f": 0, "g": ca.vertcat(*g, steps)},
                       {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                        "ipopt.tol": request.tol * 1e-2,
                        "ipopt.constr_viol_tol": request.tol * 1e-2,
                        "ipopt.max_iter": request.max_iter})
    return solver, free
