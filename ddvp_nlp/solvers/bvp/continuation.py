"""Continuation of the fixed-step problem in its end position, past turning points
(pseudo-arclength): the start of last resort of ``start.py``.

A march of fixed steps from ``(q_start, p_0)`` solves the fixed-endpoint problem whose end
position is its own last position ``a``. Moving the end position along ``q_end(s) = a + s d``,
``d = q_end - a``, from ``s = 0`` to ``s = 1`` carries that solution to the problem asked for,
unless the path of solutions turns back in ``s`` (a fold: two solutions meet and vanish). There
a continuation in ``s`` itself stops (tried: on the pendulum from 0.5 to -0.3 in 10 time units
it stopped at ``s = 0.61``, on Henon-Heiles at ``s = 0.02-0.88``). Here the unknowns are
``y = (x, s)`` and each step moves a length ``h`` along the path's tangent ``T``:

- predictor ``y + h T``; corrector: Newton on ``F(x, s) = 0`` together with
  ``<T, y - y_pred> = 0`` (the hyperplane through the prediction across the path), solved by
  bordering with the banded LU of ``F_x``: ``dx = z_1 + ds z_2`` with ``F_x z_1 = -F`` and
  ``F_x z_2 = -F_s`` (``F_s = -d`` on the end rows), which stays well posed at a fold where
  ``F_x`` alone is singular;
- the tangent is the secant of the last two points (its orientation kept), ``h`` grows by half
  after a corrector that converged in a few iterations and halves after one that failed;
- in ``<., .>`` the ``x`` part is divided by the number of unknowns, so that ``s`` counts as much
  as the whole grid.

When a step crosses ``s = 1`` the point at ``s = 1`` is interpolated and handed back; the caller
solves the problem there (``start.py``). The solution found is the one connected to
the march by the path: ``stats["p_sign_changes"]`` of the result says which it is.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from ..grid.linear import Factorization, band_kernel
from ..grid.problem import GridRequest
from .assembly import Ends, NodeLayout
from .phase import Boundary, assembly

FIRST_STEP = 0.05
SMALLEST_STEP = 1e-5
LARGEST_STEP = 0.5
MAX_STEPS = 400
CORRECTOR_ITERATIONS = 8
# The corrector has converged when every |F_i| is below this times max(1, |x|_inf).
CORRECTOR_TOL = 1e-10


def continue_in_end_position(request: GridRequest[Boundary], fixed, times, base: dict):
    """The fixed-step problem's nodes near ``s = 1`` on the path from the march ``base``
    (module docstring), as a start (``dict`` of ``t``, ``q``, ``p``), or ``None``; the phase
    record in ``request.phases`` says how far it got."""
    layout = NodeLayout(request.system.n, request.nodes)
    grid = assembly(request, fixed)
    n, size = request.system.n, layout.size
    a = np.asarray(base["q"][-1], float)
    d = request.data.q_end - a
    F_s = np.zeros(size)
    F_s[-n:] = -d
    weight = np.concatenate([np.full(size, 1.0 / size), [1.0]])
    kernel = band_kernel(request.compilation)

    def factor(blocks):
        return Factorization(grid, blocks, request.linear, kernel)

    record = {"phase": "continuation in q_end (fixed steps, pseudo-arclength)",
              "solver": "newton (bordered)", "converged": False, "return_status": "",
              "iterations": 0, "steps": 0}
    request.phases.append(record)
    started = time.perf_counter()

    def ends(s):
        return Ends(request.data.q_start, a + s * d, np.asarray(times, float), request.theta, 1.0)

    y = np.concatenate([layout.pack(times, base["q"], base["p"]), [0.0]])
    h, result = FIRST_STEP, None
    try:
        tangent = _first_tangent(grid, y, ends, F_s, weight, factor)
        if tangent is None:
            record["return_status"] = "the Jacobian at the march is singular: no tangent"
        while record["steps"] < MAX_STEPS and tangent is not None:
            if request.remaining() == 0.0:
                record["return_status"] = f"time limit reached at s = {y[-1]:.4g}"
                break
            corrected, iterations = _corrector(grid, y + h * tangent, tangent, ends, F_s,
                                               weight, factor)
            record["iterations"] += iterations
            record["steps"] += 1
            if corrected is None:
                h /= 2
                if h < SMALLEST_STEP:
                    record["return_status"] = (f"the step fell below {SMALLEST_STEP:g} at "
                                               f"s = {y[-1]:.4g}")
                    break
                continue
            if corrected[-1] >= 1.0:
                w = (1.0 - y[-1]) / (corrected[-1] - y[-1])
                point = y + w * (corrected - y)
                t, q, p = layout.unpack(point[:-1])
                result = {"t": t, "q": q, "p": p}
                record.update(converged=True, return_status=f"s = 1 reached in "
                              f"{record['steps']} steps")
                break
            secant = corrected - y
            tangent = secant / _norm(secant, weight)
            y = corrected
            if request.progress:
                print(f"bvp [continuation]: step {record['steps']}, s = {y[-1]:.6g}, "
                      f"arclength step {h:.3g}", file=sys.stderr, flush=True)
            if iterations <= 3:
                h = min(LARGEST_STEP, 1.5 * h)
        else:
            if tangent is not None:
                record["return_status"] = f"{MAX_STEPS} steps without reaching s = 1 " \
                                          f"(s = {y[-1]:.4g})"
    finally:
        grid.release()
    record["seconds"] = time.perf_counter() - started
    return result


def _norm(v, weight) -> float:
    return float(np.sqrt(np.sum(weight * v * v)))


def _first_tangent(grid, y, ends, F_s, weight, factor):
    """The tangent at the march (``s`` increasing): ``(F_x^-1 (-F_s), 1)``, normalised."""
    _, blocks = grid.evaluate(y[:-1], ends(y[-1]), jacobian=True)
    lu = factor(blocks)
    z = lu.solve(-F_s.copy())
    if not np.all(np.isfinite(z)):
        return None
    tangent = np.concatenate([z, [1.0]])
    return tangent / _norm(tangent, weight)


def _corrector(grid, prediction, tangent, ends, F_s, weight, factor):
    """Newton on ``F(x, s) = 0``, ``<tangent, y - prediction> = 0`` by bordering (module
    docstring): ``(y, iterations)``, ``y`` ``None`` if it did not converge."""
    y = prediction.copy()
    for iteration in range(1, CORRECTOR_ITERATIONS + 1):
        F, blocks = grid.evaluate(y[:-1], ends(y[-1]), jacobian=True)
        if not np.all(np.isfinite(F)):
            return None, iteration
        if np.max(np.abs(F)) <= CORRECTOR_TOL * max(1.0, float(np.max(np.abs(y[:-1])))):
            return y, iteration - 1
        lu = factor(blocks)
        z1 = lu.solve(-F)
        z2 = lu.solve(-F_s.copy())
        if not (np.all(np.isfinite(z1)) and np.all(np.isfinite(z2))):
            return None, iteration
        g = float(np.sum(weight * tangent * (y - prediction)))
        wx = weight[:-1] * tangent[:-1]
        denominator = float(wx @ z2) + weight[-1] * tangent[-1]
        if denominator == 0.0:
            return None, iteration
        ds = (-g - float(wx @ z1)) / denominator
        y[:-1] += z1 + ds * z2
        y[-1] += ds
    return None, CORRECTOR_ITERATIONS
