"""Starting points of the fixed-endpoint solve (docs/theory.md section 6: the Jacobian's condition
number grows like ``N^2``, so the start must be close).

Default (``guess="straight"``), for grids of any length:

1. the ``fixed`` problem on uniform times, from uniform motion between the endpoints (with
   ``solver="auto"``, IPOPT again if Newton fails; if both fail, the pseudo-arclength
   continuation in the end position from the march of the straight line's momentum,
   ``end_continuation.py``, then this phase from where it ends);
2. the ``fixed`` problem on times with the predicted site density
   ``tau ~ (f' H_zz f)^(-1/3)`` (``predicted_times``), ``f`` the Hamiltonian vector field (the
   paper's section 4 for ``H = p^2/2 + V``: ``f' H_zz f = V'' p^2 + V'^2``; the expansion
   ``H(z_mid) = H(z) - tau^2 f' H_zz f / 8`` gives the same weight for any ``H``);
3. (``fixed_ends.py``) the scheme's equations with the times released.

Released directly from uniform times, Newton diverged at N = 1e5 on the pendulum; from the
predicted times it took 3-4 iterations at N = 1e3, 1e4 and 1e5 (measured).

``guess="march"`` replaces phase 1 by shooting: march ``fixed`` steps on the uniform grid from
``(q_start, p_0)`` and solve ``q_{N-1}(p_0) = q_end`` for ``p_0`` by the grid's Newton
(``grid/newton.py``) on `ShootingProblem`, a grid problem of ``n`` unknowns with a
finite-difference Jacobian (``n + 1`` marches an iteration), a least-squares solve and steps of its
own (`ShootingSteps`), from ``p_start`` if given, else from the straight line's momentum. The
fixed-endpoint problem can have several solutions (a pendulum that swings once or twice between the
same positions); shooting from the straight line's momentum picks the one the march from that
momentum reaches, which the straight-line start, a trajectory that never turns, can miss. A Kepler
orbit over three periods is one: the straight line between two points near the pericentre leads to
the radial branch (out to r = 4.2 and back), on which the energy rules have no solution (``w < 0``
for ``r < 2``, docs/theory.md section 7); ``p_start`` near the orbit's momentum selects the three
revolutions.

A node guess (a march, a file) of another rule is first moved to the predicted times and solved
with fixed steps there (``_from_nodes``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ...discrete.scheme import Scheme
from ...errors import InputError
from ...physics.hamiltonian import site_density_weight_function
from ...solution import Solution
from ...validation import check_finite_array, check_real
from ..grid.maps import evaluate_blocks
from ..grid.newton import NaturalMonotonicity, newton
from ..grid.policy import Stage
from ..grid.problem import GridRequest
from ..options import Compilation, StepControl
from .end_continuation import continue_in_end_position
from .interleaved import NodeLayout
from .phases import Boundary, assembly, ends, mean_step, newton_targets, run_phase


@dataclass(frozen=True)
class Shooting:
    """The start by shooting (``solve_bvp(..., guess=Shooting(p_start))``; ``guess="march"`` is
    ``Shooting()``): march fixed steps from ``(q_start, p_start)`` and correct ``p_start`` until
    the march ends on ``q_end`` (module docstring). ``p_start``: the momentum shooting starts
    from (default the straight line's); it chooses the branch of a problem with several
    solutions."""

    p_start: object = None


SHOOTING_ITERATIONS = 30
# Relative singular-value cut of the shooting Jacobian (LeastSquares).
SHOOTING_RCOND = 1e-6
# Halvings of a shooting step before the iteration gives up.
SHOOTING_HALVINGS = 8
# Iterations without halving the closest miss before shooting stops.
SHOOTING_STALL = 3
# ... once the closest miss is below this (relative to the first march's range of positions,
# `ShootingProblem.size_from`): close enough for
# the fixed-step solve to start on the march's branch. Farther, shooting goes on (the swinging
# pendulum of the tests leaves a local minimum of the miss, 0.049, at its 10th iteration).
SHOOTING_CLOSE = 1e-3


def straight_line(request: GridRequest[Boundary], times) -> dict:
    """Uniform motion between the endpoints: ``q`` linear in ``t``, ``p`` its slope (the
    velocity; for ``H = p^2/2 + V`` the momentum of that motion)."""
    s = (times - times[0]) / (times[-1] - times[0])
    q = (
        request.data.q_start[None, :]
        + s[:, None] * (request.data.q_end - request.data.q_start)[None, :]
    )
    slope = (request.data.q_end - request.data.q_start) / (times[-1] - times[0])
    return {"t": np.asarray(times, float), "q": q, "p": np.repeat(slope[None, :], times.size, 0)}


def first_solver(request: GridRequest[Boundary]) -> str:
    """The solver a start phase tries first: IPOPT if asked for, else Newton."""
    return "ipopt" if request.solver == "ipopt" else "newton"


def fixed_scheme(scheme: Scheme) -> Scheme:
    return Scheme("fixed", alpha=scheme.alpha, clock=scheme.clock)


def start_point(request: GridRequest[Boundary], guess) -> dict:
    """The point the final solve starts from (module docstring); every phase that fails leaves
    the previous phase's point. ``guess`` is ``"straight"``, ``"march"`` or node arrays."""
    if isinstance(guess, dict):
        return _from_nodes(request, guess)
    uniform = request.data.grid_times if not request.scheme.variable_steps else \
        np.linspace(request.data.t0, request.data.t1, request.nodes)
    start = straight_line(request, uniform)
    fixed = fixed_scheme(request.scheme)
    reached, shot = False, None
    if guess == "march":
        shot, reached = shooting(request, fixed, uniform)
        start = shot or start
    solver = first_solver(request)
    if not reached or not request.scheme.variable_steps:
        solved = _solve_fixed(request, fixed, uniform, start, "fixed steps, uniform times",
                              solver)
        whole = np.linspace(request.data.t0, request.data.t1, request.nodes)
        if solved is None and request.remaining() != 0.0 and request.solver != "ipopt" \
                and np.allclose(uniform, whole):
            solved = _continued(request, fixed, uniform, shot if guess == "march" else None,
                                solver)
        start = solved or start
    if not request.scheme.variable_steps:
        return start
    return _at_predicted_times(request, start, "fixed steps, predicted times") or start


# A node guess whose released residuals are all within this many times Newton's targets (a
# march of the same scheme: round-off) starts the released solve as it is; any other is first
# moved to the predicted times and solved with fixed steps there. A small residual is not enough:
# a fixed-step march's energy rows are only O(tau^2) off, 4e-8 at N = 1e5 on kepler e = 0.5, yet
# its node times are far from the released ones (Newton from it hit a 60 s limit; from the
# predicted times it took 2 iterations at N = 1e4; measured).
NEAR_RELEASED = 64


def _from_nodes(request: GridRequest[Boundary], guess: dict) -> dict:
    """The start from the user's nodes (module docstring): as given when they nearly solve the
    released equations (a march of the same scheme), else fixed steps on the predicted times
    first."""
    if not request.scheme.variable_steps:
        return guess
    layout = NodeLayout(request.system.n, request.nodes)
    x = layout.pack(guess["t"], guess["q"], guess["p"])
    grid, data = assembly(request, request.scheme), ends(request, request.scheme)
    F, _ = grid.evaluate(x, data, jacobian=False)
    if np.all(np.abs(F) <= NEAR_RELEASED * newton_targets(request, grid, x, data)):
        return guess
    return _at_predicted_times(request, guess,
                               "fixed steps, predicted times (from the guess)") or guess


def _at_predicted_times(request: GridRequest[Boundary], start: dict, name: str) -> dict | None:
    """``start`` moved to its predicted times and solved there with fixed steps (phase 2);
    ``None`` if that solve does not converge."""
    times = predicted_times(request.system, start["t"], start["q"], start["p"], request.theta,
                            request.compilation)
    moved = {"t": times, "q": interpolate(times, start["t"], start["q"]),
             "p": interpolate(times, start["t"], start["p"])}
    return _solve_fixed(request, fixed_scheme(request.scheme), times, moved, name,
                        first_solver(request))


def _solve_fixed(request, fixed, times, start, name, solver):
    """The fixed-step problem on ``times`` from ``start`` by ``solver``; with ``solver="auto"``
    IPOPT again from the same start when Newton does not converge (Henon-Heiles over 50 time
    units at N = 1e3: Newton stalled on the uniform phase, IPOPT solved it and the rest followed
    in 2 + 2 iterations; measured). ``None`` if it does not converge."""
    layout = NodeLayout(request.system.n, request.nodes)
    x0 = layout.pack(times, start["q"], start["p"])
    x, stage = run_phase(request, fixed, x0, name, solver, times=times)
    if not (stage.converged and np.all(np.isfinite(x))) and request.solver == "auto" \
            and solver == "newton" and request.remaining() != 0.0:
        x, stage = run_phase(request, fixed, x0, name, "ipopt", times=times)
    if not (stage.converged and np.all(np.isfinite(x))):
        return None
    t, q, p = layout.unpack(x)
    return {"t": t, "q": q, "p": p}


def _continued(request: GridRequest[Boundary], fixed: Scheme, times, base, solver) -> dict | None:
    """The fixed-step problem solved after a continuation in its end position
    (``end_continuation.py``) from ``base`` (shooting's closest march) or else from the march
    of the straight line's momentum; ``None`` if either fails."""
    if base is None:
        base = _fixed_march(request, fixed, straight_line(request, times)["p"][0])
    if base is None:
        return None
    near = continue_in_end_position(request, fixed, times, base)
    if near is None:
        return None
    return _solve_fixed(request, fixed, times, near,
                        "fixed steps, uniform times (after the continuation)", solver)


def _march(request: GridRequest[Boundary], fixed: Scheme, p0, theta=None):
    """The march of ``fixed`` steps on the uniform grid of ``request.nodes`` nodes from
    ``(q_start, p0)`` (with the parameters ``theta``, default the request's)."""
    from ..marching import march

    theta = request.theta if theta is None else np.asarray(theta, float)
    params = dict(zip(request.system.params, theta.tolist(), strict=True))
    return march(request.system, request.data.q_start, p0, (request.data.t0, request.data.t1),
                 tau0=mean_step(request), scheme=fixed, params=params,
                 steps=StepControl(tol=min(request.tol, 1e-10), max_steps=request.nodes),
                 compilation=request.compilation)


def _fixed_march(request: GridRequest[Boundary], fixed: Scheme, p0) -> dict | None:
    """`_march`'s nodes, or ``None`` if it does not reach ``t_end`` in ``nodes`` nodes."""
    run = _march(request, fixed, p0)
    return {"t": run.t, "q": run.q, "p": run.p} if _whole(request, run) else None


def _whole(request: GridRequest[Boundary], run) -> bool:
    """Whether the march ``run`` reached ``t_end`` in exactly the grid's ``nodes`` nodes."""
    return run.success and run.t.size == request.nodes


def shooting(request: GridRequest[Boundary], fixed: Scheme, times) -> tuple[dict | None, bool]:
    """``(march, reached)``: the march of ``fixed`` steps from ``(q_start, p_0)`` that ends on
    ``q_end`` to ``tol`` (module docstring), or, when the iteration stops short, the march that
    came closest (``reached`` False: the fixed-step solve then starts from it, on its branch);
    ``None`` if not even the first march succeeds. The iteration is the grid's Newton on
    `ShootingProblem` with its own steps (`ShootingSteps`) and least-squares solve."""
    p0 = straight_line(request, times)["p"][0] if request.data.p_start is None \
        else request.data.p_start.copy()
    record = Stage("shooting (march)", "newton (finite differences)")
    request.phases.append(record)
    problem, aim = ShootingProblem(request, fixed), Aim(request.data.q_end, request.theta)
    run = problem.run(p0, aim)
    if not _whole(request, run):
        record.said = f"the march from p_0 = {p0.tolist()} failed: {run.message}"
        return None, False
    problem.size_from(run, p0)
    close = SHOOTING_CLOSE * problem.q_size
    result = newton(problem, p0, aim, np.full(p0.size, request.tol * problem.q_size),
                    tau_floor=-np.inf,
                    max_iter=SHOOTING_ITERATIONS, test=ShootingSteps(problem, aim, close),
                    factor=LeastSquares)
    record.iterations = result.last_iteration
    if result.converged:
        record.converged, record.said = True, f"q_end reached, p_0 = {result.x.tolist()}"
        run = problem.run(result.x, aim)
    else:
        record.said, run = result.outcome, problem.closest[1]
    return {"t": run.t, "q": run.q, "p": run.p}, bool(result.converged)


@dataclass(frozen=True)
class Aim:
    """The data of a `ShootingProblem`: the end position the march must reach and the
    parameters it runs with."""

    q_end: np.ndarray
    theta: np.ndarray


@dataclass(frozen=True)
class _MomentumLayout:
    """The unknowns of shooting: ``p_0`` alone, no node times."""

    n: int

    @property
    def size(self) -> int:
        return self.n

    @property
    def bandwidth(self) -> int:
        return max(self.n - 1, 0)

    def time_index(self) -> np.ndarray:
        return np.zeros(0, int)


class ShootingProblem:
    """``F(p_0) = q_{N-1}(p_0) - q_end``, ``q_{N-1}`` the last position of the march of fixed
    steps from ``(q_start, p_0)`` on the grid's ``N`` nodes (``nan`` where that march does not
    reach ``t_end`` in ``N`` nodes): a ``grid.GridProblem`` of ``n`` unknowns whose Jacobians
    are forward differences (``n + 1`` marches; ``None`` if a march of the differences fails),
    step ``1e-7`` of the momentum's size (`size_from`).

    The marches of the residuals are kept until the next Jacobian (a line search's trials, the
    step is one of them); `closest` is the march that came closest to ``q_end`` (2-norm; the
    first of equals), the start shooting falls back on."""

    def __init__(self, request: GridRequest[Boundary], fixed: Scheme):
        self.request, self.fixed = request, fixed
        self.layout = _MomentumLayout(request.system.n)
        self._runs: dict = {}
        self.closest = (np.inf, None)
        self.q_size, self.p_size = 1.0, np.ones(request.system.n)

    def size_from(self, run, p0: np.ndarray) -> None:
        """The sizes the iteration measures in, from the first march ``run`` from ``p0``: the
        largest range of a position over it (the distance between the ends where it does not
        move) for the miss, and each momentum's larger of ``|p_0,i|`` and its range for the
        differences' steps and the step's cap. In the problem's own units, never ``max(1,
        .)``: in lengths of ``1e-8`` a step of ``1e-7`` was ten times the momentum."""
        data = self.request.data
        q_size = float(np.max(np.ptp(run.q, axis=0)))
        if not q_size > 0:
            q_size = float(np.max(np.abs(data.q_end - data.q_start)))
        self.q_size = q_size if q_size > 0 else float(np.max(np.abs(data.q_end))) or 1.0
        p_size = np.maximum(np.abs(p0), np.ptp(run.p, axis=0))
        largest = float(np.max(p_size))
        self.p_size = np.where(p_size > 0, p_size, largest if largest > 0 else 1.0)

    def run(self, p0: np.ndarray, aim: Aim):
        """The march from ``p0`` (kept)."""
        key = (p0.tobytes(), np.asarray(aim.theta, float).tobytes())
        run = self._runs.get(key)
        if run is None:
            run = self._runs[key] = _march(self.request, self.fixed, p0, aim.theta)
        return run

    def forget(self, p0: np.ndarray, aim: Aim) -> None:
        """Drop the march from ``p0`` (a trial the line search does not take)."""
        self._runs.pop((p0.tobytes(), np.asarray(aim.theta, float).tobytes()), None)

    def evaluate(self, p0: np.ndarray, aim: Aim, jacobian: bool = True):
        run = self.run(p0, aim)
        if not _whole(self.request, run):
            return np.full(self.layout.size, np.nan), None
        F = run.q[-1] - aim.q_end
        if not jacobian:
            distance = np.linalg.norm(F)
            if distance < self.closest[0]:
                self.closest = (distance, run)
            return F, None
        self._runs = {key: kept for key, kept in self._runs.items() if kept is run}
        return F, self._differences(p0, aim, run)

    def _differences(self, p0, aim, run) -> np.ndarray | None:
        n = p0.size
        J = np.empty((n, n))
        for i in range(n):
            h = 1e-7 * self.p_size[i]
            bumped = p0.copy()
            bumped[i] += h
            moved = _march(self.request, self.fixed, bumped, aim.theta)
            if not moved.success:
                return None
            J[:, i] = (moved.q[-1] - run.q[-1]) / h
        return J

    def parameter_jacobian(self, p0: np.ndarray, aim: Aim) -> sp.csc_matrix:
        """``dF/dtheta`` by forward differences of marches (step ``1e-7 max(1, |theta_j|)``):
        a march has no expression to differentiate; ``nan`` columns where a march fails."""
        theta = np.asarray(aim.theta, float)
        run = _march(self.request, self.fixed, p0, theta)
        columns = np.full((p0.size, theta.size), np.nan)
        for j in range(theta.size):
            h = 1e-7 * max(1.0, abs(theta[j]))
            bumped = theta.copy()
            bumped[j] += h
            moved = _march(self.request, self.fixed, p0, bumped)
            if moved.success and run.success:
                columns[:, j] = (moved.q[-1] - run.q[-1]) / h
        return sp.csc_matrix(columns)

    def sparse(self, jacobian) -> sp.csc_matrix:
        return sp.csc_matrix(jacobian)

    def banded(self, jacobian) -> np.ndarray:
        """The dense ``n x n`` Jacobian in LAPACK band storage (bandwidth ``n - 1``)."""
        n, w = self.layout.size, self.layout.bandwidth
        ab = np.zeros((3 * w + 1, n), order="F")
        rows, cols = np.indices((n, n))
        ab[2 * w + rows - cols, cols] = jacobian
        return ab

    def release(self) -> None:
        """Nothing to drop until shooting ends: it reads `closest` after the solve."""


class LeastSquares:
    """The solve of shooting's Newton step: the least-squares ``J^+ rhs`` with the singular
    values below ``SHOOTING_RCOND`` times the largest cut, ``nan`` without a ``J`` (a march
    of the differences failed). Directions the end barely depends on are left alone: over
    whole periods of a Kepler orbit every direction of ``p_0`` with the same ``|p_0|`` returns
    to the start, and the minimum-norm step along that near-null direction sent ``p_0`` into
    the centre (measured)."""

    def __init__(self, jacobian):
        self.jacobian = jacobian

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        if self.jacobian is None:
            return np.full_like(rhs, np.nan)
        return np.linalg.lstsq(self.jacobian, rhs, rcond=SHOOTING_RCOND)[0]

    def solve_transposed(self, rhs: np.ndarray) -> np.ndarray:
        if self.jacobian is None:
            return np.full_like(rhs, np.nan)
        return np.linalg.lstsq(self.jacobian.T, rhs, rcond=SHOOTING_RCOND)[0]


class ShootingSteps(NaturalMonotonicity):
    """How shooting steps along ``dx = -J^+ F`` (grid Newton's step test): the step is capped
    at the momenta's size (`ShootingProblem.size_from`: a step larger than the momentum itself
    leaves the march's basin),
    then halved ``SHOOTING_HALVINGS`` times at most; the longest of the halved steps whose march
    succeeds and comes closer to ``q_end`` is taken, and if none comes closer, the longest whose
    march succeeds (the end can depend on ``p_0`` so unevenly, a swinging pendulum, that full
    steps converge where every shorter step first moves away; measured). The iteration stops
    when the closest miss, below ``close``, has not halved in ``SHOOTING_STALL`` steps; the
    closest march seen is returned."""

    keep_best = True

    def __init__(self, problem: ShootingProblem, aim: Aim, close: float):
        self.problem, self.aim, self.close = problem, aim, close
        self.start, self.unhalved = None, 0

    def norm(self, F, weight) -> float:
        return np.linalg.norm(F)

    def search(self, residual, problem, lu, x, dx, tau_floor, norm, weight, near_floor,
               unknowns=None):
        self.start = x
        scale = max(float(np.max(self.problem.p_size)), float(np.max(np.abs(x))))
        cap = min(1.0, scale / max(float(np.max(np.abs(dx))), np.finfo(float).tiny))
        step, taken = dx * cap, None
        for halving in range(SHOOTING_HALVINGS + 1):
            trial = x + step / 2 ** halving
            F, _ = residual(trial, False)
            if not np.all(np.isfinite(F)):
                continue
            if np.linalg.norm(F) < norm:
                return trial, F, cap / 2 ** halving
            if taken is None:
                taken = (trial, F, cap / 2 ** halving)
            else:
                self.problem.forget(trial, self.aim)
        return taken

    def singular(self, iteration: int) -> str:
        return "a march of the finite differences failed"

    def stalled(self, F, target, norm: float, iteration: int) -> tuple[str, bool]:
        return (f"every march along the step from p_0 = {self.start.tolist()} fails (miss "
                f"{norm:.3e})"), False

    def halted(self, norm: float, best_norm: float) -> str | None:
        self.unhalved = 0 if norm < 0.5 * best_norm else self.unhalved + 1
        if self.unhalved >= SHOOTING_STALL and min(best_norm, norm) <= self.close:
            return f"the miss has not halved in {SHOOTING_STALL} iterations"
        return None

    def finish(self, result, best, target, max_iter: int, norm: float) -> None:
        """The closest iterate, never converged (a last step that reaches ``q_end`` is not
        checked: the closest march starts the fixed-step solve)."""
        if not result.outcome:
            result.outcome = f"q_end not reached in {max_iter} iterations"
        result.outcome += (f"; the closest march (miss {best[0]:.3e}) starts the fixed-step "
                           f"solve")
        result.x, result.converged = best[1], False


def interpolate(times, t, values) -> np.ndarray:
    return np.column_stack([np.interp(times, t, column) for column in values.T])


def predicted_times(system, t, q, p, theta, compilation: Compilation | None = None) -> np.ndarray:
    """Node times with the site density of the energy rules: ``tau ~ w^(-1/3)``, that is
    ``w^(1/3)`` nodes per unit time, ``w`` evaluated at the interval midpoints of the grid ``t``,
    ``q``, ``p``; same number of nodes, same first and last time.

    The new nodes split the integral of ``w^(1/3)`` over the old grid into equal parts: the
    density is a function of where the motion is, not of the old node's index (taking
    ``tau_k ~ w_k^(-1/3)`` of the old interval ``k`` put the released kepler e = 0.5 solution up
    to 37 mean steps away from the prediction and cost 44 damped Newton iterations at N = 1e3;
    measured)."""
    N = t.size
    w = site_weights(system, t, q, p, theta, compilation)
    # Where w <= 0 the energy rules have no positive step anyway (docs/theory.md
    # section 7); keep the prediction finite there and let the solve report it.
    floor = 1e-3 * np.median(np.abs(w)) if np.any(w != 0) else 1.0
    density = np.maximum(w, floor) ** (1 / 3)
    mass = np.concatenate([[0.0], np.cumsum(density * np.diff(t))])
    times = np.interp(np.linspace(0.0, mass[-1], N), mass, t)
    times[0], times[-1] = t[0], t[-1]
    return times


def site_weights(system, t, q, p, theta, compilation: Compilation | None = None) -> np.ndarray:
    """``w = f' H_zz f`` at the interval midpoints of the grid ``t``, ``q``, ``p``."""
    # through the assembly's compiled windows: a VM map built for each N took 1.33 s CPU at
    # N = 1e6, this 0.08 s, the same values (measured)
    return evaluate_blocks(system, ("site_weights",), site_density_weight_function(system),
                           [(q[:-1] + q[1:]) / 2, (p[:-1] + p[1:]) / 2,
                            ((t[:-1] + t[1:]) / 2)[:, None]], theta,
                           compilation or Compilation())[0].ravel()


def branch_obstacle(request: GridRequest[Boundary], start: dict) -> str | None:
    """Why the released solve may have no solution near ``start``: the intervals where
    ``w <= 0``, on which the energy rules have no positive step (docs/theory.md section 7), or
    ``None`` if there are none."""
    t = np.asarray(start["t"], float)
    w = site_weights(request.system, t, np.asarray(start["q"], float),
                     np.asarray(start["p"], float), request.theta, request.compilation)
    bad = np.flatnonzero(w <= 0)
    if bad.size == 0:
        return None
    return (f"on the start's branch w = f' H_zz f <= 0 on {bad.size} of {w.size} intervals "
            f"(t in [{t[bad[0]]:.6g}, {t[bad[-1] + 1]:.6g}]), where the energy rules have no "
            f"positive step: this branch probably has no {request.scheme.rule} solution; give "
            f"a start on another branch (guess='march' with p_start, or nodes)")


def check_tau_floor(tau_floor, t0: float, t1: float, nodes: int) -> float:
    """The fixed-end grid's least step: ``tau_floor`` (default a thousandth of the mean step
    ``(t1 - t0) / (nodes - 1)``), positive and below the mean step, or refused by name."""
    mean = (t1 - t0) / (nodes - 1)
    floor = check_real("tau_floor", 1e-3 * mean if tau_floor is None else tau_floor,
                       positive=True)
    if floor >= mean:
        raise InputError(f"tau_floor must be < (t_end - t_0)/(nodes - 1) = {mean!r}, "
                         f"got {floor!r}")
    return floor


def check_times(times, nodes: int, t0: float, t1: float) -> np.ndarray:
    """The fixed rule's node times: uniform by default, else ``nodes`` increasing values from
    ``t0`` to ``t1``."""
    if times is None:
        return np.linspace(t0, t1, nodes)
    try:
        grid_times = np.asarray(times, float)
    except (TypeError, ValueError):
        grid_times = np.zeros(0)
    if grid_times.shape != (nodes,) or not np.all(np.isfinite(grid_times)) \
            or grid_times[0] != t0 or grid_times[-1] != t1 or np.any(np.diff(grid_times) <= 0):
        raise InputError(f"times must be {nodes} increasing finite values from t_0 to "
                         f"t_end, got {times!r}")
    return grid_times


def check_guess(guess, nodes, n, t0, t1) -> dict:
    """The guess's ``t``, ``q``, ``p`` on ``nodes`` rows: as given, or resampled by node index
    (linear interpolation between the guess's rows, so that its step distribution is kept) with
    the times mapped affinely onto ``[t0, t1]``."""
    if isinstance(guess, Solution):
        guess = {"t": guess.t, "q": guess.q, "p": guess.p}
    if not isinstance(guess, Mapping) or not {"t", "q", "p"} <= set(guess):
        raise InputError("guess must be a Solution or a mapping with t, q and p")
    rows = np.shape(guess["t"])[0] if np.ndim(guess["t"]) == 1 else -1
    if rows < 2:
        raise InputError(f"guess['t'] must be a vector of at least 2 times, got shape "
                         f"{np.shape(guess['t'])}")
    shapes = {"t": (rows,), "q": (rows, n), "p": (rows, n)}
    result = {}
    for key, shape in shapes.items():
        result[key] = check_finite_array(f"guess[{key!r}]", guess[key], shape)
    if np.any(np.diff(result["t"]) <= 0):
        raise InputError("guess['t'] must increase")
    if rows == nodes:
        return result
    index = np.linspace(0.0, rows - 1, nodes)
    old = np.arange(rows)
    t = np.interp(index, old, result["t"])
    t = t0 + (t - t[0]) * (t1 - t0) / (t[-1] - t[0])
    t[0], t[-1] = t0, t1
    return {"t": t, **{key: np.column_stack([np.interp(index, old, c) for c in result[key].T])
                       for key in ("q", "p")}}
