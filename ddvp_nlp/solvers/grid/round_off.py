"""How far a grid problem's rows are known at a point: the round-off every grid family's
Newton targets and verification limits are read from, the same way for each.

Each row is evaluated at ``x`` and at ``x (1 + eps s)``, every unknown moved by one unit in its
last place in a drawn direction ``s = +-1`` (a fixed seed: the same answer on every run); the
change of a row is how far its value is known at ``x``. It is in the row's own units, scales
with them under any change of units, grows where a coordinate is offset or a constant is added
to ``H`` (as the round-off does), and needs no model of the rows and no floor of 1. A family
takes the largest change over its grid for each kind of row (`solvers/bvp/phases.py`).
"""

from __future__ import annotations

import numpy as np

from .problem import GridProblem

EPS = float(np.finfo(float).eps)
# Up to DRAWS drawn directions, fewer on a grid of more than ROWS rows (each draw is one
# evaluation of the whole grid; over many rows one draw already meets the largest changes).
DRAWS = 3
ROWS = 10_000
SEED = 20261207


def row_noise(problem: GridProblem, x: np.ndarray, data, base: np.ndarray | None = None
              ) -> np.ndarray:
    """``|F_i(x (1 + eps s)) - F_i(x)|``, the largest over the draws, per row of ``problem``
    at ``x`` (0 where a row is not finite). ``base``: ``F(x)``, where already evaluated."""
    if base is None:
        base, _ = problem.evaluate(x, data, jacobian=False)
    draws = np.random.default_rng(SEED)
    noise = np.zeros_like(base)
    for _ in range(int(np.clip(np.ceil(ROWS / max(base.size, 1)), 1, DRAWS))):
        moved = x * (1.0 + EPS * draws.choice([-1.0, 1.0], x.size))
        F, _ = problem.evaluate(moved, data, jacobian=False)
        np.maximum(noise, np.abs(F - base), out=noise)
    return np.where(np.isfinite(noise), noise, 0.0)
