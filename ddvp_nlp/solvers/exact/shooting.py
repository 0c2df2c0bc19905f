"""The continuous fixed-endpoint problem near a discrete solution: is there a motion of the exact
flow from ``q_start`` at ``t_0`` to ``q_end`` at ``t_end``, and which?

A discrete solution can exist where the continuous problem has none: the harmonic oscillator
``H = (p^2 + q^2)/2`` from ``q = 1`` at ``t = 0`` reaches ``q = -1`` at ``t = pi`` whatever its
momentum (``t = pi`` is conjugate to ``0``), so no motion goes to ``q = 0.5``, yet the grid's
equations, whose discrete half period differs from ``pi``, have a solution with a huge momentum.

Multiple shooting on segments the flow's own error control chooses: a pilot run of the exact
flow from the discrete solution's start is cut every ``STEPS_PER_SEGMENT`` accepted steps (each
segment is as much motion as that many steps resolve, wherever the motion is fast or slow, and
however many nodes the grid has). Unknowns ``x = (p_0, z_1, ..., z_{S-1})``; equations: the
continuity ``phi_j(z_j) - z_{j+1} = 0`` at every cut and ``q(phi_{S-1}(z_{S-1})) = q_end``.
Newton's Jacobian is block-bidiagonal, its blocks the variational equations' ``Y_j`` over each
segment and ``-I``, solved as a band (never a dense ``(S 2n)^2`` matrix); the step is damped
until the scaled residual shrinks. Converged, the solution is the segments' dense output, read
at any times (the grid's nodes: a 10^6-node grid costs this check what a 10^3-node one does).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .flow import exact_flow
from .flow_newton import exact_newton
from .tolerance import EXACT_TOLERANCE
from .trajectory import Trajectory, concatenate

STEPS_PER_SEGMENT = 16
MAX_ITERATIONS = 30
# continuity and the end position must hold to this fraction of the motion's size
TOLERANCE = EXACT_TOLERANCE.newton_tol
# the flow's tolerance (its error is then far below TOLERANCE of the motion's size)
RTOL = EXACT_TOLERANCE.flow_rtol


@dataclass
class Shot:
    """The continuous solution (``trajectory``, dense over the span; ``None`` where there is
    none), its initial momentum, the segments' ends, Newton's iterations and its last scaled
    residual, and, where there is no solution, why."""

    trajectory: Trajectory | None
    p0: np.ndarray | None
    cuts: np.ndarray
    iterations: int
    residual: float
    reason: str = ""

    def states(self, times) -> np.ndarray:
        """The continuous solution at ``times``: rows ``(q, p)``."""
        return self.trajectory.z(times)


def shoot(system, theta, t: np.ndarray, z: np.ndarray, q_end, scale, *,
          compiler: str | None = "auto", cache_dir=None) -> Shot:
    """The continuous solution from ``q_start = z[0, :n]`` at ``t[0]`` to ``q_end`` at
    ``t[-1]`` nearest to the discrete solution ``z`` (rows at ``t``), Newton started from the
    discrete solution itself; ``scale``: the motion's size per component (module
    docstring)."""
    n = z.shape[1] // 2
    d = 2 * n
    theta = np.asarray(theta, float)
    scale = np.asarray(scale, float)
    q_start, q_end = z[0, :n], np.asarray(q_end, float)
    flow = exact_flow(system, compiler=compiler, cache_dir=cache_dir)
    tangent = exact_flow(system, tangent=d, dense=False, slots=4 * STEPS_PER_SEGMENT,
                         compiler=compiler, cache_dir=cache_dir)
    atol = RTOL * scale
    t0, t1 = float(t[0]), float(t[-1])
    pilot = flow.run(z[0], t0, t1, theta, rtol=RTOL, atol=atol)
    cuts = np.concatenate([[t0], pilot.t_old[STEPS_PER_SEGMENT::STEPS_PER_SEGMENT], [t1]])
    if cuts.size > 2 and abs(cuts[-1] - cuts[-2]) < 0.25 * abs(cuts[-2] - cuts[-3]):
        cuts = np.delete(cuts, -2)  # no sliver of a last segment
    segments = cuts.size - 1
    weights = np.concatenate([np.tile(scale, segments - 1), scale[:n]])
    x = np.concatenate([z[0, n:], _at(t, z, cuts[1:-1]).ravel()])

    def starts_of(x_value):
        return np.vstack([np.concatenate([q_start, x_value[:n]]), x_value[n:].reshape(-1, d)])

    def evaluate(x_value):
        starts = starts_of(x_value)
        ends, tangents = np.empty((segments, d)), np.empty((segments, d, d))
        for j in range(segments):
            run = tangent.run(starts[j], cuts[j], cuts[j + 1], theta, rtol=RTOL, atol=atol)
            if not run.success or not np.all(np.isfinite(run.w_end)):
                return None, None
            ends[j], tangents[j] = run.z_end, run.Y_end
        residual = np.concatenate([(ends[:-1] - starts[1:]).ravel(), ends[-1, :n] - q_end])
        return residual, tangents

    def newton_step(_x, residual, tangents):
        return -banded_solve(tangents, residual, n)

    result = exact_newton(evaluate, newton_step, x, size=lambda residual: float(
        np.max(np.abs(residual) / weights)), tolerance=TOLERANCE, max_iterations=MAX_ITERATIONS,
        halvings=30)
    if result.failed_evaluation:
        return _none(system, theta, t, z, q_end, cuts, 0, np.inf, None, flow, atol)
    if result.converged:
        parts = [flow.run(start, cuts[j], cuts[j + 1], theta, rtol=RTOL, atol=atol)
                 for j, start in enumerate(starts_of(result.x))]
        return Shot(concatenate(parts), result.x[:n].copy(), cuts, result.iterations,
                    result.residual)
    return _none(system, theta, t, z, q_end, cuts, MAX_ITERATIONS, result.residual,
                 result.payload, flow, atol, scale)


def _at(t: np.ndarray, z: np.ndarray, times: np.ndarray) -> np.ndarray:
    """The discrete solution at ``times`` (linear between its nodes): the segments' starts."""
    return np.stack([np.interp(times, t, z[:, i]) for i in range(z.shape[1])], axis=-1)


def banded_solve(tangents: np.ndarray, residual: np.ndarray, n: int) -> np.ndarray:
    """``J^-1 residual`` for the block-bidiagonal Jacobian of the shooting equations
    (``tangents``: (S, d, d), the flow's Jacobian over each segment), by LAPACK's band solver
    (partial pivoting): O(S d^3), never a dense (S d)^2 matrix."""
    from scipy.linalg import solve_banded

    segments, d, _ = tangents.shape
    size = n + d * (segments - 1)
    rows, columns, values = [], [], []

    def block(r0, c0, matrix):
        r, c = np.indices(matrix.shape)
        rows.append((r + r0).ravel())
        columns.append((c + c0).ravel())
        values.append(matrix.ravel())

    def column(j):
        return 0 if j == 0 else n + (j - 1) * d

    for j in range(segments):
        Y = tangents[j][:, n:] if j == 0 else tangents[j]  # z_0 = (q_start, p_0): p_0 varies
        if j < segments - 1:
            block(j * d, column(j), Y)
            block(j * d, column(j + 1), -np.eye(d))
        else:
            block(j * d, column(j), Y[:n])
    rows, columns, values = map(np.concatenate, (rows, columns, values))
    lower, upper = int(np.max(rows - columns)), int(np.max(columns - rows))
    band = np.zeros((lower + upper + 1, size))
    band[upper + rows - columns, columns] = values
    return solve_banded((lower, upper), band, residual)


def _none(system, theta, t, z, q_end, cuts, iterations, size, tangents, flow, atol,
          scale=None) -> Shot:
    """No continuous solution near: why, in words (where the flow from the discrete start ends,
    and whether ``t_end`` is conjugate to ``t_0``)."""
    n = z.shape[1] // 2
    run = flow.run(z[0], float(t[0]), float(t[-1]), theta, rtol=RTOL, atol=atol)
    end = run.z_end if run.success else np.full(2 * n, np.nan)
    if not np.all(np.isfinite(end)):  # an escape, not a conjugate point: say so
        return Shot(None, None, cuts, iterations, size,
                    "no motion of the exact flow near this solution goes from q_start to "
                    f"q_end: the flow from its first node escapes (it stops at t = "
                    f"{run.t_reached:.6g} of [{float(t[0]):.6g}, {float(t[-1]):.6g}], last "
                    f"|z| = {float(np.max(np.abs(run.z_end))):.3g}: {run.status})")
    reason = ("no motion of the exact flow near this solution goes from q_start to q_end: the "
              f"flow from its first node ends at q = {end[:n].tolist()} against q_end = "
              f"{np.asarray(q_end).tolist()}")
    conditioning = _conditioning(tangents, n, scale)
    if conditioning is not None and conditioning < 1e-8:
        reason += (f"; the end position barely depends on the initial data (singular values "
                   f"{conditioning:.1e} apart): t_end is conjugate to t_0, where every motion "
                   "from q_start ends at one point or none does")
    return Shot(None, None, cuts, iterations, size, reason)


def _conditioning(tangents, n: int, scale) -> float | None:
    """How much the end position depends on the initial momentum, against how much the flow
    moves anything: the smallest singular value of ``d q_end / d p_0`` over the largest of the
    flow's whole Jacobian (the segments' chained, each in units of the motion's size), or
    ``None``. Near zero: ``t_end`` is conjugate to ``t_0``."""
    if tangents is None or scale is None:
        return None
    product = np.eye(2 * n)
    for Y in tangents:
        product = Y @ product
    scaled = product * scale[None, :] / scale[:, None]
    if not np.all(np.isfinite(scaled)):
        return None
    largest = np.linalg.norm(scaled, 2)
    singular = np.linalg.svd(scaled[:n, n:], compute_uv=False)
    return float(singular[-1] / largest) if largest > 0 else 0.0
