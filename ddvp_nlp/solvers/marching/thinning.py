"""A march that keeps only some of its nodes (``Output(keep_every=k)``, ``Output(keep="t_eval")``),
with memory and output proportional to what it keeps.

The driver (rule 7) hands `Thinning` the nodes every monitor has seen once more than
``WINDOW`` rows have gathered, and the rest at the end. Of each window it

- keeps the nodes ``0, k, 2k, ...`` (``keep="t_eval"``: node 0 only) and, at the end, the last
  node;
- feeds every step to the accuracy check (``accuracy/streaming.py``), which keeps bounded state;
- recomputes every equation (``recheck.py``): the largest residuals of all steps go to
  ``march.kept``, and the residual of the step from each kept node (canonical), at each kept
  interior node (energy), is kept as the `Solution`'s arrays;
- reads the ``t_eval`` states that fall in it from the dense output of its nodes (the same
  Hermite interpolant `Solution.at` reads from all nodes).

The last two rows stay in the driver's arrays (the next energy step starts from them), so the
windows overlap by one node: window ``j`` judges the steps from its rows ``0 .. m-1``, and row
``m`` starts the next window.
"""

from __future__ import annotations

import numpy as np

from ...solution import hermite
from ..columns import row_max_abs

# Rows gathered before a window is settled (Output.window's default): 64k nodes of a
# one-degree-of-freedom march are 1.5 MB; fewer windows cost nothing more than the recheck and
# the check on the same nodes.
WINDOW = 65536
# Rows that stay behind after a window: the energy step starts from the last two nodes.
STAY = 2


class Thinning:
    """What a thinned march keeps (module docstring). ``residuals(t, z)`` gives the canonical
    ``(N-1, 2n)`` and energy ``(N-2,)`` residuals of consecutive nodes; ``judge`` is a
    `StreamingJudgement` or ``None``; ``field(t, z)`` the slopes for the ``t_eval`` states."""

    def __init__(self, keep_every: int, keep: str, *, residuals, judge=None, t_eval=None,
                 field=None, window: int | None = None):
        self.every, self.keep = keep_every, keep
        self.window = WINDOW if window is None else window
        self.residuals, self.judge, self.field = residuals, judge, field
        self.t_eval = t_eval if t_eval is not None else np.zeros(0)
        self.t: list = []
        self.z: list = []
        self.canonical: list = []
        self.energy: list = []
        self.local: list = []
        self.eval_t: list = []
        self.eval_z: list = []
        self.evaluated = 0  # t_eval times read so far
        self.canonical_max, self.energy_max = 0.0, 0.0
        self.tau_min, self.tau_max = np.inf, -np.inf
        self.windows = 0

    def selected(self, start: int, stop: int) -> np.ndarray:
        """The kept node indices in ``[start, stop)`` (the run's last node aside)."""
        if self.keep == "t_eval":
            return np.zeros(1 if start == 0 < stop else 0, dtype=int)
        first = -(-start // self.every) * self.every
        return np.arange(first, stop, self.every)

    def settle(self, nodes) -> None:
        """Driver rule 7: keep what is kept of all but the last ``STAY`` rows, drop them."""
        settled = nodes.count - STAY
        self._window(nodes, settled)
        nodes.drop(settled)

    def finish(self, nodes) -> tuple[np.ndarray, np.ndarray]:
        """The last window, to the last node; returns the kept nodes ``t``, ``z``."""
        self._window(nodes, nodes.count - 1)
        # `selected` never holds the last node: it is added here, once
        t = np.concatenate(self.t + [nodes.t[nodes.count - 1:nodes.count]])
        z = np.vstack(self.z + [nodes.z[nodes.count - 1:nodes.count]])
        return t, z

    def _window(self, nodes, settled: int) -> None:
        """Rows ``0 .. settled`` of ``nodes``: their ``settled`` steps judged and rechecked,
        the kept ones among rows ``0 .. settled - 1`` stored."""
        base, count = nodes.dropped, nodes.count
        t, z = nodes.t[:count], nodes.z[:count]
        rows = self.selected(base, base + settled) - base
        self.t.append(t[rows].copy())
        self.z.append(z[rows].copy())
        if settled < 1:
            return
        self.windows += 1
        tau = np.diff(t[:settled + 1])
        self.tau_min = min(self.tau_min, float(tau.min()))
        self.tau_max = max(self.tau_max, float(tau.max()))
        if self.judge is not None:
            local = self.judge.feed(t[:settled + 1], z[:settled + 1], base)
            self.local.append(local[rows])
        n = z.shape[1] // 2
        canonical, energy = self.residuals(t, z) if count > 1 else (np.zeros((0, 2 * n)),
                                                                    np.zeros(0))
        canonical = row_max_abs(canonical[:settled]) if canonical.size else np.zeros(0)
        energy = energy[:settled]  # nodes 1 .. settled (1 .. settled - 1 in the last window)
        if canonical.size:
            self.canonical_max = max(self.canonical_max, float(np.max(canonical)))
            self.canonical.append(canonical[rows])
        if energy.size:
            self.energy_max = max(self.energy_max, float(np.max(np.abs(energy))))
            interior = self.selected(base + 1, base + 1 + energy.size) - base - 1
            self.energy.append(energy[interior])
        self._evaluate(t[:settled + 1], z[:settled + 1])

    def _evaluate(self, t, z) -> None:
        """The ``t_eval`` times up to ``t[-1]`` not read yet, from these nodes."""
        end = int(np.searchsorted(self.t_eval, t[-1], side="right"))
        times = self.t_eval[self.evaluated:end]
        if not times.size:
            return
        j = np.clip(np.searchsorted(t, times, side="right") - 1, 0, t.size - 2)
        rows = np.unique(np.concatenate([j, j + 1]))
        slopes = np.asarray(self.field(t[rows], z[rows]), float).reshape(rows.size, -1)
        self.eval_t.append(times)
        self.eval_z.append(hermite(t[rows], z[rows], slopes, times))
        self.evaluated = end

    def arrays(self, width: int) -> dict:
        """The kept per-step arrays and the ``t_eval`` states."""
        def joined(parts):
            return np.concatenate(parts) if parts else np.zeros(0)
        return {"canonical": joined(self.canonical), "energy": joined(self.energy),
                "local": joined(self.local), "t_eval": joined(self.eval_t),
                "z_eval": np.vstack(self.eval_z) if self.eval_z else np.zeros((0, width))}

    def record(self, marched: int, kept: int) -> dict:
        """``march.kept``: what was kept of how much."""
        return {"keep_every": self.every, "keep": self.keep, "nodes_marched": marched,
                "nodes_kept": kept, "windows": self.windows,
                "tau_min": self.tau_min if self.windows else None,
                "tau_max": self.tau_max if self.windows else None,
                "canonical_residual_max": self.canonical_max,
                "energy_residual_max": self.energy_max}
