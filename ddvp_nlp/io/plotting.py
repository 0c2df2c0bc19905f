"""The trajectory plot of a run: only the panels that apply to it."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..discrete import equations  # noqa: E402

# Long runs get a second column that zooms on the start, where single swings can be seen
# (the paper's figures 2-3 are such zooms of figure 1).
ZOOM_FROM_NODES = 2000
ZOOM_FRACTION = 0.035
# Points drawn per line: a long run is drawn from every stride-th node (the energy errors from
# the largest value of each stride, so no spike is lost); drawing all 400,000 nodes of a
# 20000-time-unit pendulum took 7 s, eight times the march.
MAX_POINTS = 4000


def plot_trajectory(solution, scene, scheme, theta, path: Path) -> None:
    t, q, p, tau = solution.t, solution.q, solution.p, solution.tau
    system = scene.system
    panels = [("q", lambda ax, sel: _lines(ax, t[sel], q[sel], "q")),
              ("p", lambda ax, sel: _lines(ax, t[sel], p[sel], "p"))]
    if scheme.variable_steps:
        panels.append(("step length tau_k", lambda ax, sel: ax.plot(
            t[:-1][sel[:-1]], tau[sel[:-1]], lw=0.8)))
    if system.time_dependent:
        rule = equations.diagnostic_rule(scheme)
        residual = np.abs(solution.energy_residual)
        if residual.size:
            panels.append((f"|{rule} energy residual|", lambda ax, sel: _semilog(
                ax, t[1:-1][sel[1:-1]], residual[sel[1:-1]], None)))
    else:
        interval = equations.interval_energies(system, scheme, t, q, p, theta)
        nodes = system.energy(q, p, t, theta)

        interval_drift = _envelope(np.abs(interval - interval[0]))
        node_drift = _envelope(np.abs(nodes - nodes[0]))

        def energy_panel(ax, sel):
            _semilog(ax, t[:-1][sel[:-1]], interval_drift[sel[:-1]],
                     "interval energy H(Q_k, P_k)")
            _semilog(ax, t[sel], node_drift[sel], "node energy H(q_k, p_k)")
            ax.legend(fontsize=7, loc="upper left")  # "best" searched 2 s on long runs
        panels.append(("energy error", energy_panel))

    zoom = t.size >= ZOOM_FROM_NODES
    columns = 2 if zoom else 1
    fig, axes = plt.subplots(len(panels), columns, figsize=(6.5 * columns, 2.1 * len(panels)),
                             sharex="col", squeeze=False)
    everything = _sampled(np.ones(t.size, dtype=bool))
    selections = [everything]
    if zoom:
        selections.append(_sampled(t <= t[0] + ZOOM_FRACTION * (t[-1] - t[0])))
    for column, sel in enumerate(selections):
        for row, (label, draw) in enumerate(panels):
            ax = axes[row, column]
            draw(ax, sel)
            ax.set_ylabel(label if column == 0 else "")
            ax.grid(alpha=0.3)
        axes[-1, column].set_xlabel("t")
    axes[0, 0].set_title(f"{scene.name}: {scheme.rule}, {solution.steps} steps, "
                         f"{solution.status.code}", fontsize=9)
    if zoom:
        axes[0, 1].set_title(f"first {ZOOM_FRACTION:.1%} of the time span", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _stride(count: int) -> int:
    return max(1, -(-count // MAX_POINTS))


def _sampled(selection: np.ndarray) -> np.ndarray:
    """Every stride-th of the selected nodes, at most ``MAX_POINTS`` of them."""
    chosen = np.flatnonzero(selection)
    sampled = np.zeros_like(selection)
    sampled[chosen[::_stride(chosen.size)]] = True
    return sampled


def _envelope(values: np.ndarray) -> np.ndarray:
    """``values`` with each entry replaced by the largest over the next stride (the stride of
    the whole run), so a sample of every stride-th entry still shows every spike."""
    stride = _stride(values.size + 1)
    if stride == 1 or not values.size:
        return values
    padded = np.pad(values, (0, -values.size % stride), constant_values=-np.inf)
    blocks = padded.reshape(-1, stride).max(axis=1)
    return np.repeat(blocks, stride)[:values.size]


def _lines(ax, t, values, name):
    n = values.shape[1]
    for i in range(n):
        ax.plot(t, values[:, i], lw=0.8, label=f"{name}{i + 1}" if n > 1 else None)
    if 1 < n <= 6:
        ax.legend(fontsize=7, ncol=n, loc="upper right")


def _semilog(ax, t, values, label):
    # Exact zeros (the first node, exactly conserved steps) cannot be drawn on a log axis.
    shown = np.where(values > 0, values, np.nan)
    ax.semilogy(t, shown, lw=0.8, label=label)


def plot_higher_trajectory(solution, scene, command, exact, energy, path: Path) -> None:
    """A higher-order run: nodes against the exact solution, the steps, and the energy
    ``E^(k)`` where the recursion defines it."""
    panels = 3 if energy.size else 2
    fig, axes = plt.subplots(panels, 1, figsize=(8, 2.6 * panels), sharex=True)
    axes[0].plot(solution.t, solution.q, ".-", ms=3, label="nodes")
    axes[0].plot(solution.t, exact, "k--", lw=0.8, label="exact")
    axes[0].set_ylabel("q")
    axes[0].legend(fontsize=8)
    axes[1].plot(solution.t[:-1], solution.tau, ".-", ms=3)
    axes[1].set_ylabel("tau_k")
    if energy.size:
        lo = scene.order - 1
        axes[2].plot(solution.t[lo:lo + energy.size], energy - energy[0], ".-", ms=3)
        axes[2].set_ylabel("E^(k) - E^(l-1)")
    axes[-1].set_xlabel("t")
    fig.suptitle(f"{scene.name} {command} [{solution.scheme}]: {solution.status.code}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
