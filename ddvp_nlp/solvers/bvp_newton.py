"""Newton's method on the square fixed-endpoint system ``F(x) = 0`` (``bvp_assembly.py``).

Each iteration solves ``F'(x) dx = -F(x)`` by LU factorisation of the banded Jacobian (LAPACK
``gbsv``: ``O(N w^2)`` work and ``O(N w)`` memory, ``w = 3n + 1`` the bandwidth), or by sparse
LU (SuperLU) when the band is wide, then takes ``x + alpha dx`` with:

- a safeguard: ``alpha <= 0.99 alpha_max``, where ``alpha_max`` is the largest step that keeps
  every ``t_{k+1} - t_k >= tau_floor`` (the time-reversed root ``tau < 0`` of THEORY.md section 5
  is never approached);
- a backtracking line search on ``||F||_2``: ``alpha`` halves until
  ``||F(x + alpha dx)|| <= (1 - 1e-4 alpha) ||F(x)||``.

It stops when every ``|F_i|`` is below its ``target_i`` (given by the caller at a small multiple
of the row's round-off), or when no step decreases the residual any more (its floor of
round-off, or no solution nearby), and returns the iterate with the smallest residual, with what
happened in words (``outcome``). Whether that point solves the problem is the caller's
verification to decide.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse.linalg as spla
from scipy.linalg import lapack

from .bvp_assembly import Ends, GridAssembly

# Band storage above this bandwidth costs more than the sparse factorisation (fill-in of the
# whole band against the blocks' own).
WIDEST_BAND = 32


@dataclass
class NewtonResult:
    """The best iterate, whether the residual reached its target, and the history."""

    x: np.ndarray
    converged: bool
    outcome: str
    iterations: int
    residual_norms: list = field(default_factory=list)
    step_lengths: list = field(default_factory=list)


def solve_linear(assembly: GridAssembly, blocks, rhs: np.ndarray, linear: str) -> np.ndarray:
    """``dx`` with ``F'(x) dx = rhs``; ``nan`` if the Jacobian is singular."""
    width = assembly.layout.bandwidth
    if linear == "banded" or (linear == "auto" and width <= WIDEST_BAND):
        _, _, dx, info = lapack.dgbsv(width, width, assembly.banded(blocks), rhs,
                                      overwrite_ab=1, overwrite_b=1)
        return dx if info == 0 else np.full_like(rhs, np.nan)
    try:
        return spla.splu(assembly.sparse(blocks)).solve(rhs)
    except RuntimeError:  # SuperLU: "Factor is exactly singular"
        return np.full_like(rhs, np.nan)


def largest_admissible_step(assembly: GridAssembly, x, dx, tau_floor: float) -> float:
    """The largest ``alpha`` in ``(0, inf]`` with ``tau_k(x + alpha dx) >= tau_floor`` for all
    ``k``, given ``tau_k(x) >= tau_floor``."""
    where = assembly.layout.time_index()
    tau, dtau = np.diff(x[where]), np.diff(dx[where])
    shrinking = dtau < 0
    if not np.any(shrinking):
        return np.inf
    room = np.maximum(tau[shrinking] - tau_floor, 0.0)
    return float(np.min(room / -dtau[shrinking]))


def newton(assembly: GridAssembly, x0: np.ndarray, ends: Ends, target: np.ndarray, *,
           tau_floor: float, max_iter: int = 50, linear: str = "auto",
           deadline: float | None = None, progress=None) -> NewtonResult:
    """Newton's method with safeguard and line search (module docstring) from ``x0``.

    Args:
        assembly, ends: the system and its data.
        target: per-row bound on ``|F_i|`` at which the iteration has converged.
        tau_floor: smallest step the iterates may take.
        max_iter: iteration limit.
        linear: ``"banded"``, ``"sparse"`` or ``"auto"`` (banded up to ``WIDEST_BAND``).
        deadline: ``time.perf_counter()`` value after which to stop.
        progress: called as ``progress(iteration, residual_norm, alpha)`` after each iteration.
    """
    x = np.array(x0, float)
    F, blocks = assembly.evaluate(x, ends)
    norm = float(np.linalg.norm(F))
    result = NewtonResult(x, False, "", 0, [norm])
    if not np.isfinite(norm):
        result.outcome = "the start has non-finite residuals"
        return result
    for iteration in range(1, max_iter + 1):
        if np.all(np.abs(F) <= target):
            result.converged = True
            result.outcome = f"converged: every residual at its target after {iteration - 1} " \
                             f"iterations"
            return result
        if deadline is not None and time.perf_counter() > deadline:
            result.outcome = f"time limit reached after {iteration - 1} iterations"
            return result
        dx = solve_linear(assembly, blocks, -F, linear)
        if not np.all(np.isfinite(dx)):
            result.outcome = f"singular Jacobian at iteration {iteration}"
            return result
        step = _line_search(assembly, x, dx, ends, norm, tau_floor)
        if step is None:
            result.outcome = _stalled(F, target, norm, iteration)
            result.converged = result.outcome.startswith("converged")
            return result
        x, F, alpha = step
        norm = float(np.linalg.norm(F))
        result.x, result.iterations = x, iteration
        result.residual_norms.append(norm)
        result.step_lengths.append(alpha)
        if progress is not None:
            progress(iteration, norm, alpha)
        F, blocks = assembly.evaluate(x, ends)
    result.outcome = f"max_iter = {max_iter} reached, residual norm {norm:.3e}"
    result.converged = bool(np.all(np.abs(F) <= target))
    return result


def _line_search(assembly, x, dx, ends, norm, tau_floor):
    """``(x_new, F_new, alpha)`` of the first ``alpha = a_0, a_0/2, ...`` that decreases
    ``||F||`` enough, with ``a_0 = min(1, 0.99 alpha_max)``; ``None`` if none down to 1e-10."""
    alpha = min(1.0, 0.99 * largest_admissible_step(assembly, x, dx, tau_floor))
    while alpha >= 1e-10:
        trial = x + alpha * dx
        F, _ = assembly.evaluate(trial, ends, jacobian=False)
        trial_norm = float(np.linalg.norm(F))
        if np.isfinite(trial_norm) and trial_norm <= (1 - 1e-4 * alpha) * norm:
            return trial, F, alpha
        alpha /= 2
    return None


def _stalled(F, target, norm, iteration) -> str:
    """Why no step decreased the residual: round-off (every row within 100 targets, which are
    themselves a multiple of round-off) or a local minimum of ``||F||`` that is not a root."""
    ratio = float(np.max(np.abs(F) / target))
    if ratio <= 100:
        return (f"converged: residual at its round-off floor (largest |F_i| / target = "
                f"{ratio:.2g}) after {iteration - 1} iterations")
    return (f"stalled at iteration {iteration}: no step along the Newton direction decreases "
            f"the residual norm {norm:.3e} (a local minimum of |F|, no root nearby)")
