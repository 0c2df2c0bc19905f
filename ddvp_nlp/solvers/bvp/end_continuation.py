"""Continuation of the fixed-step problem in its end position, past turning points
(pseudo-arclength): the start of last resort of ``first_guess.py``.

A march of fixed steps from ``(q_start, p_0)`` solves the fixed-endpoint problem whose end
position is its own last position ``a``. Moving the end position along ``q_end(s) = a + s d``,
``d = q_end - a``, from ``s = 0`` to ``s = 1`` carries that solution to the problem asked for,
unless the path of solutions turns back in ``s`` (a fold: two solutions meet and vanish). There
a continuation in ``s`` itself stops (tried: on the pendulum from 0.5 to -0.3 in 10 time units
it stopped at ``s = 0.61``, on Henon-Heiles at ``s = 0.02-0.88``). Here the unknowns are
``y = (x, s)`` and each step moves a length ``h`` along the path's tangent ``T``:

- predictor ``y + h T``; corrector: the grid's Newton (``grid/newton.py``, full steps) on
  ``F(x, s) = 0`` together with ``<T, y - y_pred> = 0`` (the hyperplane through the prediction
  across the path; `_Path` is that grid problem), each step solved by bordering with the banded
  LU of ``F_x`` (`Bordered`): ``dx = z_1 + ds z_2`` with ``F_x z_1 = -F`` and
  ``F_x z_2 = -F_s`` (``F_s = -d`` on the end rows), which stays well posed at a fold where
  ``F_x`` alone is singular;
- the tangent is the secant of the last two points (its orientation kept), ``h`` grows by half
  after a corrector that converged in a few iterations and halves after one that failed;
- in ``<., .>`` the ``x`` part is divided by the number of unknowns, so that ``s`` counts as much
  as the whole grid.

When a step crosses ``s = 1`` the point at ``s = 1`` is interpolated and handed back; the caller
solves the problem there (``first_guess.py``). The solution found is the one connected to
the march by the path: ``ends.p_sign_changes`` of the result says which it is.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..grid.linear import Factorization, band_kernel
from ..grid.newton import FullSteps, newton
from ..grid.policy import Stage
from ..grid.problem import BorderedLayout, GridRequest
from .interleaved import Ends, NodeLayout
from .phases import Boundary, assembly, newton_targets

FIRST_STEP = 0.05
SMALLEST_STEP = 1e-5
LARGEST_STEP = 0.5
MAX_STEPS = 400
CORRECTOR_ITERATIONS = 8
# The corrector has converged when every |F_i| is below this many of its row's round-off
# (phases.newton_targets at the prediction): it follows the path, the point at s = 1 is solved
# after. It was 1e-10 max(1, |x|), which took any point for converged in lengths of 1e-8.
CORRECTOR_TARGETS = 1e4


def continue_in_end_position(request: GridRequest[Boundary], fixed, times, base: dict):
    """The fixed-step problem's nodes near ``s = 1`` on the path from the march ``base``
    (module docstring), as a start (``dict`` of ``t``, ``q``, ``p``), or ``None``; the phase
    record in ``request.phases`` says how far it got."""
    layout = NodeLayout(request.system.n, request.nodes)
    path = _Path(request, assembly(request, fixed), times, np.asarray(base["q"][-1], float))
    record = Stage("continuation in q_end (fixed steps, pseudo-arclength)",
                   "newton (bordered)", steps=0)
    request.phases.append(record)
    started = time.perf_counter()
    y = np.concatenate([layout.pack(times, base["q"], base["p"]), [0.0]])
    try:
        point = _walk(request, path, y, record)
    finally:
        path.grid.release()
    record.seconds = time.perf_counter() - started
    if point is None:
        return None
    t, q, p = layout.unpack(point[:-1])
    return {"t": t, "q": q, "p": p}


def _walk(request, path, y, record):
    """Steps along the path from ``y`` until ``s = 1`` (the point there, interpolated) or a
    stop (``None``; ``record`` says why)."""
    h = FIRST_STEP
    tangent = path.first_tangent(y)
    if tangent is None:
        record.said = "the Jacobian at the march is singular: no tangent"
        return None
    while record.steps < MAX_STEPS:
        if request.remaining() == 0.0:
            record.said = f"time limit reached at s = {y[-1]:.4g}"
            return None
        corrected, iterations = path.correct(y + h * tangent, tangent)
        record.iterations += iterations
        record.steps += 1
        if corrected is None:
            h /= 2
            if h < SMALLEST_STEP:
                record.said = (f"the step fell below {SMALLEST_STEP:g} at "
                                           f"s = {y[-1]:.4g}")
                return None
            continue
        if corrected[-1] >= 1.0:
            w = (1.0 - y[-1]) / (corrected[-1] - y[-1])
            record.converged, record.said = True, f"s = 1 reached in {record.steps} steps"
            return y + w * (corrected - y)
        secant = corrected - y
        tangent = secant / path.norm(secant)
        y = corrected
        if request.progress:
            print(f"bvp [continuation]: step {record.steps}, s = {y[-1]:.6g}, "
                  f"arclength step {h:.3g}", file=sys.stderr, flush=True)
        if iterations <= 3:
            h = min(LARGEST_STEP, 1.5 * h)
    record.said = f"{MAX_STEPS} steps without reaching s = 1 (s = {y[-1]:.4g})"
    return None


@dataclass(frozen=True)
class Hyperplane:
    """The data of one corrector solve: the prediction ``y_pred`` and the tangent ``T`` of the
    hyperplane ``<T, y - y_pred> = 0`` the corrected point lies on."""

    prediction: np.ndarray
    tangent: np.ndarray


class _CorrectorSteps(FullSteps):
    """The corrector's Newton: full steps, converged when every ``|F_i|`` of the fixed-step
    problem (not the hyperplane's row) is below its target."""

    def converged(self, F, y, target) -> bool:
        return bool(np.all(np.abs(F[:-1]) <= target[:-1]))


CORRECTOR_STEPS = _CorrectorSteps()


class _Path:
    """The path of solutions ``F(x, s) = 0`` with the end position ``a + s d``: its tangent and
    corrector by bordering (module docstring). A ``grid.GridProblem`` in ``y = (x, s)`` (its
    data a `Hyperplane`): ``(F(x, s), <T, y - y_pred>)``, solved by the grid's Newton with
    full steps and the bordered solve (`Bordered`)."""

    def __init__(self, request, grid, times, a):
        self.grid, self.request = grid, request
        size = grid.layout.size
        self.layout = BorderedLayout(grid.layout)
        self.times, self.a, self.d = np.asarray(times, float), a, request.data.q_end - a
        self.F_s = np.zeros(size)
        self.F_s[-request.system.n:] = -self.d
        self.weight = np.concatenate([np.full(size, 1.0 / size), [1.0]])
        self.kernel = band_kernel(request.compilation)

    def ends(self, s) -> Ends:
        return Ends(self.request.data.q_start, self.a + s * self.d, self.times,
                    self.request.theta, 1.0)

    def norm(self, v) -> float:
        return float(np.sqrt(np.sum(self.weight * v * v)))

    def factor(self, blocks) -> Factorization:
        return Factorization(self.grid, blocks, self.request.linear, self.kernel)

    def first_tangent(self, y):
        """The tangent at the march (``s`` increasing): ``(F_x^-1 (-F_s), 1)``, normalised."""
        _, blocks = self.grid.evaluate(y[:-1], self.ends(y[-1]), jacobian=True)
        z = self.factor(blocks).solve(-self.F_s.copy())
        if not np.all(np.isfinite(z)):
            return None
        tangent = np.concatenate([z, [1.0]])
        return tangent / self.norm(tangent)

    def evaluate(self, y: np.ndarray, plane: Hyperplane, jacobian: bool = True):
        """``(F(x, s), <T, y - y_pred>)`` and, if asked, the Jacobian ``(blocks, plane)``."""
        F, blocks = self.grid.evaluate(y[:-1], self.ends(y[-1]), jacobian=jacobian)
        g = float(np.sum(self.weight * plane.tangent * (y - plane.prediction)))
        return np.r_[F, g], ((blocks, plane) if jacobian else None)

    def bordered(self, jacobian) -> Bordered:
        """The solve of the bordered Jacobian by the LU of ``F_x`` (grid Newton's ``factor``)."""
        blocks, plane = jacobian
        return Bordered(self.factor(blocks), self.F_s, self.weight * plane.tangent)

    def sparse(self, jacobian) -> sp.csc_matrix:
        blocks, plane = jacobian
        row = self.weight * plane.tangent
        return sp.bmat([[self.grid.sparse(blocks), sp.csc_matrix(self.F_s[:, None])],
                        [sp.csr_matrix(row[None, :-1]), sp.csr_matrix(row[None, -1:])]],
                       format="csc")

    def parameter_jacobian(self, y: np.ndarray, plane: Hyperplane) -> sp.csc_matrix:
        """``dF/dtheta``: the fixed-step problem's at ``s`` (``GridAssembly``'s, from its CasADi
        blocks), and a zero row for the hyperplane."""
        rows = self.grid.parameter_jacobian(y[:-1], self.ends(y[-1]))
        return sp.vstack([rows, sp.csc_matrix((1, rows.shape[1]))], format="csc")

    def release(self) -> None:
        """Nothing: the band store serves every corrector of the walk, and
        `continue_in_end_position` releases the assembly's when the walk ends."""

    def correct(self, prediction, tangent):
        """Newton on ``F(x, s) = 0``, ``<tangent, y - prediction> = 0`` (the grid's Newton,
        full steps, bordered solve): ``(y, iterations)``, ``y`` ``None`` if it did not
        converge (then ``iterations`` counts the one it stopped in)."""
        rows = CORRECTOR_TARGETS * newton_targets(self.request, self.grid, prediction[:-1],
                                                  self.ends(prediction[-1]))
        result = newton(self, prediction, Hyperplane(prediction, tangent),
                        np.r_[rows, np.inf], tau_floor=-np.inf,
                        max_iter=CORRECTOR_ITERATIONS, test=CORRECTOR_STEPS,
                        factor=self.bordered)
        if result.converged:
            return result.x, result.iterations
        return None, result.last_iteration


class Bordered:
    """``[[F_x, F_s], [r_x^T, r_s]] (dx, ds) = (b, beta)`` by bordering with the factors of
    ``F_x``: ``dx = z_1 + ds z_2``, ``F_x z_1 = b``, ``F_x z_2 = -F_s``,
    ``ds = (beta - r_x . z_1) / (r_x . z_2 + r_s)``; well posed at a fold, where ``F_x``
    alone is singular. ``nan`` where a solve is not finite or the denominator is zero."""

    def __init__(self, lu: Factorization, F_s: np.ndarray, row: np.ndarray):
        self.lu, self.F_s, self.row = lu, F_s, row

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        z1 = self.lu.solve(rhs[:-1].copy())
        z2 = self.lu.solve(-self.F_s.copy())
        wx = self.row[:-1]
        if not (np.all(np.isfinite(z1)) and np.all(np.isfinite(z2))):
            return np.full_like(rhs, np.nan)
        denominator = float(wx @ z2) + self.row[-1]
        if denominator == 0.0:
            return np.full_like(rhs, np.nan)
        ds = (rhs[-1] - float(wx @ z1)) / denominator
        return np.r_[z1 + ds * z2, ds]

    def solve_transposed(self, rhs: np.ndarray) -> np.ndarray:
        """The transpose ``[[F_x^T, r_x], [F_s^T, r_s]]`` by the same bordering:
        ``u = w_1 - v w_2``, ``F_x^T w_1 = b``, ``F_x^T w_2 = r_x``,
        ``v = (beta - F_s . w_1) / (r_s - F_s . w_2)``."""
        w1 = self.lu.solve_transposed(rhs[:-1].copy())
        w2 = self.lu.solve_transposed(self.row[:-1].copy())
        denominator = self.row[-1] - float(self.F_s @ w2)
        if not (np.all(np.isfinite(w1)) and np.all(np.isfinite(w2))) or denominator == 0.0:
            return np.full_like(rhs, np.nan)
        v = (rhs[-1] - float(self.F_s @ w1)) / denominator
        return np.r_[w1 - v * w2, v]
