"""The accuracy check of a higher-order trajectory: its positions against the exact flow of the
Euler-Lagrange equation (``physics.higher_order.euler_lagrange_field``, Ostrogradsky's variables
``y = (q, q', ..., q^(2l-1))``), integrated by the exact flow (``exact/``).

The same verdicts as for a trajectory in phase space (``judgement.py``), on the positions alone
(the nodes carry no derivatives), every figure relative to ``S_i``, the range of ``q_i`` over
the run (at least a tenth of the largest range):

1. **Local error** of every step ``k >= 2l - 1``: the state ``y_k`` of the polynomial of degree
   ``2l - 1`` through the ``2l`` nodes ``k - 2l + 1 .. k`` (its derivatives at ``t_k``), carried
   by the exact flow to ``t_{k+1}``, against ``q_{k+1}``; it fails above ``rtol S``. The
   polynomial's own error is ``O(tau^(2l))``, as the scheme's; where it is large the step does
   not resolve the motion either.
2. **Trajectory error** against the motion of the exact flow through the run's data (the
   exact solution where one is given): ``y_0`` such that the flow passes through the first
   ``2l`` nodes (a march: its start), or through the ``l`` fixed nodes at each end (a
   fixed-endpoint problem), found by Newton from the polynomial's derivatives. A fixed-endpoint
   problem with no such motion is refused (``inaccurate``) with that reason.

There is no energy test: the Ostrogradsky energy is not the one the discrete rules keep.
"""

from __future__ import annotations

import math

import numpy as np

from ..columns import row_max, row_max_ratio
from ..exact.flow import exact_flow
from ..exact.flow_newton import exact_newton
from ..exact.reference import FACTOR, FLOOR_RTOL, reference
from ..exact.short_flows import short_flows
from ..exact.tolerance import EXACT_TOLERANCE

NEWTON_ITERATIONS = 30  # evaluations of the fit's Newton
FIT_TOLERANCE = EXACT_TOLERANCE.newton_tol  # of the motion's size
FIT_RTOL = EXACT_TOLERANCE.flow_rtol  # the flow's tolerance while fitting the start
SHARE = 0.1  # of global_tol: the reference's own error
# the reference's first tolerance (tighter by 100 while it must be)
REFERENCE_RTOL = EXACT_TOLERANCE.reference_rtol


def window_states(t: np.ndarray, q: np.ndarray, order: int, at: np.ndarray) -> np.ndarray:
    """For each index ``k`` in ``at``: the derivatives ``(q, q', ..., q^(2l-1))`` at ``t_k`` of
    the polynomial of degree ``2l - 1`` through the nodes ``k - 2l + 1 .. k``, as rows
    ``(len(at), 2l n)``."""
    width = 2 * order
    n = q.shape[1]
    offsets = np.arange(-width + 1, 1)
    index = at[:, None] + offsets[None, :]  # (K, 2l)
    s = t[index] - t[at][:, None]
    vandermonde = s[:, :, None] ** np.arange(width)[None, None, :]  # (K, 2l, 2l)
    coefficients = np.linalg.solve(vandermonde, q[index])  # (K, 2l, n)
    factorial = np.array([math.factorial(j) for j in range(width)], float)
    derivatives = coefficients * factorial[None, :, None]
    return derivatives.reshape(at.size, width * n)


def _weights(scale: np.ndarray, order: int, span: float) -> np.ndarray:
    """The size of each of Ostrogradsky's variables ``(q, q', ..., q^(2l-1))``: the positions'
    scale over the span's powers."""
    return np.concatenate([scale / max(span, 1e-300) ** j for j in range(2 * order)])


def fit_start(system, theta, t, data_index, q, order, scale, *, compiler=None,
              cache_dir=None) -> tuple:
    """``y_0`` at ``t[0]`` of the motion of the exact flow through the positions ``q`` at the
    nodes ``data_index`` (Newton from the polynomial through the first ``2l`` nodes, its
    Jacobian from the variational equations), or ``None`` with the reason."""
    n = q.shape[1]
    y = window_states(t, q, order, np.array([2 * order - 1]))[0]
    # the polynomial's derivatives at node 2l - 1, carried back to t_0 by Taylor's formula
    shift = t[0] - t[2 * order - 1]
    blocks = y.reshape(2 * order, n)
    y = np.concatenate([sum(blocks[j + i] * shift ** i / math.factorial(i)
                            for i in range(2 * order - j)) for j in range(2 * order)])
    weights = _weights(scale, order, t[data_index[-1]] - t[0])
    target = FIT_TOLERANCE * scale
    flow = exact_flow(system, tangent=y.size, compiler=compiler, cache_dir=cache_dir)
    times = t[data_index]

    def evaluate(y_value):
        with np.errstate(all="ignore"):
            run = flow.run(y_value, t[0], times[-1], theta, rtol=FIT_RTOL,
                           atol=FIT_RTOL * weights)
            states = run.z(times) if run.success else np.full((times.size, y.size), np.nan)
        residual = (states[:, :n] - q[data_index]).ravel()
        return (residual if np.all(np.isfinite(residual)) else None), run

    def step(_y, residual, run):  # least squares: more positions than unknowns
        jacobian = run.Y(times)[:, :n, :].reshape(-1, y.size)
        return np.linalg.lstsq(jacobian, -residual, rcond=None)[0]

    def scaled(values, sizes):  # the largest |v_i| / s_i (inf past the largest float)
        with np.errstate(over="ignore"):
            return float(np.max(np.abs(values) / sizes))

    result = exact_newton(
        evaluate, step, y, size=lambda residual: scaled(residual.reshape(-1, n), scale),
        converged=lambda residual, _run: bool(np.all(np.abs(residual.reshape(-1, n)) <= target)),
        max_iterations=NEWTON_ITERATIONS - 1, step_size=lambda dy: scaled(dy, weights))
    if result.failed_evaluation:
        return None, "the exact flow from the nodes' own start does not stay finite"
    if result.converged:
        return result.x, ""
    return None, ("no motion of the exact flow passes through the given nodes (Newton on its "
                  "initial state did not converge)")


def judge_higher(system, t, q, theta, tolerance, *, data=None, exact=None, compiler=None,
                 cache_dir=None) -> tuple[dict, np.ndarray]:
    """The report (as ``accuracy.Judgement.report``'s) and the local errors ``|d_k|_inf`` of a
    higher-order trajectory ``t`` (N+1,), ``q`` (N+1, n). ``data``: the indices of the nodes
    the motion is defined by (default the first ``2l``); ``exact``: ``exact(t) -> q`` (rows),
    the motion itself where known."""
    t, q = np.asarray(t, float), np.asarray(q, float)
    l = system.order  # noqa: E741 (l is the order, as in the paper)
    report = _empty_report(tolerance, t.size - 1)
    if t.size < 2 * l + 1 or not (np.all(np.isfinite(q)) and np.all(np.isfinite(t))):
        if not np.all(np.isfinite(q)):
            report.update(verdict="inaccurate", first_failure={
                "step": 0, "t": float(t[0]), "test": "finite nodes", "value": None,
                "limit": None, "detail": "a node is not finite"})
        return report, np.zeros(max(t.size - 1, 0))
    flows = {"compiler": compiler, "cache_dir": cache_dir}
    scale = _q_scales(q)
    motion, reason, estimate = _motion(system, theta, t, q, scale, tolerance, data, exact,
                                       flows)
    if motion is None:
        report.update(verdict="inaccurate", scale=scale.tolist(), estimate="none",
                      first_failure={"step": t.size - 2, "t": float(t[-2]),
                                     "test": "continuous solution", "value": None,
                                     "limit": tolerance.global_tol, "detail": reason})
        return report, np.zeros(t.size - 1)
    scale = _q_scales(np.vstack([q, motion]))
    error = row_max_ratio(np.abs(q - motion), scale)
    over = np.flatnonzero(~(error <= tolerance.global_tol))
    local, failure, local_max = _local(system, theta, t, q, l, scale, tolerance, flows)
    verdict = "inaccurate" if failure else ("drifted" if over.size else "accurate")
    report.update(verdict=verdict, first_failure=failure, scale=scale.tolist(),
                  estimate=estimate, error_max=float(np.max(error)),
                  error_max_t=float(t[int(np.argmax(error))]),
                  t_drift=float(t[over[0]]) if over.size else None,
                  drift_step=int(over[0]) if over.size else None,
                  reference_until=float(t[-1]), local_error_max=local_max)
    return report, local


def _q_scales(q: np.ndarray) -> np.ndarray:
    """The scales of the positions alone (one block)."""
    span = np.ptp(q, axis=0)
    scale = np.maximum(span, 0.1 * np.max(span))
    return np.maximum(np.maximum(scale, 1e-12 * np.max(np.abs(q), axis=0)),
                      np.finfo(float).tiny)


def _motion(system, theta, t, q, scale, tolerance, data, exact, flows):
    """The positions of the motion the run is measured against, at its nodes: the exact
    solution, or the exact flow through the data nodes (``exact/reference.py``, its own error
    on the positions held below ``SHARE * global_tol``); ``(None, reason, "")`` if none."""
    l, n = system.order, system.n  # noqa: E741
    if exact is not None:
        return np.asarray(exact(t), float).reshape(t.size, n), "", "exact solution"
    data = np.arange(2 * l) if data is None else np.asarray(data)
    y0, reason = fit_start(system, theta, t, data, q, l, scale, **flows)
    if y0 is None:
        return None, reason, ""
    weights = _weights(scale, l, t[-1] - t[0])
    # the claim on the positions alone: the derivatives' entries count as far below their size
    claim_scale = np.concatenate([scale, np.full((2 * l - 1) * n, np.inf)])
    flow = exact_flow(system, **flows)
    rtol = REFERENCE_RTOL
    while True:
        ref = reference(flow, y0, t[0], t[-1], theta, weights, rtol=rtol)
        own = float(np.max(ref.error(t, claim_scale)))
        if own <= SHARE * tolerance.global_tol or rtol / 100 < FLOOR_RTOL * FACTOR:
            break
        rtol /= 100
    with np.errstate(invalid="ignore", over="ignore"):
        states = ref.states(t)
    return states[:, :n], "", ("the exact Euler-Lagrange flow through the run's data "
                               f"(adaptive order-8 reference, its own error {own:.1e})")


def _local(system, theta, t, q, order, scale, tolerance, flows):
    """The local error test of every step from node ``2l - 1`` on (module docstring): the
    exact flow over each step (``exact/short_flows.py``) from the window's derivatives, its
    own error on the positions held below a tenth of the bound."""
    n = q.shape[1]
    limit = tolerance.rtol * scale + (tolerance.atol or 0.0)
    steps = t.size - 1
    local = np.zeros(steps)
    at = np.arange(2 * order - 1, steps)
    if not at.size:
        return local, None, 0.0
    y = window_states(t, q, order, at)
    budget = np.concatenate([SHARE * limit, np.full((2 * order - 1) * n, np.inf)])
    with np.errstate(invalid="ignore", over="ignore"):
        phi, _, _ = short_flows(system, **flows)(t[at], y, t[at + 1] - t[at], theta, budget)
    d = np.abs(q[at + 1] - phi[:, :n])
    local[at] = row_max(d)
    ratio = row_max_ratio(d, limit)
    relative = row_max_ratio(d, scale)
    bad = np.flatnonzero(~(ratio <= 1.0))
    failure = None
    if bad.size:
        k = int(at[bad[0]])
        failure = {"step": k, "t": float(t[k]), "test": "local error",
                   "value": float(relative[bad[0]]), "limit": tolerance.rtol}
    return local, failure, float(np.nanmax(relative)) if relative.size else 0.0


def _empty_report(tolerance, steps: int) -> dict:
    return {"verdict": "accurate", "first_failure": None, "t_drift": None, "drift_step": None,
            "error_max": 0.0, "error_max_t": None, "estimate": "none (too few nodes)",
            "reference_until": None, "reference_error": None, "reference_lost": None,
            "scale": None, "energy_scale": None, "local_error_max": 0.0,
            "level": None, "level_reference": None, "level_error": None, "energy_drift": None,
            "steps": max(steps, 0),
            "rtol": tolerance.rtol, "atol": tolerance.atol, "energy_tol": tolerance.energy_tol,
            "global_tol": tolerance.global_tol, "require_accurate": tolerance.require_accurate}
