"""Newton's method on the square fixed-endpoint system ``F(x) = 0`` (``bvp_assembly.py``).

Each iteration solves ``F'(x) dx = -F(x)`` by LU factorisation of the banded Jacobian (LAPACK's
``gbtrf``/``gbtrs``, compiled (``bvp_band.py``) or through scipy: ``O(N w^2)`` work and
``O(N w)`` memory, ``w = 3n + 1`` the bandwidth), or by sparse LU (SuperLU) when the band is
wide, then takes ``x + alpha dx`` with:

- a safeguard: ``alpha <= 0.99 alpha_max``, where ``alpha_max`` is the largest step that keeps
  every ``t_{k+1} - t_k >= tau_floor`` (the time-reversed root ``tau < 0`` of docs/theory.md
  section 7 is never approached);
- a backtracking line search with Deuflhard's natural monotonicity test: ``alpha`` halves
  until the simplified Newton correction ``|F'(x)^-1 F(x + alpha dx)|`` is at most
  ``(1 - alpha/2) |dx|`` (the residual norm in the units of ``x``, so that no row's scale
  decides; the factors of ``F'(x)`` are reused).

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

from ..bvp.assembly import Ends, GridAssembly
from . import band as bvp_band

# Band storage above this bandwidth costs more than the sparse factorisation (fill-in of the
# whole band against the blocks' own).
WIDEST_BAND = 32
# Near the round-off floor (every |F_i| within this many targets) a step that does not pass the
# monotonicity test ends the iteration instead of being halved.
FLOOR_FACTOR = 64


@dataclass
class NewtonResult:
    """The best iterate, whether the residual reached its target, and the history."""

    x: np.ndarray
    converged: bool
    outcome: str
    iterations: int
    residual_norms: list = field(default_factory=list)
    step_lengths: list = field(default_factory=list)


class Factorization:
    """LU factors of ``F'(x)``: banded up to ``WIDEST_BAND`` (LAPACK's ``gbtrf``, compiled by
    ``bvp_band.py`` when there is a compiler, else through scipy: the same factors), else sparse
    (SuperLU); ``solve(rhs)`` is ``nan`` if the matrix is singular. The band is factorised in
    place, in the assembly's store."""

    def __init__(self, assembly: GridAssembly, blocks, linear: str):
        self.width = assembly.layout.bandwidth
        self.banded = linear == "banded" or (linear == "auto" and self.width <= WIDEST_BAND)
        self.singular = False
        self.kernel = None
        if self.banded:
            ab = assembly.banded(blocks)
            self.kernel = bvp_band.kernel() if ab.flags.f_contiguous else None
            if self.kernel is not None:
                self.pivots, info = self.kernel.factor(ab, self.width, self.width)
                self.lu = ab
            else:
                self.lu, self.pivots, info = lapack.dgbtrf(ab, self.width, self.width,
                                                           overwrite_ab=1)
            self.singular = info != 0
            return
        try:
            self.lu = spla.splu(assembly.sparse(blocks))
        except RuntimeError:  # SuperLU: "Factor is exactly singular"
            self.singular = True

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``F'(x)^-1 rhs``; ``rhs`` (a temporary of the caller's) may be overwritten."""
        if self.singular:
            return np.full_like(rhs, np.nan)
        if self.kernel is not None:
            return self.kernel.solve(self.lu, self.width, self.width, self.pivots, rhs)
        if self.banded:
            return lapack.dgbtrs(self.lu, self.width, self.width, rhs, self.pivots,
                                 overwrite_b=1)[0]
        return self.lu.solve(rhs)


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
    try:
        return _newton(assembly, x0, ends, target, tau_floor=tau_floor, max_iter=max_iter,
                       linear=linear, deadline=deadline, progress=progress)
    finally:
        release = getattr(assembly, "release", None)
        if release is not None:  # the band store (312 MB at N = 1e6): not kept by the cache
            release()


def _newton(assembly, x0, ends, target, *, tau_floor, max_iter, linear, deadline, progress):
    x = np.array(x0, float)
    F, _ = assembly.evaluate(x, ends, jacobian=False)
    norm = float(_norm(F))
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
        # F(x) is at hand (the start's, or the line search's); the Jacobian only now, when a
        # step is needed: a converged phase evaluates none
        _, blocks = assembly.evaluate(x, ends)
        lu = Factorization(assembly, blocks, linear)
        dx = lu.solve(-F)
        if not np.all(np.isfinite(dx)):
            result.outcome = f"singular Jacobian at iteration {iteration}"
            return result
        step = _line_search(assembly, lu, x, dx, ends, tau_floor, near_floor=bool(
            np.all(np.abs(F) <= FLOOR_FACTOR * target)))
        if step is None:
            result.outcome = _stalled(F, target, norm, iteration)
            result.converged = result.outcome.startswith("converged")
            return result
        x, F, alpha = step
        norm = float(_norm(F))
        result.x, result.iterations = x, iteration
        result.residual_norms.append(norm)
        result.step_lengths.append(alpha)
        if progress is not None:
            progress(iteration, norm, alpha)
    result.outcome = f"max_iter = {max_iter} reached, residual norm {norm:.3e}"
    result.converged = bool(np.all(np.abs(F) <= target))
    return result


def _line_search(assembly, lu, x, dx, ends, tau_floor, near_floor):
    """``(x_new, F_new, alpha)`` of the first ``alpha = a_0, a_0/2, ...`` that passes the
    natural monotonicity test ``|F'(x)^-1 F(x + alpha dx)| <= (1 - alpha/2) |dx|`` (Deuflhard:
    the residual measured in the Newton correction's own units, so that badly scaled rows do not
    reject good steps; the 2-norm of ``F`` rejected the first full step on the pendulum at
    N = 1e4 and took 32 iterations where this takes 3), with ``a_0 = min(1, 0.99 alpha_max)``;
    ``None`` if none down to 1e-10, or at once if the residual is already near its floor."""
    alpha = min(1.0, 0.99 * largest_admissible_step(assembly, x, dx, tau_floor))
    size = float(_norm(dx))
    while alpha >= 1e-10:
        trial = x + alpha * dx
        F, _ = assembly.evaluate(trial, ends, jacobian=False)
        if np.all(np.isfinite(F)):
            correction = float(_norm(lu.solve(-F)))
            if np.isfinite(correction) and correction <= (1 - alpha / 2) * size:
                return trial, F, alpha
        if near_floor:
            return None
        alpha /= 2
    return None


def _norm(v: np.ndarray) -> float:
    """The 2-norm without BLAS: numpy's ``dot`` took 7 ms on 3e4 values (OpenBLAS threads
    waking up), einsum 20 us."""
    return float(np.sqrt(np.einsum("i,i->", v, v)))


def _stalled(F, target, norm, iteration) -> str:
    """Why no step passed: round-off (every row within ``FLOOR_FACTOR`` targets, which are
    themselves a multiple of round-off) or no root nearby."""
    ratio = float(np.max(np.abs(F) / target))
    if ratio <= FLOOR_FACTOR:
        return (f"converged: residual at its round-off floor (largest |F_i| / target = "
                f"{ratio:.2g}) after {iteration - 1} iterations")
    return (f"stalled at iteration {iteration}: no step along the Newton direction passes the "
            f"monotonicity test, residual norm {norm:.3e} (no root nearby)")
