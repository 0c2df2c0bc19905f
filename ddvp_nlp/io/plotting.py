"""The trajectory plot of a run: only the panels that apply to it."""

from __future__ import annotations

from pathlib import Path

# Figure without pyplot: no backend switching and no global figure registry to keep.
import numpy as np
from matplotlib.figure import Figure

from ..discrete import equations

# Long runs get a second column that zooms on the start, where single swings can be seen
# (the paper's figures 2-3 are such zooms of figure 1).
ZOOM_FROM_NODES = 2000
ZOOM_FRACTION = 0.035
# Lines against t are drawn from their min/max envelope per pixel column (COLUMNS columns per
# axis, about the axis' width at DPI): what a full line would light up, at a few thousand points
# whatever the length. Drawing all 20000 nodes of paper_pendulum in five panels took 1.4 s, more
# than the march, and the q and p panels were solid blocks.
COLUMNS = 600
DPI = 100
# The phase portrait is a histogram of the nodes on this many cells a side.
PHASE_BINS = 160
# Exact zeros on the log-scale energy axis are drawn at this floor, labelled 0.
ZERO_FLOOR = 1e-17


def envelope(t: np.ndarray, values: np.ndarray, columns: int = COLUMNS):
    """``(t, values)`` reduced to the minimum and maximum of each of ``columns`` equal bins of
    ``t`` (in the order they occur), so that a line through them covers the same pixels as the
    full line. ``values`` is ``(N,)`` or ``(N, m)``; short series are returned as they are."""
    values = np.asarray(values, dtype=float)
    if t.size <= 2 * columns:
        return t, values
    flat = values.reshape(t.size, -1)
    edges = np.linspace(t[0], t[-1], columns + 1)
    starts = np.unique(np.searchsorted(t, edges[:-1], side="left"))
    starts = starts[starts < t.size]
    shown = []
    for i in range(flat.shape[1]):
        column = flat[:, i]
        finite = np.where(np.isfinite(column), column, np.nan)
        low = np.fmin.reduceat(finite, starts)
        high = np.fmax.reduceat(finite, starts)
        shown.append(np.column_stack([low, high]).ravel())
    mids = np.repeat(t[starts], 2)
    return mids, np.column_stack(shown).reshape(-1, *values.shape[1:])


def plot_trajectory(solution, scene, scheme, path: Path, *, energies) -> None:
    """``trajectory.png``: ``q``, ``p``, the step (energy rules) and the relative energy error
    against ``t`` (a zoom on the start beside them for long runs) and the phase portrait.
    ``energies``: the run's node and interval energies (``runs.run_energies``)."""
    t, q, p = solution.t, solution.q, solution.p
    panels = [("q", q), ("p", p)]
    if scheme.variable_steps:
        panels.append(("step length tau_k", (t[:-1], solution.tau)))
    panels.append(_energy_panel(solution, scene.system, scheme, energies))
    zoom = t.size >= ZOOM_FROM_NODES
    columns = 3 if zoom else 2
    fig = Figure(figsize=(4.4 * columns, 1.7 * len(panels) + 0.6), dpi=DPI)
    grid = fig.add_gridspec(len(panels), columns, width_ratios=[1.5] * (columns - 1) + [1],
                            left=0.07, right=0.98, bottom=0.08, top=0.93, wspace=0.28,
                            hspace=0.12)
    spans = [(t[0], t[-1])]
    if zoom:
        spans.append((t[0], t[0] + ZOOM_FRACTION * (t[-1] - t[0])))
    for column, (start, stop) in enumerate(spans):
        axes = None
        for row, (label, data) in enumerate(panels):
            axes = fig.add_subplot(grid[row, column], sharex=axes)
            _draw_panel(axes, t, label, data, start, stop)
            axes.set_ylabel(label if column == 0 else "", fontsize=8)
            axes.tick_params(labelsize=7, labelbottom=row == len(panels) - 1)
            _few_ticks(axes, y=not isinstance(data, list))
        axes.set_xlabel("t", fontsize=8)
    _phase_portrait(fig.add_subplot(grid[:, -1]), q, p)
    fig.suptitle(f"{scene.name}: {scheme.rule}, {solution.steps} steps, {solution.status.code}"
                 + (f"   (middle: the first {ZOOM_FRACTION:.1%} of the time span)"
                    if zoom else ""), fontsize=9)
    fig.savefig(path, dpi=DPI)


def _few_ticks(axes, *, y: bool = True):
    """Four ticks an axis: matplotlib builds each tick as several artists, and the ticks were
    most of the drawing time once the lines were decimated."""
    from matplotlib.ticker import MaxNLocator

    axes.xaxis.set_major_locator(MaxNLocator(4))
    if y:
        axes.yaxis.set_major_locator(MaxNLocator(3))


def _energy_panel(solution, system, scheme, energies):
    """The energy panel's label and curves: relative drifts of the interval and node energies
    for autonomous ``H``, the relative residual of the energy equation for a time-dependent one;
    both relative to ``max(1, |H0|)``."""
    t = solution.t
    nodes, interval = energies
    scale = max(1.0, abs(float(nodes[0])))
    if system.time_dependent:
        rule = equations.diagnostic_rule(scheme)
        residual = np.abs(solution.energy_residual) / scale
        return (f"|{rule} residual| / max(1,|H0|)", [("", t[1:-1], residual)])
    return ("|H - H0| / max(1,|H0|)",
            [("interval energy H(Q_k, P_k)", t[:-1], np.abs(interval - interval[0]) / scale),
             ("node energy H(q_k, p_k)", t, np.abs(nodes - nodes[0]) / scale)])


def _draw_panel(axes, t, label, data, start, stop):
    if isinstance(data, list):  # energy curves: (label, t, values), log scale with zeros
        for name, times, values in data:
            selected = (times >= start) & (times <= stop)
            shown_t, shown = envelope(times[selected], values[selected])
            axes.plot(shown_t, np.maximum(shown, ZERO_FLOOR), lw=0.8, label=name or None)
        _log_axis_with_zero(axes)
        if len(data) > 1:
            axes.legend(fontsize=6, loc="upper left")
        return
    times, values = (t, data) if not isinstance(data, tuple) else data
    selected = (times >= start) & (times <= stop)
    shown_t, shown = envelope(times[selected], values[selected])
    shown = shown.reshape(shown_t.size, -1)
    for i in range(shown.shape[1]):
        axes.plot(shown_t, shown[:, i], lw=0.8,
                  label=f"{label}{i + 1}" if shown.shape[1] > 1 else None)
    if 1 < shown.shape[1] <= 6:
        axes.legend(fontsize=6, ncol=shown.shape[1], loc="upper right")


def _log_axis_with_zero(axes):
    """A log axis whose bottom decade, ``ZERO_FLOOR``, stands for exact zeros (labelled 0).
    At most six labelled decades, plain text labels: mathtext labels and minor ticks over 17
    decades took 0.6 s to draw."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullLocator

    axes.set_yscale("log")
    _, top = axes.get_ylim()
    axes.set_ylim(ZERO_FLOOR / 3, max(top, ZERO_FLOOR * 10))
    axes.yaxis.set_major_locator(LogLocator(numticks=4))
    axes.yaxis.set_minor_locator(NullLocator())
    axes.yaxis.set_major_formatter(FuncFormatter(
        lambda value, _: "0" if value <= ZERO_FLOOR * 1.01 else f"{value:.0e}"))


def _phase_portrait(axes, q, p):
    """Where the orbit went in the ``(q_1, p_1)`` plane, as pixels: each of
    ``PHASE_BINS`` x ``PHASE_BINS`` cells the nodes visit is shaded by how many do (log scale).
    A line through 20000 nodes that retrace one orbit a thousand times took a second to draw;
    the visited cells show the same curve (and a chaotic orbit's spread) at a fixed cost."""
    from matplotlib.colors import LogNorm

    counts, q_edges, p_edges = np.histogram2d(q[:, 0], p[:, 0], bins=PHASE_BINS)
    counts = np.where(counts > 0, counts, np.nan)
    axes.imshow(counts.T, origin="lower", aspect="auto", cmap="viridis_r",
                norm=LogNorm(vmin=1, vmax=max(2.0, np.nanmax(counts))), interpolation="nearest",
                extent=(q_edges[0], q_edges[-1], p_edges[0], p_edges[-1]))
    axes.plot(q[0, 0], p[0, 0], "r.", ms=6)
    components = f" (q1, p1 of {q.shape[1]})" if q.shape[1] > 1 else ""
    axes.set_xlabel("q1" if components else "q", fontsize=8)
    axes.set_ylabel("p1" if components else "p", fontsize=8)
    axes.set_title(f"phase portrait{components}: nodes per cell; red: start", fontsize=8)
    axes.tick_params(labelsize=7)
    _few_ticks(axes)


def plot_higher_trajectory(solution, scene, command, exact, energy, path: Path) -> None:
    """A higher-order run: nodes against the exact solution, the steps, and the energy
    ``E^(k)`` where the recursion defines it."""
    panels = 3 if energy.size else 2
    fig = Figure(figsize=(8, 2.6 * panels))
    axes = fig.subplots(panels, 1, sharex=True)
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
