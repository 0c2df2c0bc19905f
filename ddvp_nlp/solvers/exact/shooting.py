"""The continuous fixed-endpoint problem near a discrete solution: is there a motion of the exact
flow from ``q_start`` at ``t_0`` to ``q_end`` at ``t_end``, and which?

A discrete solution can exist where the continuous problem has none: the harmonic oscillator
``H = (p^2 + q^2)/2`` from ``q = 1`` at ``t = 0`` reaches ``q = -1`` at ``t = pi`` whatever its
momentum (``t = pi`` is conjugate to ``0``), so no motion goes to ``q = 0.5``, yet the grid's
equations, whose discrete half period differs from ``pi``, have a solution with a huge momentum.

The check solves the continuous problem by multiple shooting with the reference flow
(``reference.py``), from the discrete solution itself: the run is cut into ``SEGMENTS`` pieces at
its nodes; the unknowns are the initial momentum and the states at the cuts, the equations the
continuity of the flow at every cut and ``q(t_end) = q_end``; Newton (Jacobian by forward
differences, all pieces and perturbations integrated together, a damped step) converges in a few
iterations where a continuous solution is near, also on sensitive orbits that single shooting
cannot follow (the pieces are short). It fails, and says so, where the end position does not
depend on the initial data (a conjugate point) or no root is found.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .flow import MAX_SUBSTEPS, ReferenceFlow

SEGMENTS = 16
MAX_ITERATIONS = 30
# continuity and the end position must hold to this fraction of the motion's size
TOLERANCE = 1e-9
# forward-difference step, relative to the motion's size per component
DIFFERENCE = 1e-7


@dataclass
class Shot:
    """The outcome: the continuous solution's states at the grid's times (rows; or ``None``),
    its initial momentum, and, where there is none, why."""

    states: np.ndarray | None
    p0: np.ndarray | None
    reason: str = ""


class _Pieces:
    """The run cut at ``cuts`` (node indices, first 0, last N), each piece integrated by the
    reference flow from its start through the grid's own times."""

    def __init__(self, reference: ReferenceFlow, t: np.ndarray, cuts: np.ndarray):
        self.reference, self.t, self.cuts = reference, t, cuts
        self.substeps = 1

    def run(self, starts: np.ndarray, record: bool = False):
        """``starts`` (pieces, variants, 2n): the end of every piece for every variant, and
        with ``record`` the states of variant 0 at every node (rows 0 .. N)."""
        t, cuts = self.t, self.cuts
        pieces, variants, width = starts.shape
        lengths = np.diff(cuts)
        while True:
            current = starts.copy()
            nodes = np.empty((t.size, width)) if record else None
            if record:
                nodes[cuts[:-1]] = starts[:, 0]
            own = 0.0
            for s in range(int(lengths.max())):
                active = np.flatnonzero(lengths > s)
                k = cuts[active] + s
                A, B = self.reference.maps(np.repeat(t[k], variants),
                                           current[active].reshape(-1, width),
                                           np.repeat(t[k + 1] - t[k], variants), self.substeps)
                own = max(own, float(np.max(np.abs(A - B), initial=0.0)))
                current[active] = B.reshape(active.size, variants, width)
                if record:
                    nodes[k + 1] = current[active, 0]
            size = float(np.max(np.abs(current), initial=0.0))
            if own <= 1e-10 * size or 2 * self.substeps > MAX_SUBSTEPS or not np.isfinite(own):
                return current, nodes
            self.substeps *= 2


def shoot(reference: ReferenceFlow, t: np.ndarray, z: np.ndarray, q_end, scale) -> Shot:
    """The continuous solution from ``q_start = z[0, :n]`` at ``t[0]`` to ``q_end`` at ``t[-1]``
    nearest to the discrete solution ``z`` (rows at ``t``; ``scale``: the motion's size per
    component)."""
    n = z.shape[1] // 2
    cuts = np.unique(np.linspace(0, t.size - 1, min(SEGMENTS, t.size - 1) + 1).round()
                     .astype(int))
    pieces = _Pieces(reference, t, cuts)
    q_start, q_end = z[0, :n], np.asarray(q_end, float)
    x = np.concatenate([z[0, n:], z[cuts[1:-1]].ravel()])  # p_0, then the states at the cuts
    steps = DIFFERENCE * np.concatenate([scale[n:], np.tile(scale, cuts.size - 2)])
    weights = np.concatenate([np.tile(scale, cuts.size - 2), scale[:n]])

    def starts_of(x_value, variants=1):
        first = np.concatenate([q_start, x_value[:n]])
        rest = x_value[n:].reshape(-1, 2 * n)
        return np.repeat(np.vstack([first, rest])[:, None, :], variants, axis=1)

    def residual_of(ends, x_value):
        starts = starts_of(x_value)[:, 0]
        continuity = (ends[:-1] - starts[1:]).ravel()
        return np.concatenate([continuity, ends[-1, :n] - q_end])

    ends, _ = pieces.run(starts_of(x))
    residual = residual_of(ends[:, 0], x)
    conditioning = None
    for _ in range(MAX_ITERATIONS):
        if not np.all(np.isfinite(residual)):
            break
        if np.all(np.abs(residual) <= TOLERANCE * weights):
            _, states = pieces.run(starts_of(x), record=True)
            return Shot(states, x[:n].copy())
        jacobian = _jacobian(pieces, starts_of, residual_of, x, steps, n, residual)
        scaled = jacobian / weights[:, None] * steps[None, :] / DIFFERENCE
        singular = np.linalg.svd(scaled, compute_uv=False)
        conditioning = float(singular[-1] / singular[0]) if singular[0] > 0 else 0.0
        step = np.linalg.lstsq(jacobian, -residual, rcond=None)[0]
        size = float(np.max(np.abs(residual) / weights))
        for _ in range(30):  # damped: the defects must shrink
            trial = x + step
            trial_ends, _ = pieces.run(starts_of(trial))
            trial_residual = residual_of(trial_ends[:, 0], trial)
            if np.all(np.isfinite(trial_residual)) and \
                    float(np.max(np.abs(trial_residual) / weights)) < size:
                break
            step = step / 2
        else:
            break
        x, residual = trial, trial_residual
    return Shot(None, None, _reason(reference, t, z, q_end, conditioning))


def _jacobian(pieces, starts_of, residual_of, x, steps, n, residual):
    """The Jacobian of the defects in ``x`` by forward differences: every piece with every
    perturbation of its own start integrated in one pass (variant 0 unperturbed)."""
    pieces_count = pieces.cuts.size - 1
    width = 2 * n
    starts = starts_of(x, variants=width + 1)
    columns = []  # (piece, variant, index into x)
    for j in range(n):  # the first piece: its momentum
        starts[0, 1 + j, n + j] += steps[j]
        columns.append((0, 1 + j, j))
    for piece in range(1, pieces_count):
        for i in range(width):
            index = n + (piece - 1) * width + i
            starts[piece, 1 + i, i] += steps[index]
            columns.append((piece, 1 + i, index))
    ends, _ = pieces.run(starts)
    jacobian = np.zeros((residual.size, x.size))
    base = ends[:, 0]
    for piece, variant, index in columns:
        moved = base.copy()
        moved[piece] = ends[piece, variant]
        shifted = x.copy()
        shifted[index] += steps[index]
        jacobian[:, index] = (residual_of(moved, shifted) - residual) / steps[index]
    return jacobian


def _reason(reference, t, z, q_end, conditioning) -> str:
    """Why there is no continuous solution: where the flow from the discrete start ends, and
    whether ``t_end`` is conjugate to ``t_0``."""
    n = z.shape[1] // 2
    end, _ = reference.flow(z[0], t[0], t[-1], substeps=max(8, 2 * (t.size - 1)))
    reason = ("no motion of the exact flow near this solution goes from q_start to q_end: the "
              f"flow from its first node ends at q = {end[:n].tolist()} against q_end = "
              f"{np.asarray(q_end).tolist()}")
    if conditioning is not None and conditioning < 1e-8:
        reason += (f"; the end position barely depends on the initial data (singular values "
                   f"{conditioning:.1e} apart): t_end is conjugate to t_0, where every motion "
                   "from q_start ends at one point or none does")
    return reason
