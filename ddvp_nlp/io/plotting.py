"""The trajectory figure of a run, and of any :class:`~ddvp_nlp.solution.Solution`: only the
panels that apply to it, drawn on a raster canvas (``raster.py``; why not matplotlib is said
there)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..discrete import equations
from . import raster

# Long runs get a second column that zooms on the start, where single swings can be seen
# (the paper's figures 2-3 are such zooms of figure 1).
ZOOM_FROM_NODES = 2000
ZOOM_FRACTION = 0.035
# Lines against t are drawn from their min/max envelope per pixel column: what a full line would
# light up, at a few thousand points whatever the length. Drawing all 20000 nodes of
# paper_pendulum in five panels took 1.4 s, more than the march, and the q and p panels were
# solid blocks. COLUMNS: the default number of columns of ``envelope``.
COLUMNS = 600
# Exact zeros on the log-scale energy axis are drawn at this floor, labelled 0.
ZERO_FLOOR = 1e-17
# Figure geometry in pixels: a time column, the zoom column, the phase portrait; panel height.
TIME_WIDTH, PHASE_WIDTH, PANEL_HEIGHT = 470, 330, 150
LEFT, GAP, TOP, BOTTOM, ROW_GAP = 78, 78, 34, 44, 10


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
    """``trajectory.png`` of a run: ``q``, ``p``, the step (energy rules) and the relative
    energy error against ``t`` (a zoom on the start beside them for long runs) and the phase
    portrait. ``energies``: the run's node and interval energies (``runs.run_energies``)."""
    energy = _energy_panel(solution, scene.system, scheme, energies)
    title = f"{scene.name}: {scheme.rule}, {solution.steps} steps, {solution.status.code}"
    _figure(solution, _panels(solution, scheme.variable_steps, energy), title).save(path)


def plot_solution(solution, path=None, *, system=None, params=None, title: str | None = None):
    """The figure of ``ddvp march`` for any :class:`~ddvp_nlp.solution.Solution` (a march, a
    fixed-endpoint solve, a higher-order run): ``q``, ``p``, the step length where it varies,
    the phase portrait, and, given the ``system`` that was solved (``params``: its values,
    default those of the solve), the relative energy drift ``|H - H0| / max(1, |H0|)`` at the
    nodes (for a time-dependent ``H``, the residual of the scheme's energy equation relative
    to ``max(1, |H0|)``).

    Returns:
        ``path`` after writing the PNG there, or the ``PIL.Image.Image`` when ``path`` is
        ``None`` (Jupyter shows it).
    """
    tau = solution.tau
    varies = tau.size > 1 and float(np.ptp(tau)) > 1e-9 * float(np.max(np.abs(tau)))
    energy = None
    if system is not None and solution.t.size >= 2:
        nodes = solution.energy(system, params)
        scale = max(1.0, abs(float(nodes[0])))
        if system.time_dependent:
            energy = ("|energy residual| / max(1,|H0|)",
                      [("", solution.t[1:-1], np.abs(solution.energy_residual) / scale)])
        else:
            energy = ("|H - H0| / max(1,|H0|)",
                      [("node energy H(q_k, p_k)", solution.t, np.abs(nodes - nodes[0]) / scale)])
    canvas = _figure(solution, _panels(solution, varies, energy), title or
                     f"{solution.scheme}: {solution.steps} steps, {solution.status.code}")
    if path is None:
        return canvas.image
    canvas.save(path)
    return path


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


def _panels(solution, steps: bool, energy) -> list:
    """``(label, curves, log)`` per row, ``curves`` a list of ``(name, t, values)``."""
    t = solution.t
    rows = [(name, [(f"{name}{i + 1}" if values.shape[1] > 1 else "", t, values[:, i])
                    for i in range(values.shape[1])], False)
            for name, values in (("q", solution.q), ("p", solution.p))]
    if steps:
        rows.append(("step length tau_k", [("", t[:-1], solution.tau)], False))
    if energy is not None:
        rows.append((energy[0], energy[1], True))
    return rows


def _figure(solution, rows, title: str) -> raster.Canvas:
    """The canvas: the rows against ``t`` over the whole run (and over its start, for long
    runs), and the phase portrait on the right."""
    t = solution.t
    zoom = t.size >= ZOOM_FROM_NODES
    spans = [(t[0], t[-1])] + ([(t[0], t[0] + ZOOM_FRACTION * (t[-1] - t[0]))] if zoom else [])
    width = LEFT + len(spans) * (TIME_WIDTH + GAP) + PHASE_WIDTH + 20
    height = TOP + len(rows) * (PANEL_HEIGHT + ROW_GAP) + BOTTOM
    canvas = raster.Canvas(width, height)
    canvas.text(width / 2, 8, title + (f"   (middle: the first {ZOOM_FRACTION:.1%} of the time "
                                       "span)" if zoom else ""), "mt")
    for column, span in enumerate(spans):
        left = LEFT + column * (TIME_WIDTH + GAP)
        for row, (label, curves, log) in enumerate(rows):
            top = TOP + row * (PANEL_HEIGHT + ROW_GAP)
            box = (left, top, left + TIME_WIDTH, top + PANEL_HEIGHT)
            _time_panel(canvas, box, span, curves, log, last=row == len(rows) - 1)
            if column == 0:
                canvas.vertical_text(18, top + PANEL_HEIGHT / 2, label)
        canvas.text(left + TIME_WIDTH / 2, height - 14, "t", "mm")
    left = LEFT + len(spans) * (TIME_WIDTH + GAP)
    _phase_portrait(canvas, (left, TOP + 18, left + PHASE_WIDTH, height - BOTTOM),
                    solution.q, solution.p)
    return canvas


def _time_panel(canvas, box, span, curves, log: bool, *, last: bool) -> None:
    """One panel against ``t`` over ``span``: each curve's envelope per pixel column."""
    start, stop = span
    shown = []
    for name, times, values in curves:
        selected = (times >= start) & (times <= stop)
        x, y = envelope(times[selected], values[selected], columns=box[2] - box[0])
        shown.append((name, x, np.maximum(y, ZERO_FLOOR) if log else y))
    finite = np.concatenate([y[np.isfinite(y)] for _, _, y in shown] + [np.zeros(0)])
    names = [name for name, _, _ in shown]
    legend = 1 < len(names) <= 6 and all(names)
    if log:  # room above the data for the legend: three decades
        top = max(float(finite.max()) if finite.size else 1.0, ZERO_FLOOR * 10)
        top *= 1e3 if legend else 3
        panel = raster.Panel(canvas, box, span, (ZERO_FLOOR / 3, top), log=True)
        ticks, labels = _log_ticks(top)
        panel.frame(x_labels=last, y_ticks=ticks, y_labels=labels)
    else:  # room above the data for the legend: a third of the range
        low, high = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        panel = raster.Panel(canvas, box, span,
                             (low, high + 0.3 * (high - low) if legend else high))
        panel.frame(x_labels=last)
    colors = [raster.COLORS[i % len(raster.COLORS)] for i in range(len(shown))]
    for (_, x, y), color in zip(shown, colors, strict=True):
        panel.line(x, y, color)
    if legend:
        panel.legend(names, colors)


def _log_ticks(top: float):
    """At most six decades from ``ZERO_FLOOR`` (labelled 0) to ``top``, evenly spaced."""
    low, high = round(np.log10(ZERO_FLOOR)), int(np.floor(np.log10(top)))
    every = max(1, int(np.ceil((high - low) / 5)))
    decades = list(range(low, high + 1, every))
    ticks = 10.0 ** np.array(decades, dtype=float)
    return ticks, ["0" if d == low else f"1e{d}" for d in decades]


def _phase_portrait(canvas, box, q, p) -> None:
    """The orbit in the ``(q_1, p_1)`` plane: the polyline through the nodes (on a raster
    canvas 20000 nodes cost milliseconds; through matplotlib they took a second) and the start
    in red."""
    panel = raster.Panel(canvas, box, (float(q[:, 0].min()), float(q[:, 0].max())),
                         (float(p[:, 0].min()), float(p[:, 0].max())))
    panel.frame(grid=True)
    panel.line(q[:, 0], p[:, 0], raster.COLORS[0])
    panel.dot(q[0, 0], p[0, 0], raster.COLORS[3])
    several = q.shape[1] > 1
    canvas.text((box[0] + box[2]) / 2, box[1] - 4,
                f"phase portrait{f' (q1, p1 of {q.shape[1]})' if several else ''}; "
                "red: start", "mb", small=True)
    canvas.text((box[0] + box[2]) / 2, box[3] + 22, "q1" if several else "q", "mt")
    canvas.vertical_text(box[0] - 58, (box[1] + box[3]) / 2, "p1" if several else "p")


def plot_higher_trajectory(solution, scene, command, exact, energy, path: Path) -> None:
    """A higher-order run: nodes against the exact solution, the steps, and the energy
    ``E^(k)`` where the recursion defines it."""
    from matplotlib.figure import Figure  # no pyplot: no backend, no global figure registry

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
