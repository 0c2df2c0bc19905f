"""The figure of a followed family of periodic orbits (the house style of ``figures.py``,
matplotlib imported only when a figure is drawn): the orbits, the period against the energy
and the stability indices against the energy, each orbit coloured by its verdict, the located
bifurcations marked."""

from __future__ import annotations

import numpy as np

from . import figures

COLOURS = {"stable": "#228833", "marginal": "#CCBB44", "unstable": "#EE6677"}
MARKERS = {"fold": "s", "branch point": "D", "period doubling": "v"}


def plot_followed_family(family, title: str, path, fmt: str = "png") -> None:
    """Three panels: the orbits coloured by their verdict, the period against the energy with
    the bifurcations marked, and the stability indices."""
    with figures.styled():
        fig = figures.new_figure(figures.TEXT_WIDTH * 1.15, 2.9)
        _draw_family(fig, family)
        fig.suptitle(title)
        figures.save(fig, path, fmt)


def _draw_family(fig, family) -> None:
    members = family.members
    orbits, periods, indices = fig.subplots(1, 3)
    indices.sharex(periods)  # the same energies, whatever the indices panel holds
    for member in members:
        colour = COLOURS[member.stability.verdict]
        q, p = member.orbit.q, member.orbit.p
        x, y = (q[:, 0], p[:, 0]) if q.shape[1] == 1 else (q[:, 0], q[:, 1])
        orbits.plot(x, y, "-", lw=0.6, color=colour)
    orbits.set_xlabel("$q_1$")
    orbits.set_ylabel("$p_1$" if members and members[0].orbit.q.shape[1] == 1 else "$q_2$")
    orbits.set_aspect("equal", adjustable="datalim")
    orbits.set_title("orbits")
    energy = np.array([m.energy for m in members])
    period = np.array([m.orbit.orbit.period for m in members])
    periods.plot(energy, period, "-", color="0.7", lw=0.8, zorder=1)
    for verdict, colour in COLOURS.items():
        chosen = [j for j, m in enumerate(members) if m.stability.verdict == verdict]
        if chosen:
            periods.plot(energy[chosen], period[chosen], "o", ms=4, color=colour, label=verdict)
    _indices(indices, members)
    for bifurcation in family.bifurcations:
        marker = MARKERS[bifurcation.kind]
        periods.plot(bifurcation.energy, bifurcation.orbit.orbit.period, marker, ms=9,
                     mfc="none", mec="k", mew=1.4)
        indices.axvline(bifurcation.energy, color="k", ls=":", lw=0.8)
    for kind, marker in MARKERS.items():
        if any(b.kind == kind for b in family.bifurcations):
            periods.plot([], [], marker, ms=9, mfc="none", mec="k", label=kind)
    periods.set_xlabel("energy $E$")
    periods.set_ylabel("period $T$")
    periods.set_title(f"period ($N = {members[0].orbit.steps}$)" if members else "period")
    periods.legend(fontsize="small")


def _indices(axes, members) -> None:
    """The stability indices (real parts) against the energy with the lines ``k = +-2``,
    the axis scaled to the indices (`index_limits`). A family with no nontrivial multiplier
    (one degree of freedom) shows what there is, its trivial pair (``mu = 1``, ``k = 2``), and
    says so."""
    values = [member.stability.indices.real for member in members]
    for member, k in zip(members, values, strict=True):
        colour = COLOURS[member.stability.verdict]
        axes.plot(np.full(k.size, member.energy), k, "o", ms=3, color=colour)
    for level in (-2, 2):
        axes.axhline(level, color="0.5", lw=0.8, ls="--")
    largest = max((float(np.max(np.abs(k))) for k in values if k.size), default=0.0)
    index_limits(axes, values, largest)
    if largest == 0.0 and members:
        trivial = [(m.energy, np.asarray(m.stability.trivial)) for m in members]
        energies = [e for e, mu in trivial for _ in range(mu.size)]
        k = [float((value + 1 / value).real) for _, mu in trivial for value in mu]
        axes.plot(energies, k, "o", ms=4, mfc="none", mec="0.3", mew=0.8,
                  label=r"trivial pair $\mu = 1$")
        axes.text(0.5, 0.3, "no nontrivial multiplier:\nevery one is trivial",
                  transform=axes.transAxes, ha="center", va="center", fontsize="small")
        axes.legend(loc="upper center", fontsize="small")
    axes.set_xlabel("energy $E$")
    axes.set_ylabel(r"stability index $k = \mu + 1/\mu$")
    axes.set_title(r"stability indices ($|k| < 2$: stable)", fontsize="medium")


def index_limits(axes, values, largest: float, axis: str = "y") -> None:
    """The index axis (``axis``, "y" or "x") from the data and the lines ``k = +-2``: linear
    while every index is within 10, else a symmetric log scale (linear within 3; an unstable
    pair's index grows like its multiplier, and the indices of one orbit may span decades), the
    limits the data's with a margin in the scale's own terms (a factor on the log part), so no
    marker sits on an edge; the side of zero no index reaches shows no more than the line
    ``k = -2`` or ``2``."""
    set_limits = getattr(axes, f"set_{axis}lim")
    if largest == 0.0:
        set_limits(-3.0, 3.0)
        return
    data = np.concatenate([k for k in values if k.size])
    top, bottom = max(float(np.max(data)), 2.0), min(float(np.min(data)), -2.0)
    if max(top, -bottom) <= 10:
        pad = 0.08 * (top - bottom)
        set_limits(bottom - pad, top + pad)
        return
    getattr(axes, f"set_{axis}scale")("symlog", linthresh=3.0)
    low, high = (bottom * 2.0 if bottom < -3 else bottom - 0.6,
                 top * 2.0 if top > 3 else top + 0.6)
    set_limits(low, high)
    _index_ticks(getattr(axes, f"{axis}axis"), low, high)


def _index_ticks(axis, low: float, high: float) -> None:
    """The symmetric log axis's ticks: -2, 0 and 2 (the stability bounds) in its linear part,
    then the decades the limits hold, each labelled (the default labelled 1 and 0 but left the
    negative side bare)."""
    from matplotlib.ticker import FixedFormatter, FixedLocator

    ticks, labels = [-2.0, 0.0, 2.0], ["$-2$", "$0$", "$2$"]
    for sign, reach in ((1.0, high), (-1.0, -low)):
        for decade in range(1, int(np.floor(np.log10(reach))) + 1 if reach >= 10 else 1):
            ticks.append(sign * 10.0 ** decade)
            labels.append(("$-10^{%d}$" if sign < 0 else "$10^{%d}$") % decade)
    order = np.argsort(ticks)
    axis.set_major_locator(FixedLocator([ticks[i] for i in order]))
    axis.set_major_formatter(FixedFormatter([labels[i] for i in order]))
    axis.set_minor_locator(FixedLocator([]))
