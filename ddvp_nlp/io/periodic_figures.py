"""The figure of a followed family of periodic orbits (plain matplotlib, imported only when a
figure is drawn): the orbits, the period against the energy and the stability indices against
the energy, each orbit coloured by its verdict, the located bifurcations marked."""

from __future__ import annotations

import numpy as np

COLOURS = {"stable": "tab:green", "marginal": "tab:orange", "unstable": "tab:red"}
MARKERS = {"fold": "s", "branch point": "D", "period doubling": "v"}


def plot_followed_family(family, title: str, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    members = family.members
    fig, (orbits, periods, indices) = plt.subplots(1, 3, figsize=(16, 4.8))
    for member in members:
        colour = COLOURS[member.stability.verdict]
        q, p = member.orbit.q, member.orbit.p
        x, y = (q[:, 0], p[:, 0]) if q.shape[1] == 1 else (q[:, 0], q[:, 1])
        orbits.plot(x, y, "-", lw=0.6, color=colour)
    orbits.set_xlabel("q1")
    orbits.set_ylabel("p1" if members and members[0].orbit.q.shape[1] == 1 else "q2")
    orbits.set_aspect("equal", adjustable="datalim")
    orbits.set_title("orbits")
    energy = np.array([m.energy for m in members])
    period = np.array([m.orbit.stats["period"] for m in members])
    periods.plot(energy, period, "-", color="0.7", lw=0.8, zorder=1)
    for verdict, colour in COLOURS.items():
        chosen = [j for j, m in enumerate(members) if m.stability.verdict == verdict]
        if chosen:
            periods.plot(energy[chosen], period[chosen], "o", ms=4, color=colour, label=verdict)
    _indices(indices, members)
    for bifurcation in family.bifurcations:
        marker = MARKERS[bifurcation.kind]
        periods.plot(bifurcation.energy, bifurcation.orbit.stats["period"], marker, ms=9,
                     mfc="none", mec="k", mew=1.4)
        indices.axvline(bifurcation.energy, color="k", ls=":", lw=0.8)
    for kind, marker in MARKERS.items():
        if any(b.kind == kind for b in family.bifurcations):
            periods.plot([], [], marker, ms=9, mfc="none", mec="k", label=kind)
    periods.set_xlabel("energy E")
    periods.set_ylabel("period T")
    periods.set_title(f"period (N = {members[0].orbit.steps})" if members else "period")
    periods.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120, format="png")
    plt.close(fig)


def _indices(axes, members) -> None:
    """The stability indices (real parts) against the energy with the lines ``k = +-2``;
    on a symmetric log scale when some index passes 10 (an unstable pair's grows like its
    multiplier)."""
    values = [member.stability.indices.real for member in members]
    for member, k in zip(members, values, strict=True):
        colour = COLOURS[member.stability.verdict]
        axes.plot(np.full(k.size, member.energy), k, "o", ms=3, color=colour)
    for level in (-2, 2):
        axes.axhline(level, color="0.5", lw=0.8, ls="--")
    largest = max((float(np.max(np.abs(k))) for k in values if k.size), default=0.0)
    if largest > 10:
        axes.set_yscale("symlog", linthresh=3.0)
    else:
        axes.set_ylim(-max(3.0, 1.1 * largest), max(3.0, 1.1 * largest))
    if largest == 0.0:
        axes.text(0.5, 0.5, "no nontrivial multiplier\n(every one is trivial)",
                  transform=axes.transAxes, ha="center", va="center")
    axes.set_xlabel("energy E")
    axes.set_ylabel("stability index k = mu + 1/mu")
    axes.set_title("stability indices (|k| < 2: stable pair)")
