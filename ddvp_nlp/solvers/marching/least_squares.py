"""Kane, Marsden and Ortiz's least-squares step, where an energy step has no admissible root.

For a step from node ``k`` let ``z_{k+1}(tau)`` solve the canonical equations of the interval
``[t_k, t_k + tau]`` (a fixed-length step). The least-squares step takes the ``tau`` in
``[low, high]`` that minimises ``|r(tau)|``, the energy residual at node ``k`` (with the drift,
scaled as in the energy step), where ``[low, high]`` is ``[tau_min, tau_max]`` (default
``[tau_{k-1} / 10, 10 tau_{k-1}]``) cut to the steps ``max_step_ratio`` allows. ``|r|`` is
sampled on 16 log-spaced steps and its best sample refined by Brent's bounded search (scipy).
The energy equation then holds only up to the step's *energy defect*, which is recorded.
"""

from __future__ import annotations

import math

import numpy as np

from ...solution import Status
from .step_newton import NewtonSteps, StepResult
from .steps import EnergyCheck


def step_range(acceptance, tau_prev: float) -> tuple[float, float]:
    """``[low, high]``: the bounds of ``acceptance``, by default ``[tau_prev/10, 10 tau_prev]``."""
    low = acceptance.tau_min if acceptance.tau_min is not None else tau_prev / 10
    high = acceptance.tau_max if acceptance.tau_max is not None else 10 * tau_prev
    if acceptance.max_step_ratio is not None:
        low = max(low, tau_prev / acceptance.max_step_ratio)
        high = min(high, tau_prev * acceptance.max_step_ratio)
    return low, high


def least_squares_step(steps: NewtonSteps, t_prev, t_mid, z_prev, z_mid, drift,
                       failure: StepResult, step: int) -> tuple[StepResult, dict | None]:
    """The least-squares step from node ``step`` (at ``t_mid``) after the energy step failed
    with ``failure``, and its record ``{"step", "t", "tau", "energy_defect", "replaced"}``.

    If no step in the range solves the canonical equations, ``failure`` stands (its detail
    extended) and the record is ``None``."""
    from scipy.optimize import minimize_scalar

    f = steps.functions
    prefix = f"{failure.detail}; " if failure.detail else ""
    low, high = step_range(steps.acceptance, t_mid - t_prev)
    w = steps.energy_parameters(t_prev, t_mid, z_prev, z_mid, drift)
    if not 0 < low < high:
        return StepResult.failed(failure.status, prefix + (
            f"least-squares step: empty step range [{low:.3g}, {high:.3g}]")), None

    def solve(tau):
        result = steps.fixed_step(t_mid, t_mid + tau, z_mid)
        if result.status is not Status.SUCCESS:
            return None, math.inf
        x = np.concatenate([result.z_next, [tau]])
        return x, abs(float(np.asarray(f.energy_residual(x, w)).ravel()[-1]))

    grid = np.geomspace(low, high, 16)
    values = [solve(tau)[1] for tau in grid]
    best = int(np.argmin(values))
    if not math.isfinite(values[best]):
        return StepResult.failed(failure.status, prefix + (
            f"least-squares step: no step in [{low:.3g}, {high:.3g}] solves the canonical "
            "equations")), None
    bracket = (grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)])
    refined = minimize_scalar(lambda tau: solve(tau)[1], bounds=bracket, method="bounded",
                              options={"xatol": 1e-14 * bracket[1]})
    tau = float(refined.x) if refined.fun <= values[best] else float(grid[best])
    x, _ = solve(tau)
    check = EnergyCheck(*(float(v) for v in f.energy_check(x, w)))
    # The defect stays out of the compensated sum (``energy`` stays 0): the shifted level is the
    # new one. (Aiming the next steps back at the old level was tried: on the rotating pendulum
    # the nodal H then sat on the wrong side of the level and the steps shrank to zero.)
    # Step k goes from node k to k + 1; its energy equation, at node k, has the defect.
    record = {"step": step, "t": t_mid, "tau": tau, "energy_defect": check.energy,
              "replaced": failure.status.code}
    return StepResult(Status.SUCCESS, t_next=t_mid + tau, z_next=x[:-1], tau=tau,
                      H_node=check.H_node, w_node=check.w_node), record
