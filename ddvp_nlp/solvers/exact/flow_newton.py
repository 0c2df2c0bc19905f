"""The one damped Newton on residuals of the exact flow (shooting, closure, transfer, fit):
``F(x) = 0`` with ``F`` a residual the exact flow evaluates and ``F'`` its variational
equations.

Each iteration takes ``x + dx / 2^k``, ``dx = step(x)`` (the caller's linear solve of
``F'(x) dx = -F(x)``, least squares where ``F`` has more rows than ``x``), with the smallest
``k <= halvings`` whose scaled residual ``size(F)`` shrinks (``halvings = 0``: the full step,
no test). It stops when ``size(F) <= tolerance`` (converged; a caller whose residual has parts
with scales of their own gives the test instead, ``converged(F, payload)``), when no halved
step shrinks the residual or an evaluation fails (not converged), or after ``max_iterations``
steps. Numerical failure is a status on the result, never an exception; the evaluation at the
last iterate (``payload``: the flow's tangents, the last Newton matrix) is kept on every path,
a failed one's too, for what the caller reads from it (a derivative, the conditioning, why).
The result states a bound of its own error: the size of the last step taken (in the caller's
scales), which bounds the distance to the root once the iteration converges quadratically.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class ExactNewtonResult:
    """What `exact_newton` found: the last iterate ``x`` and the evaluation there
    (``payload``, e.g. the flow's tangents), whether it converged, the steps taken, the last
    scaled residual (``inf`` after a failed evaluation), and ``error_bound``: the scaled size
    of the last step (``inf`` before any step)."""

    x: np.ndarray
    converged: bool
    iterations: int
    residual: float
    error_bound: float
    payload: Any = None
    failed_evaluation: bool = False


def exact_newton(evaluate: Callable, step: Callable, x: np.ndarray, *, size: Callable,
                 max_iterations: int, tolerance: float | None = None,
                 converged: Callable | None = None, halvings: int = 0,
                 step_size: Callable | None = None) -> ExactNewtonResult:
    """Newton on ``F(x) = 0`` (module docstring). ``evaluate(x) -> (F, payload)``, ``F``
    ``None`` where the flow fails (the payload is kept); ``step(x, F, payload) -> dx``;
    ``size(F)``: the scaled residual the damping compares and the result reports; the test of
    convergence is ``size(F) <= tolerance`` or the caller's ``converged(F, payload)``;
    ``step_size(dx)``: the scaled size of a step (default the largest ``|dx_i|``)."""
    step_size = step_size or (lambda dx: float(np.max(np.abs(dx))))
    residual, payload = evaluate(x)
    if residual is None:
        return ExactNewtonResult(x, False, 0, np.inf, np.inf, payload, True)
    current = size(residual)
    bound = np.inf
    for iteration in range(max_iterations + 1):
        if converged(residual, payload) if converged else current <= tolerance:
            return ExactNewtonResult(x, True, iteration, current, bound, payload)
        if iteration == max_iterations:
            break
        dx = step(x, residual, payload)
        if halvings == 0:
            trial = x + dx
            trial_residual, trial_payload = evaluate(trial)
            if trial_residual is None:
                return ExactNewtonResult(trial, False, iteration + 1, np.inf, step_size(dx),
                                         trial_payload, True)
            trial_size = size(trial_residual)
        else:
            for _ in range(halvings):  # damped: the scaled residual must shrink
                trial = x + dx
                trial_residual, trial_payload = evaluate(trial)
                if trial_residual is not None:
                    trial_size = size(trial_residual)
                    if trial_size < current:
                        break
                dx = dx / 2
            else:
                break
        x, residual, payload, current = trial, trial_residual, trial_payload, trial_size
        bound = step_size(dx)
    return ExactNewtonResult(x, False, max_iterations, current, bound, payload)
