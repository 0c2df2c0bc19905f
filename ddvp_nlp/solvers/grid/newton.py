"""Newton's method on a square grid system ``F(x) = 0``: the one Newton of every grid problem
(fixed ends, periodic orbits, higher-order problems), with a pluggable step test.

Each iteration solves ``F'(x) dx = -F(x)`` (``linear.py``: banded LU, or sparse LU where the
Jacobian is not narrowly banded), then takes ``x + alpha dx`` with:

- a safeguard: ``alpha <= 0.99 alpha_max``, where ``alpha_max`` is the largest step that keeps
  every ``t_{k+1} - t_k >= tau_floor`` (the time-reversed root ``tau < 0`` of docs/theory.md
  section 7 is never approached);
- a backtracking line search: ``alpha`` halves until the step passes the *step test*, down to
  ``1e-10``. Two tests, each with the iterate it returns:

  - `NaturalMonotonicity` (first-order fixed-endpoint and periodic problems):
    Deuflhard's natural monotonicity test, the simplified Newton correction
    ``|F'(x)^-1 F(x + alpha dx)|`` at most ``(1 - alpha/2) |dx|`` (the residual in the units of
    ``x``, so that no row's scale decides; the factors of ``F'(x)`` are reused). The 2-norm of
    ``F`` rejected the first full step on the pendulum at N = 1e4 and took 32 iterations where
    this takes 3. Returns the last iterate.
  - `DecreaseOrMonotonicity` (higher-order problems): either that test or a decrease of
    the residual weighted by the targets (Armijo). On these systems ``F'`` has condition
    ``~N^4`` (a fourth difference): at N = 1e5 of the spline the round-off of ``F`` at the exact
    step, carried through ``F'^-1``, exceeded the step itself, and the monotonicity test alone
    rejected every step from the straight line (residual left at 1e-5, measured), where the full
    step takes the residual to round-off; the weighted norm alone took Pais-Uhlenbeck's released
    times through 19 homotopy stages (310 iterations) where either test takes 11. Returns the
    iterate with the smallest weighted residual.

It stops when every ``|F_i|`` is below its ``target_i`` (given by the caller at a small multiple
of the row's round-off), or when no step passes the test any more (the round-off floor, or no
solution nearby), and returns a `GridResult` with what
happened in words. Whether that point solves the problem is the caller's verification to decide.

``offset``: solve ``F(x) = offset`` instead (a stage of a Newton homotopy).

The same loop serves Newtons whose globalisation is their own (the fixed-endpoint start by
shooting, ``bvp/first_guess.py``; the corrector of the continuation in the end position,
``bvp/end_continuation.py``): a step test may also decide when the iteration has converged
(``converged``), search along the Newton direction its own way (``search``; `FullSteps` takes
every step whole), name a singular solve (``singular``) and stop after a step (``halted``); its
defaults are those above. ``factor`` replaces the LU of ``F'(x)`` by another solve of it (a
bordered one, a least-squares one). An iterate whose residual is not finite ends the iteration
(only a search that takes steps untested can reach one).
"""

from __future__ import annotations

import time
from typing import Protocol

import numpy as np

from . import band
from .linear import Factorization
from .problem import GridProblem, GridResult

# Near the round-off floor (every |F_i| within this many targets) a step that does not pass the
# test ends the iteration instead of being halved; a returned point within this many targets
# counts as converged.
FLOOR_FACTOR = 64
SMALLEST_ALPHA = 1e-10


def largest_admissible_step(problem: GridProblem, x, dx, tau_floor: float) -> float:
    """The largest ``alpha`` in ``(0, inf]`` with ``tau_k(x + alpha dx) >= tau_floor`` for all
    ``k``, given ``tau_k(x) >= tau_floor``."""
    where = problem.layout.time_index()
    tau, dtau = np.diff(x[where]), np.diff(dx[where])
    shrinking = dtau < 0
    if not np.any(shrinking):
        return np.inf
    room = np.maximum(tau[shrinking] - tau_floor, 0.0)
    return float(np.min(room / -dtau[shrinking]))


def _norm(v: np.ndarray, weight=None) -> float:
    """The 2-norm (of ``v * weight``) without BLAS: numpy's ``dot`` took 7 ms on 3e4 values
    (OpenBLAS threads waking up), einsum 20 us."""
    with np.errstate(all="ignore"):
        if weight is not None:
            v = v * weight
        return float(np.sqrt(np.einsum("i,i->", v, v)))


def column_sizes(jacobian, target: np.ndarray) -> np.ndarray:
    """Each unknown's size as the rows see it: ``1 / max_i |J_ij| / target_i``, the move of
    unknown ``j`` that changes some row by its target (``jacobian``: scipy sparse). It carries
    the unknown's units (``J_ij`` has the units of row ``i`` over those of unknown ``j``, the
    target those of row ``i``), so a norm of ``dx`` weighted by its inverse is the same in any
    units of length, momentum or time; an unknown no row depends on gets 1."""
    A = abs(jacobian.tocsc())
    reach = np.asarray(A.multiply(1.0 / np.asarray(target, float)[:, None]).max(axis=0)
                       .todense()).ravel()
    with np.errstate(divide="ignore"):
        sizes = 1.0 / reach
    return np.where(np.isfinite(sizes) & (sizes > 0), sizes, 1.0)


class StepTest(Protocol):
    """What the line search asks of a step test, and which iterate the solve returns."""

    keep_best: bool

    def norm(self, F, weight) -> float:
        """The residual norm the history records (and the test compares)."""

    def accepts(self, F_trial, lu, alpha: float, size: float, norm: float, weight,
                unknowns=None) -> bool:
        """Whether ``x + alpha dx`` (residual ``F_trial``) is taken; ``size``: ``|dx|`` in the
        norm of the unknowns (``unknowns``: their weights, `newton`'s ``unknown_sizes``)."""

    def stalled(self, F, target, norm: float, iteration: int) -> tuple[str, bool]:
        """What happened, and whether it counts as converged, when no step passes."""

    def finish(self, result: GridResult, best, target, max_iter: int, norm: float) -> None:
        """The returned iterate and words after ``max_iter`` iterations."""

    def converged(self, F, x, target) -> bool:
        """Whether ``x`` (residual ``F``) ends the iteration as converged."""

    def search(self, residual, problem, lu, x, dx, tau_floor: float, norm: float, weight,
               near_floor: bool, unknowns=None):
        """``(x_new, F_new, alpha)`` along ``dx``, or ``None`` if no step is taken."""

    def singular(self, iteration: int) -> str:
        """What happened when the linear solve gave a non-finite ``dx``."""

    def halted(self, norm: float, best_norm: float) -> str | None:
        """After a step to residual norm ``norm`` (the best before it ``best_norm``): why the
        iteration stops there, or ``None`` to go on."""


class NaturalMonotonicity:
    """Deuflhard's natural monotonicity test (module docstring); the last iterate is returned.
    Its `converged`, `search`, `singular` and `halted` are every test's defaults."""

    keep_best = False

    def converged(self, F, x, target) -> bool:
        """Every ``|F_i|`` at its ``target_i``."""
        return bool(np.all(np.abs(F) <= target))

    def search(self, residual, problem, lu, x, dx, tau_floor: float, norm: float, weight,
               near_floor: bool, unknowns=None):
        """The backtracking line search of the module docstring (`_line_search`)."""
        return _line_search(residual, problem, lu, x, dx, tau_floor, self, norm, weight,
                            near_floor, unknowns)

    def singular(self, iteration: int) -> str:
        return f"singular Jacobian at iteration {iteration}"

    def halted(self, norm: float, best_norm: float) -> str | None:
        return None

    def norm(self, F, weight) -> float:
        return _norm(F)

    def accepts(self, F_trial, lu, alpha: float, size: float, norm: float, weight,
                unknowns=None) -> bool:
        correction = _norm(lu.solve(-F_trial), unknowns)
        return bool(np.isfinite(correction) and correction <= (1 - alpha / 2) * size)

    def stalled(self, F, target, norm: float, iteration: int) -> tuple[str, bool]:
        """Why no step passed: round-off (every row within ``FLOOR_FACTOR`` targets, which are
        themselves a multiple of round-off) or no root nearby."""
        ratio = float(np.max(np.abs(F) / target))
        if ratio <= FLOOR_FACTOR:
            return (f"converged: residual at its round-off floor (largest |F_i| / target = "
                    f"{ratio:.2g}) after {iteration - 1} iterations"), True
        return (f"stalled at iteration {iteration}: no step along the Newton direction passes "
                f"the monotonicity test, residual norm {norm:.3e} (no root nearby)"), False

    def finish(self, result: GridResult, best, target, max_iter: int, norm: float) -> None:
        """After ``max_iter`` iterations."""
        result.outcome = f"max_iter = {max_iter} reached, residual norm {norm:.3e}"
        result.converged = bool(np.all(np.abs(best[2]) <= target))


class DecreaseOrMonotonicity(NaturalMonotonicity):
    """A decrease of the weighted residual (Armijo) or the natural monotonicity test (module
    docstring); the iterate with the smallest weighted residual is returned."""

    keep_best = True

    def norm(self, F, weight) -> float:
        return _norm(F, weight)

    def accepts(self, F_trial, lu, alpha: float, size: float, norm: float, weight,
                unknowns=None) -> bool:
        return (_norm(F_trial, weight) <= (1 - 1e-4 * alpha) * norm
                or _norm(lu.solve(-F_trial), unknowns) <= (1 - alpha / 2) * size)

    def stalled(self, F, target, norm: float, iteration: int) -> tuple[str, bool]:
        return (f"stalled at iteration {iteration}: no step along the Newton direction "
                f"decreases the residual"), False

    def finish(self, result: GridResult, best, target, max_iter: int, norm: float) -> None:
        """The best iterate; at its round-off floor if every row is within ``FLOOR_FACTOR``
        targets."""
        if not result.outcome:
            result.outcome = f"max_iter = {max_iter} reached"
        _, result.x, F = best
        ratio = float(np.max(np.abs(F) / target))
        result.converged = ratio <= FLOOR_FACTOR
        result.outcome = (f"converged: residual at its round-off floor (largest |F_i| / target "
                          f"= {ratio:.2g}) after {result.iterations} iterations"
                          if result.converged
                          else f"{result.outcome}, largest |F_i| / target = {ratio:.3g}")


class FullSteps(NaturalMonotonicity):
    """Newton's method undamped: every step taken whole (``alpha = 1``) and untested (a
    non-finite residual ends the iteration at the next one); the last iterate is returned, and
    ``max_iter`` iterations without convergence are a failure."""

    def search(self, residual, problem, lu, x, dx, tau_floor: float, norm: float, weight,
               near_floor: bool, unknowns=None):
        trial = x + dx
        F, _ = residual(trial, False)
        return trial, F, 1.0

    def finish(self, result: GridResult, best, target, max_iter: int, norm: float) -> None:
        result.outcome = f"max_iter = {max_iter} reached, residual norm {norm:.3e}"
        result.converged = False


MONOTONICITY = NaturalMonotonicity()
DECREASE_OR_MONOTONICITY = DecreaseOrMonotonicity()


def newton(problem: GridProblem, x0: np.ndarray, data, target: np.ndarray, *,
           tau_floor: float, max_iter: int = 50, linear: str = "auto",
           kernel: band.BandKernel | None = None, deadline: float | None = None,
           progress=None, test: StepTest = MONOTONICITY,
           offset: np.ndarray | None = None, factor=None,
           unknown_sizes: str | None = None) -> GridResult:
    """Newton's method with safeguard and line search (module docstring) from ``x0``.

    Args:
        problem, data: the system (a `GridProblem`) and
            its data.
        target: per-row bound on ``|F_i|`` at which the iteration has converged.
        tau_floor: smallest step the iterates may take (``-inf``: no node times are free).
        max_iter: iteration limit.
        linear: ``"banded"``, ``"sparse"`` or ``"auto"`` (banded up to ``WIDEST_BAND``).
        kernel: the compiled band LU (``linear.band_kernel``), or ``None`` for LAPACK.
        deadline: ``time.perf_counter()`` value after which to stop.
        progress: called as ``progress(iteration, residual_norm, alpha)`` after each iteration.
        test: the step test, and with it which iterate is returned.
        offset: solve ``F(x) = offset``.
        factor: ``factor(J)``, the solve of ``F'(x) dx = -F`` from the problem's Jacobian ``J``
            (an object with ``solve(rhs)``, ``nan`` where it is singular); default the banded or
            sparse LU (`Factorization`) of ``linear`` and ``kernel``.
        unknown_sizes: ``"columns"``: the step tests measure ``dx`` in units of each unknown's
            size `column_sizes` read off the first Jacobian (then the monotonicity test is the
            same in any units of the unknowns); ``None``: the plain 2-norm.
    """
    if factor is None:
        def factor(jacobian):
            return Factorization(problem, jacobian, linear, kernel)
    try:
        return _newton(problem, x0, data, target, tau_floor=tau_floor, max_iter=max_iter,
                       deadline=deadline, progress=progress, test=test, offset=offset,
                       factor=factor, unknown_sizes=unknown_sizes)
    finally:
        problem.release()  # the band store (312 MB at N = 1e6): not kept by the cache


def _newton(problem, x0, data, target, *, tau_floor, max_iter, deadline, progress, test, offset,
            factor, unknown_sizes):
    def residual(x, jacobian):
        F, J = problem.evaluate(x, data, jacobian=jacobian)
        return (F if offset is None else F - offset), J

    weight = 1.0 / target
    x = np.array(x0, float)
    F, _ = residual(x, False)
    norm = test.norm(F, weight)
    result = GridResult(x, False, "", 0, [norm], last_iteration=1)
    if not np.isfinite(norm):
        result.outcome = "the start has non-finite residuals"
        return result
    best = (norm, x, F)
    unknowns = None  # the weights of the unknowns in the step tests' norm
    for iteration in range(1, max_iter + 1):
        result.last_iteration = iteration
        if test.converged(F, x, target):
            result.x, result.converged = x, True
            result.outcome = f"converged: every residual at its target after {iteration - 1} " \
                             f"iterations"
            return result
        if not np.all(np.isfinite(F)):
            result.outcome = f"non-finite residuals at iteration {iteration}"
            return _ended(test, result, best, target, max_iter, norm)
        if deadline is not None and time.perf_counter() > deadline:
            result.outcome = f"time limit reached after {iteration - 1} iterations"
            return result
        # F(x) is at hand (the start's, or the line search's); the Jacobian only now, when a
        # step is needed: a converged solve evaluates none (F is the same with and without J:
        # the grid contract's rule 3)
        F, J = residual(x, True)
        if unknown_sizes == "columns" and unknowns is None:
            unknowns = 1.0 / column_sizes(problem.sparse(J), target)
        lu = factor(J)
        dx = lu.solve(-F)
        if not np.all(np.isfinite(dx)):
            result.outcome = test.singular(iteration)
            return _ended(test, result, best, target, max_iter, norm)
        step = test.search(residual, problem, lu, x, dx, tau_floor, norm, weight,
                           near_floor=bool(np.all(np.abs(F) <= FLOOR_FACTOR * target)),
                           unknowns=unknowns)
        if step is None:
            result.outcome, result.converged = test.stalled(F, target, norm, iteration)
            return _ended(test, result, best, target, max_iter, norm)
        x, F, alpha = step
        norm, best_before = test.norm(F, weight), best[0]
        if norm < best[0] or not test.keep_best:
            best = (norm, x, F)
        result.x, result.iterations = x, iteration
        result.residual_norms.append(norm)
        result.step_lengths.append(alpha)
        if progress is not None:
            progress(iteration, norm, alpha)
        halted = test.halted(norm, best_before)
        if halted is not None:
            result.outcome = halted
            return _ended(test, result, best, target, max_iter, norm)
    test.finish(result, best, target, max_iter, norm)
    return result


def _ended(test, result: GridResult, best, target, max_iter: int, norm: float) -> GridResult:
    """A solve that stopped early: the test's choice of iterate (the best one, for a test that
    keeps it)."""
    if test.keep_best:
        test.finish(result, best, target, max_iter, norm)
    return result


def _line_search(residual, problem, lu, x, dx, tau_floor, test, norm, weight, near_floor,
                 unknowns=None):
    """``(x_new, F_new, alpha)`` of the first ``alpha = a_0, a_0/2, ...`` that passes ``test``,
    with ``a_0 = min(1, 0.99 alpha_max)``; ``None`` if none down to ``SMALLEST_ALPHA``, or at
    once if the residual is already near its floor (below that, decreases are noise)."""
    alpha = min(1.0, 0.99 * largest_admissible_step(problem, x, dx, tau_floor))
    size = _norm(dx, unknowns)
    while alpha >= SMALLEST_ALPHA:
        trial = x + alpha * dx
        F, _ = residual(trial, False)
        if np.all(np.isfinite(F)) and test.accepts(F, lu, alpha, size, norm, weight,
                                                   unknowns):
            return trial, F, alpha
        if near_floor:
            return None
        alpha /= 2
    return None
