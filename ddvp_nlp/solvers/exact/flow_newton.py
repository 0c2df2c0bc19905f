"""The one damped Newton on residuals of the exact flow (shooting, closure, transfer, fit):
``F(x) = 0`` with ``F`` a residual the exact flow evaluates and ``F'`` its variational
equations.

Each iteration takes ``x + dx / 2^k``, ``dx = step(x)`` (the caller's linear solve of
``F'(x) dx = -F(x)``), with the smallest ``k <= halvings`` whose scaled residual ``size(F)``
shrinks (``halvings = 0``: the full step, no test). It stops when ``size(F) <= tolerance``
(converged), when no halved step shrinks the residual or an evaluation fails (not converged),
or after ``max_iterations`` steps. Numerical failure is a status on the result, never an
exception. The result states a bound of its own error: the size of the last step taken (in the
caller's scales), which bounds the distance to the root once the iteration converges
quadratically.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class ExactNewtonResult:
    """What `exact_newton` found: the last iterate ``x`` and the evaluation there
    (``payload``, e.g. the flow's tangents), whether the scaled residual reached the tolerance,
    the steps taken, the last scaled residual, and ``error_bound``: the scaled size of the
    last step (``inf`` before any step)."""

    x: np.ndarray
    converged: bool
    iterations: int
    residual: float
    error_bound: float
    payload: Any = None
    failed_evaluation: bool = False


def exact_newton(evaluate: Callable, step: Callable, x: np.ndarray, *, size: Callable,
                 tolerance: float, max_iterations: int, halvings: int = 0,
                 step_size: Callable | None = None) -> ExactNewtonResult:
    """Newton on ``F(x) = 0`` (module docstring). ``evaluate(x) -> (F, payload)`` or
    ``(None, None)`` where the flow fails; ``step(x, F, payload) -> dx``; ``size(F)``: the
    scaled residual the tolerance and the damping compare; ``step_size(dx)``: the scaled size
    of a step (default the largest ``|dx_i|``)."""
    step_size = step_size or (lambda dx: float(np.max(np.abs(dx))))
    residual, payload = evaluate(x)
    if residual is None:
        return ExactNewtonResult(x, False, 0, np.inf, np.inf, None, True)
    current = size(residual)
    bound = np.inf
    for iteration in range(max_iterations + 1):
        if current <= tolerance:
            return ExactNewtonResult(x, True, iteration, current, bound, payload)
        if iteration == max_iterations:
            break
        dx = step(x, residual, payload)
        if halvings == 0:
            trial = x + dx
            trial_residual, trial_payload = evaluate(trial)
            if trial_residual is None:
                return ExactNewtonResult(trial, False, iteration + 1, np.inf, step_size(dx),
                                         None, True)
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
