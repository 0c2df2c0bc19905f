"""The run figure (``trajectory.png``, ``.svg`` or ``.pdf``) of a run, and of any
`Solution`: only the panels that apply to it, in the house style
(`ddvp_nlp.io.figures`).

Layout: on the left, against ``t``, the coordinates, the momenta, the step length where it
varies and the energy error (log scale); for a long run a second column shows its first
`ZOOM_STEPS` steps, where single swings and steps can be told apart; on the right the
phase portrait ``(q_1, p_1)`` and, for two or more degrees of freedom, the configuration plane
``(q_1, q_2)`` (the orbit of Kepler or of the figure-eight), at equal aspect.
"""

from __future__ import annotations

import numpy as np

from ..discrete import diagnostic_rule
from . import figures

# A run of more nodes than a panel has pixel columns (about 660 at 200 dpi) is drawn as its
# min/max envelope, in which single steps and swings merge once there are several nodes per
# column; from ZOOM_FROM_NODES a zoom column shows the first ZOOM_STEPS steps, about as many as
# its 1.9 in at 200 dpi can separate.
ZOOM_FROM_NODES = 5000
ZOOM_STEPS = 300
# The phase portrait is drawn at equal aspect (a circle stays round) unless the ranges of q
# and p differ by more than this factor (then they are quantities of unrelated scales and
# equal aspect would flatten the orbit into a line).
EQUAL_ASPECT_RATIO = 5.0
# Components drawn with a legend; a system with more draws them all without one.
LEGEND_COMPONENTS = 6
# From this many nodes the state-space panels show the nodes as dots, not a line through them:
# the chords between nodes a step apart cut inside the orbit (the discrete solution is the
# nodes), and stroking 20000 chords cost 0.3 s of the figure of paper_pendulum.
DOTS_FROM_NODES = 2000
# From this many nodes the dots are thinned to one node per half pixel (figures.thin_points)
# before they are drawn: a million nodes drew in 0.19 s CPU, thinned in 0.07 s; below it
# drawing them all costs no more (100000 nodes: 0.018 s either way) and is exact.
THIN_FROM_NODES = 100_000
ROW_HEIGHT = 1.25  # inches per panel row
# A thinned run's samples as dots of this size (points), edge-less: at 3 points the dots of
# two components overlapped into one block.
SAMPLE_DOT = 2.0
# An equal-aspect state panel whose vertical range exceeds its horizontal one by more than
# this factor keeps its box and widens its x limits instead (``adjustable="datalim"``): the box
# shrunk to a narrow strip with its x tick labels run together (a cart pendulum's q ranges 0.45
# and 1). A wide, low box reads well and is kept.
STRIP_RATIO = 2.0


def plot_trajectory(solution, scene, scheme, path, *, energies, fmt: str = "png",
                    fixed_ends: bool = False) -> None:
    """The run figure of ``ddvp march``/``ddvp bvp`` written to ``path`` (a file name or a
    binary file) in format ``fmt``. ``energies``: the run's node and interval energies
    (``runs.run_energies``); the energy panel shows the relative drift of both for an
    autonomous ``H``, the relative residual of the energy equation for a time-dependent one.
    ``fixed_ends``: a fixed-endpoint run, its two prescribed ends marked. The title says the
    verdict (`verdict_text`)."""
    energy = _energy_panel(solution, scene.system, scheme, energies)
    kept = _kept(solution)
    title = (f"{scene.name}: {scheme.rule}, {_steps_words(solution, kept)}, "
             f"{verdict_text(solution)}")
    with figures.styled():
        # a thinned run's node spacing is not its step: the step row is left out (the title
        # gives the steps' range)
        fig = _figure(solution, _rows(solution, scheme.variable_steps and kept is None,
                                      energy), title, fixed_ends=fixed_ends,
                      dots=kept is not None)
        figures.unicode_labels(fig)
        figures.save(fig, path, fmt)


def _kept(solution) -> dict | None:
    """A thinned march's record of what it kept (``Solution.march.kept``), else ``None``."""
    record = getattr(solution, "march", None)
    return getattr(record, "kept", None) if record is not None else None


def _steps_words(solution, kept: dict | None) -> str:
    """The steps a run took: its intervals, or for a thinned march the steps it marched,
    the nodes it kept and the steps' range (its kept nodes are ``keep_every`` steps apart)."""
    if kept is None:
        return f"{solution.steps} steps"
    steps = max(int(kept["nodes_marched"]) - 1, 0)
    words = f"{steps} steps ({kept['nodes_kept']} nodes kept"
    if kept.get("tau_min") is not None:
        words += f", tau in [{kept['tau_min']:.3g}, {kept['tau_max']:.3g}]"
    return words + ")"


def verdict_text(solution) -> str:
    """What a run's title says of it: the accuracy check's verdict (``accurate``, ``drifted
    from t = ...``) for a run that passed its checks, the failed status otherwise (``inaccurate``,
    ``failed: newton_failed``); never ``success`` alone for a drifted run."""
    verdict = solution.verdict.name if solution.verdict is not None else None
    code = solution.status.code
    if not solution.success:
        return code if code == verdict else f"failed: {code}"
    if verdict == "drifted" and solution.verdict.t_drift is not None:
        return f"drifted from $t = {solution.verdict.t_drift:.4g}$"
    return verdict or "success (accuracy not checked)"


def plot_solution(solution, path=None, *, system=None, params=None, title: str | None = None):
    """The figure of ``ddvp march`` for any `Solution` (a march, a
    fixed-endpoint solve, a higher-order run): ``q``, ``p``, the step length where it varies,
    the phase portrait (and the configuration plane for two or more degrees of freedom), and,
    given the ``system`` that was solved (``params``: its values, default those of the solve),
    the relative energy drift ``|H - H0| / |H0|`` at the nodes (for a time-dependent ``H``, the
    residual of the scheme's energy equation relative to ``|H0|``; absolute where ``H0 = 0``).

    Returns:
        ``path`` after writing the figure there (PNG, SVG or PDF by its suffix), or the
        ``matplotlib.figure.Figure`` when ``path`` is ``None`` (Jupyter shows it).
    """
    tau = solution.tau
    varies = tau.size > 1 and float(np.ptp(tau)) > 1e-9 * float(np.max(np.abs(tau)))
    energy = None
    if system is not None and solution.t.size >= 2:
        nodes = solution.energy(system, params)
        scale, kind = _energy_scale(nodes[0])
        if system.time_dependent:
            energy = (f"energy residual{kind}", [("", solution.t[1:-1],
                                                  np.abs(solution.energy_residual) / scale)])
        else:
            energy = (f"$|H - H_0|${kind}", [(r"node energy $H(q_k, p_k)$", solution.t,
                                             _drift(nodes, scale))])
    title = title or f"{solution.scheme}: {solution.steps} steps, {verdict_text(solution)}"
    with figures.styled():
        fig = _figure(solution, _rows(solution, varies, energy), title)
        figures.unicode_labels(fig)
        if path is None:
            figures.save(fig, figures.Keep())  # the same finish as a saved figure, drawn
            return fig
        figures.save(fig, path, figures.format_of(path))
    return path


def _energy_scale(h0) -> tuple[float, str]:
    """The scale the energy error is divided by and what the axis label adds: ``|H0|``
    (relative), or 1 where ``H0`` is exactly zero (absolute, and said so)."""
    h0 = abs(float(h0))
    return (h0, r" / $|H_0|$") if h0 > 0 and np.isfinite(h0) else (1.0, " (absolute)")


def _energy_panel(solution, system, scheme, energies):
    """The energy panel's label and curves: relative drifts of the interval and node energies
    for autonomous ``H``, the relative residual of the energy equation for a time-dependent
    one."""
    t = solution.t
    nodes, interval = energies
    scale, kind = _energy_scale(nodes[0])
    if system.time_dependent:
        rule = diagnostic_rule(scheme)
        return (f"|{rule} residual|{kind}",
                [("", t[1:-1], np.abs(solution.energy_residual) / scale)])
    node = (r"node $H(q_k, p_k)$", t, _drift(nodes, scale))
    if interval is None:  # a thinned march: no consecutive intervals
        return f"$|H - H_0|${kind}", [node]
    return (f"$|H - H_0|${kind}",
            [(r"interval $H(Q_k, P_k)$", t[:-1], _drift(interval, scale)), node])


def _drift(energies, scale) -> np.ndarray:
    """``|H_k - H_0| / scale``, the first left out (zero by definition, it says nothing; on
    the log panel it would be drawn at the tick of exact zeros, `figures.zero_tick`)."""
    drift = np.abs(np.asarray(energies, dtype=float) - energies[0]) / scale
    drift[:1] = np.nan
    return drift


def _rows(solution, steps: bool, energy) -> list:
    """``(label, curves, log)`` per row, ``curves`` a list of ``(name, t, values)``."""
    t = solution.t
    n = solution.q.shape[1]
    rows = [(f"${name}$", [(f"${name}_{{{i + 1}}}$" if n > 1 else "", t, values[:, i])
                           for i in range(n)], False)
            for name, values in (("q", solution.q), ("p", solution.p))]
    if steps:
        rows.append((r"step $\tau_k$", [("", t[:-1], solution.tau)], False))
    if energy is not None:
        rows.append((energy[0], energy[1], True))
    return rows


def _figure(solution, rows, title: str, *, fixed_ends: bool = False, dots: bool = False):
    """The figure: the rows against ``t`` over the whole run (and over its first
    ``ZOOM_STEPS`` steps, for long runs) and the state-space panels on the right, filling the
    column's height (one degree of freedom: the phase portrait, larger, centred).

    The margins are fixed in inches rather than found by a layout engine: constrained layout
    drew the figure twice and measured every tick label, 1.6 s of the 1.8 s the figure of
    ``paper_pendulum`` took (``scripts/benchmarks/bench_figure.py``)."""
    t = solution.t
    zoom = t.size >= ZOOM_FROM_NODES
    spans = [(t[0], t[-1])] + ([(t[0], t[ZOOM_STEPS])] if zoom else [])
    n = solution.q.shape[1]
    kinds = ["phase", "configuration"] if n > 1 else ["phase"]
    # inches: time columns, the gap after each (the tick labels of the next), the state
    # column; left margin for the y labels, top for the titles, bottom for t
    widths = [3.2, 1.9][:len(spans)] + [2.1 if n > 1 else 2.8]
    gaps = [0.55] * (len(spans) - 1) + [0.95]
    left, right, top, bottom = 0.85, 0.5, 0.55, 0.5
    width = left + sum(widths) + sum(gaps) + right
    height = max(3.4, ROW_HEIGHT * len(rows) + top + bottom)
    fig = figures.new_figure(width, height, layout=None)
    x = left
    ends = (t[0], t[-1]) if fixed_ends and t.size > 1 else None
    for column, span in enumerate(spans):
        first = None
        for row, (label, curves, log) in enumerate(rows):
            box = [x / width, 1 - (top + (row + 1) * ROW_HEIGHT - 0.12) / height,
                   widths[column] / width, (ROW_HEIGHT - 0.24) / height]
            ax = fig.add_axes(box)
            first = first or ax
            _time_panel(ax, span, curves, log, legend=column == 0,
                        ends=ends if row == 0 else None, dots=dots)
            ax.set_ylabel(label)
            if column:  # shown only if it carries the axis' offset (figures.offset_in_label):
                ax.yaxis.set_label_position("right")  # then named as in the first column
                ax.yaxis.label.set_visible(False)
            if row < len(rows) - 1:
                ax.tick_params(labelbottom=False)
        first.set_title(f"first {ZOOM_STEPS} steps" if column else
                        ("whole run (min-max envelope)" if zoom else ""))
        ax.set_xlabel("$t$")
        x += widths[column] + gaps[column]
    cell = (height - top - bottom) / len(kinds)
    for index, kind in enumerate(kinds):
        side = min(widths[-1], cell - 0.7)
        lowest = top + index * cell + 0.5 * (cell - side) + 0.1
        box = [x / width, 1 - (lowest + side) / height, widths[-1] / width, side / height]
        _state_panel(fig.add_axes(box), solution.q, solution.p, kind, fixed_ends=fixed_ends,
                     dots=dots)
    fig.suptitle(figures.unicode_math(title), y=1 - 0.12 / height)
    return fig


def _time_panel(ax, span, curves, log: bool, *, legend: bool, ends=None,
                dots: bool = False) -> None:
    """One panel against ``t`` over ``span``: each curve reduced to its min/max envelope per
    pixel column (``figures.decimate``), or with ``dots`` (a thinned march: samples of the
    motion, not its path) its points unjoined while they are fewer than two per pixel column
    (denser samples merge into a block of overlapping dots: their envelope then); the names of
    the curves, if ``legend``, in a band left free above the data (never over them);
    ``ends``: the two fixed ends' times. On a log panel exact zeros are drawn at its bottom,
    the tick there labelled 0 (``figures.zero_tick``), not left out as gaps."""
    start, stop = span
    bins = figures.bins_for(ax)
    names = [name for name, _, _ in curves]
    inside = [(times >= min(start, stop)) & (times <= max(start, stop))
              for _, times, _ in curves]
    floor = (figures.zero_floor([values[chosen] for (_, _, values), chosen
                                 in zip(curves, inside, strict=True)]) if log else None)
    for index, (name, times, values) in enumerate(curves):
        chosen = inside[index]
        times, values = times[chosen], values[chosen]
        if times.size > 1 and times[-1] < times[0]:  # a backward march: the envelope's bins
            times, values = times[::-1], values[::-1]  # want increasing times
        shown = figures.with_zeros_at(values, floor) if log else values
        if dots and times.size <= 2 * bins:  # samples a pixel or more apart: each visible
            ax.plot(times, shown, ".", ms=SAMPLE_DOT, mew=0, label=name or None,
                    color=f"C{index % 8}")
        else:  # a thinned run's samples denser than the pixels merge: their envelope
            figures.envelope_band(ax, times, shown, bins, lw=0.7, label=name or None,
                                  color=f"C{index % 8}")
        if ends is not None:
            fixed = np.isin(times, ends) & chosen
            ax.plot(times[fixed], values[fixed], **FIXED_END, clip_on=False,
                    label="fixed ends" if index == 0 else None)
    if log:
        ax.set_yscale("log")
        if floor is not None:
            figures.zero_tick(ax, floor)
    ax.set_xlim(start, stop)  # a backward march's axis runs from t0 down to t_end
    ax.minorticks_off()  # 40% of the drawing time of a run figure, and little to read
    labelled = 1 < len(names) <= LEGEND_COMPONENTS and all(names)
    if labelled or ends is not None:
        _headroom(ax, log)
        if legend:
            ax.legend(loc="upper center", ncol=len(names) + (ends is not None),
                      borderaxespad=0.1, handlelength=1.2, columnspacing=1.0)


def _headroom(ax, log: bool) -> None:
    """The panel's upper limit raised so that a band of about a third of its height above
    the data holds the legend."""
    low, high = ax.get_ylim()
    if log:
        ax.set_ylim(low, high * (high / low) ** 0.5)
    else:
        ax.set_ylim(low, high + 0.45 * (high - low))


# The prescribed ends of a fixed-endpoint run.
FIXED_END = {"marker": "s", "color": "black", "mfc": "none", "ms": 5, "mew": 1.0,
             "linestyle": "none", "zorder": 4}


def _state_panel(ax, q, p, kind: str, *, fixed_ends: bool = False,
                 dots: bool = False) -> None:
    """The phase portrait ``(q_1, p_1)`` or the configuration plane ``(q_1, q_2)``: the line
    through the nodes (the nodes as dots for long runs, thinned to one per half pixel for very
    long ones), the start as a red dot (a fixed-endpoint run: both ends, as squares where they
    are prescribed (the configuration plane), as dots in the phase plane, whose p is not); equal
    aspect in the configuration plane always, in the phase plane unless the ranges are of
    unrelated scales (``EQUAL_ASPECT_RATIO``), the box kept square where equal aspect would
    make it a narrow strip (``STRIP_RATIO``); a thinned run's title says its points are the kept
    nodes (samples, which can miss the loops between them)."""
    several = q.shape[1] > 1
    if kind == "phase":
        x, y = q[:, 0], p[:, 0]
        labels = ("$q_1$", "$p_1$") if several else ("$q$", "$p$")
    else:
        x, y = q[:, 0], q[:, 1]
        labels = ("$q_1$", "$q_2$")
    if dots and x.size <= DOTS_FROM_NODES:  # a thinned march's samples: not a path
        ax.plot(x, y, ".", ms=SAMPLE_DOT, mew=0, color="C0")
    elif x.size <= DOTS_FROM_NODES:
        ax.plot(x, y, lw=0.6, color="C0")
    else:
        shown = (figures.thin_points(x, y, 2 * figures.bins_for(ax))
                 if x.size >= THIN_FROM_NODES else slice(None))
        ax.plot(x[shown], y[shown], ",", color="C0", rasterized=True)
    if fixed_ends and kind == "configuration":
        ax.plot(x[[0, -1]], y[[0, -1]], **FIXED_END, clip_on=False)
        for index, name in ((0, "start"), (-1, "end")):
            ax.annotate(name, (x[index], y[index]), xytext=(5, 4), textcoords="offset points",
                        fontsize="small")
    elif fixed_ends:  # the phase plane: q is prescribed at the ends, p is solved for
        ax.plot(x[[0, -1]], y[[0, -1]], "o", color="C1", ms=4, clip_on=False, zorder=3)
        for index, name in ((0, "start"), (-1, "end")):
            ax.annotate(name, (x[index], y[index]), xytext=(4, 4), textcoords="offset points",
                        fontsize="small", color="C1")
    else:
        ax.plot(x[:1], y[:1], "o", color="C1", ms=4, clip_on=False, zorder=3)
        finite = y[np.isfinite(y)]
        high = finite.size and y[0] > finite.min() + 0.8 * np.ptp(finite)
        ax.annotate("start", (x[0], y[0]), xytext=(4, -10 if high else 4),
                    textcoords="offset points", fontsize="small", color="C1")
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    ax.set_title(("phase portrait" if kind == "phase" else "configuration")
                 + (", kept nodes" if dots else ""))
    ax.minorticks_off()
    ax.margins(0.06)
    spans = [float(np.ptp(v[np.isfinite(v)])) if np.isfinite(v).any() else 0.0 for v in (x, y)]
    if kind == "configuration" or (min(spans) > 0
                                   and max(spans) <= EQUAL_ASPECT_RATIO * min(spans)):
        strip = spans[0] > 0 and spans[1] > STRIP_RATIO * spans[0]  # tall: x ticks crowd
        ax.set_aspect("equal", adjustable="datalim" if strip else "box")


def _nodes(ax, t, values, **style) -> None:
    """Nodes against ``t`` as dots joined by a line; for more nodes than the panel has pixel
    columns, where the dots would merge, their min/max envelope (``figures.envelope_band``)."""
    bins = figures.bins_for(ax)
    if t.size > 2 * bins:
        figures.envelope_band(ax, t, values, bins, lw=0.7, **style)
    else:
        ax.plot(t, values, ".-", ms=2.5, **style)


def _exact(ax, t, values) -> None:
    """The exact solution, dashed; for more nodes than pixel columns the dashed lines through
    its minima and its maxima per pixel column (``figures.decimate``): the outline the nodes'
    envelope should fill."""
    bins = figures.bins_for(ax)
    if t.size <= 2 * bins:
        ax.plot(t, values, "k--", lw=0.8, label="exact $q(t)$")
        return
    x, y = figures.decimate(t, values, bins)
    ax.plot(x[::2], y[::2], "k--", lw=0.8, label="exact $q(t)$")
    ax.plot(x[1::2], y[1::2], "k--", lw=0.8)


def plot_higher_trajectory(solution, scene, command, exact, energy, path,
                           fmt: str = "png") -> None:
    """A higher-order run: nodes against the exact solution, their error, the steps, and the
    energy ``E^(k)`` where the recursion defines it; a run of more nodes than pixel columns
    as envelopes (`_nodes`, `_exact`)."""
    with figures.styled():
        panels = 3 if energy.size else 2
        fig = figures.new_figure(figures.TEXT_WIDTH * 0.75, 1.5 * panels + 0.6)
        axes = fig.subplots(panels, 1, sharex=True)
        _nodes(axes[0], solution.t, solution.q[:, 0], label="nodes $q_k$")
        _exact(axes[0], solution.t, np.asarray(exact)[:, 0] if np.ndim(exact) > 1 else exact)
        axes[0].set_ylabel("$q$")
        axes[0].legend(loc="upper right")
        _nodes(axes[1], solution.t[:-1], solution.tau, color="C2")
        axes[1].set_ylabel(r"step $\tau_k$")
        tau = solution.tau
        if tau.size and float(np.ptp(tau)) <= 1e-9 * float(np.max(np.abs(tau))):
            # constant to round-off (fixed steps): the offset axis magnified 1e-14 noise
            axes[1].set_ylim(0.9 * float(tau.min()), 1.1 * float(tau.max()))
            axes[1].ticklabel_format(axis="y", useOffset=False)
        if energy.size:
            lo = scene.order - 1
            _nodes(axes[2], solution.t[lo:lo + energy.size], energy - energy[0], color="C3")
            axes[2].set_ylabel(r"$E^{(k)} - E^{(l-1)}$")
        axes[-1].set_xlabel("$t$")
        status = solution.status.code
        fig.suptitle(f"{scene.name} {command} [{solution.scheme}]: {status}"
                     + ("" if solution.success else " (FAILED: the nodes reached so far)"))
        figures.save(fig, path, fmt)
