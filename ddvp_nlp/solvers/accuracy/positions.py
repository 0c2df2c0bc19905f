"""The accuracy check of a higher-order trajectory: its positions against the exact flow of the
Euler-Lagrange equation (``physics.higher.euler_lagrange_field``, Ostrogradsky's variables
``y = (q, q', ..., q^(2l-1))``), integrated by the reference flow (``reference.py``).

The same verdicts as for a trajectory in phase space (``accuracy.py``), on the positions alone
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

from ..exact.flow import MAX_SUBSTEPS, ReferenceFlow

NEWTON_ITERATIONS = 30
FIT_TOLERANCE = 1e-10  # of the motion's size
SHARE = 0.1  # of global_tol: the reference's own error


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


def _chain(reference: ReferenceFlow, t, y0, share_limit):
    """The reference flow from ``y0`` through ``t``, substeps doubled while ``|A - B|`` passes
    ``share_limit`` (an array per component of ``y``, or a number): rows ``0 ..``, and the
    largest ``|A - B|``."""
    substeps = 1
    while True:
        rows_a, rows_b = [y0[None, :]], [y0[None, :]]
        for _, a, b in reference.chain(t, y0, substeps):
            rows_a.append(a)
            rows_b.append(b)
        A, B = np.vstack(rows_a), np.vstack(rows_b)
        own = np.abs(A - B)
        if not np.all(own <= share_limit) and 2 * substeps <= MAX_SUBSTEPS and \
                np.all(np.isfinite(own)):
            substeps *= 2
            continue
        return B, float(np.max(own))


def fit_start(reference: ReferenceFlow, t, data_index, q, order, scale) -> tuple:
    """``y_0`` at ``t[0]`` of the motion of the exact flow through the positions ``q`` at the
    nodes ``data_index`` (Newton from the polynomial through the first ``2l`` nodes), or
    ``None`` with the reason."""
    n = q.shape[1]
    y = window_states(t, q, order, np.array([2 * order - 1]))[0]
    # the polynomial's derivatives at node 2l - 1, carried back to t_0 by Taylor's formula
    shift = t[0] - t[2 * order - 1]
    blocks = y.reshape(2 * order, n)
    y = np.concatenate([sum(blocks[j + i] * shift ** i / math.factorial(i)
                            for i in range(2 * order - j)) for j in range(2 * order)])
    span = t[data_index[-1]] - t[0]
    weights = np.concatenate([scale / max(span, 1e-300) ** j for j in range(2 * order)])
    target = FIT_TOLERANCE * scale
    last = data_index[-1] + 1
    for _ in range(NEWTON_ITERATIONS):
        states, _ = _chain(reference, t[:last], y, np.inf)
        residual = (states[data_index, :n] - q[data_index]).ravel()
        if not np.all(np.isfinite(residual)):
            return None, "the exact flow from the nodes' own start does not stay finite"
        if np.all(np.abs(residual.reshape(-1, n)) <= target):
            return y, ""
        jacobian = np.empty((residual.size, y.size))
        for j in range(y.size):
            nudged = y.copy()
            nudged[j] += 1e-7 * weights[j]
            moved, _ = _chain(reference, t[:last], nudged, np.inf)
            jacobian[:, j] = ((moved[data_index, :n] - q[data_index]).ravel() - residual) / (
                1e-7 * weights[j])
        step = np.linalg.lstsq(jacobian, -residual, rcond=None)[0]
        y = y + step
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
    reference = ReferenceFlow(system, theta, compiler=compiler, cache_dir=cache_dir)
    scale = _q_scales(q)
    motion, reason, estimate = _motion(reference, system, t, q, scale, tolerance, data, exact)
    if motion is None:
        report.update(verdict="inaccurate", scale=scale.tolist(), estimate="none",
                      first_failure={"step": t.size - 2, "t": float(t[-2]),
                                     "test": "continuous solution", "value": None,
                                     "limit": tolerance.global_tol, "detail": reason})
        return report, np.zeros(t.size - 1)
    scale = _q_scales(np.vstack([q, motion]))
    error = np.max(np.abs(q - motion) / scale, axis=1)
    over = np.flatnonzero(~(error <= tolerance.global_tol))
    local, failure, local_max = _local(reference, t, q, l, scale, tolerance)
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


def _motion(reference, system, t, q, scale, tolerance, data, exact):
    """The positions of the motion the run is measured against, at its nodes: the exact
    solution, or the exact flow through the data nodes; ``(None, reason, "")`` if none."""
    l, n = system.order, system.n  # noqa: E741
    if exact is not None:
        return np.asarray(exact(t), float).reshape(t.size, n), "", "exact solution"
    data = np.arange(2 * l) if data is None else np.asarray(data)
    y0, reason = fit_start(reference, t, data, q, l, scale)
    if y0 is None:
        return None, reason, ""
    share = np.concatenate([SHARE * tolerance.global_tol * scale,
                            np.full((2 * l - 1) * n, np.inf)])
    states, own = _chain(reference, t, y0, share)
    return states[:, :n], "", ("the exact Euler-Lagrange flow through the run's data "
                               f"(order-8 reference, its own error {own:.1e})")


def _local(reference, t, q, order, scale, tolerance):
    """The local error test of every step from node ``2l - 1`` on (module docstring)."""
    n = q.shape[1]
    limit = tolerance.rtol * scale + (tolerance.atol or 0.0)
    steps = t.size - 1
    local = np.zeros(steps)
    at = np.arange(2 * order - 1, steps)
    if not at.size:
        return local, None, 0.0
    y = window_states(t, q, order, at)
    substeps = 1
    while True:
        A, B = reference.maps(t[at], y, t[at + 1] - t[at], substeps)
        own = np.abs(A[:, :n] - B[:, :n])
        if np.all(own <= 0.1 * limit) or 2 * substeps > MAX_SUBSTEPS or \
                not np.all(np.isfinite(own)):
            break
        substeps *= 2
    d = np.abs(q[at + 1] - B[:, :n])
    local[at] = np.max(d, axis=1)
    ratio = np.max(d / limit, axis=1)
    relative = np.max(d / scale, axis=1)
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
            "linear_estimate_end": None, "linear_estimate_max": None, "level": None,
            "level_reference": None,
            "level_error": None, "energy_drift": None, "steps": max(steps, 0),
            "rtol": tolerance.rtol, "atol": tolerance.atol, "energy_tol": tolerance.energy_tol,
            "global_tol": tolerance.global_tol, "require_accurate": tolerance.require_accurate}
