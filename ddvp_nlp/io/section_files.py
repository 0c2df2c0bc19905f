"""``ddvp poincare``'s output: ``section.npz`` and ``section.csv`` (every crossing and its orbit),
``orbits.csv`` (each orbit's start, status, steps and nodal energy error) and ``section.png``."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from . import atomic, figures
from .run_folder import figure_writer


def write_section(out, section, *, plot: bool = True, interruptible=None) -> dict:
    """The files of a Poincare section (module docstring) in the folder ``out``, with
    ``meta.json`` last, as one set through the output layer (`ddvp_nlp.io.atomic`)."""
    n = section.points.shape[1] // 2
    names = [f"q{i + 1}" for i in range(n)] + [f"p{i + 1}" for i in range(n)]
    crossings, orbits = io.StringIO(), io.StringIO()
    writer = csv.writer(crossings, lineterminator="\n")
    writer.writerow(["orbit", "t", *names])
    for k, t, z in zip(section.orbit, section.times, section.points, strict=True):
        writer.writerow([int(k), repr(float(t)), *(repr(float(v)) for v in z)])
    writer = csv.writer(orbits, lineterminator="\n")
    writer.writerow(["orbit", "status", "steps", "nodal_energy_error", "accuracy",
                     "t_drift", *(f"start_{name}" for name in names)])
    verdicts = section.verdicts or [("", None)] * len(section.starts)
    for k, start in enumerate(section.starts):
        verdict, t_drift = verdicts[k]
        writer.writerow([k, section.statuses[k], int(section.steps[k]),
                         f"{section.energy_errors[k]:.3e}", verdict,
                         "" if t_drift is None else repr(float(t_drift)),
                         *(repr(float(v)) for v in start)])

    def arrays(handle):
        np.savez(handle, points=section.points, times=section.times, orbit=section.orbit,
                 starts=section.starts, energy_errors=section.energy_errors,
                 steps=section.steps, energy=section.energy)

    meta = {"command": "poincare", "energy": float(section.energy),
            "section": section.section, "direction": section.direction,
            "orbits": int(section.starts.shape[0]), "crossings": int(section.points.shape[0]),
            "failed": sum(s != "success" for s in section.statuses)}
    with atomic.output_folder(out) as folder:
        figure = figure_writer(folder, "section.png",
                               (lambda handle: plot_section(section, handle)) if plot else None,
                               interruptible)
        if plot and figure is None:
            meta["figure"] = "not drawn: interrupted while drawing"
        return folder.commit({"section.npz": arrays,
                              "section.csv": atomic.text(crossings.getvalue()),
                              "orbits.csv": atomic.text(orbits.getvalue()),
                              "section.png": figure}, meta)


def plot_section(section, path: Path, fmt: str = "png") -> None:
    """The crossings in the plane of the first free coordinate and its momentum, one colour per
    orbit, as dots of a few pixels; the boundary of the energy surface on the section
    (``section.boundary``, two degrees of freedom) as a thin grey line."""
    import matplotlib

    n = section.points.shape[1] // 2
    fixed = int(section.section[1:].split("=")[0]) - 1
    free = next(i for i in range(n) if i != fixed) if n > 1 else fixed
    orbits = section.starts.shape[0]
    with figures.styled():
        fig = figures.new_figure(figures.COLUMN_WIDTH * 1.3, figures.COLUMN_WIDTH * 1.3)
        ax = fig.subplots()
        colours = matplotlib.colormaps["turbo"](np.linspace(0.05, 0.95, max(orbits, 1)))
        for k in range(orbits):
            mine = section.orbit == k
            ax.plot(section.points[mine, free], section.points[mine, n + free], "o",
                    ms=DOT_SIZE, mew=0, color=colours[k], rasterized=True)
        _boundary(ax, section)
        failed = [k for k, s in enumerate(section.statuses) if s != "success"]
        if failed:  # where a failed orbit started, so a reader knows a curve is cut short
            ax.plot(section.starts[failed, free], section.starts[failed, n + free],
                    **figures.FAILED, label=f"{len(failed)} orbits failed (start)")
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper right")
        ax.set_xlabel(f"$q_{free + 1}$")
        ax.set_ylabel(f"$p_{free + 1}$")
        ax.set_title(f"Poincare section ${_section_tex(section.section)}$ "
                     f"({section.direction}), $E = {section.energy:g}$,\n{orbits} orbits, "
                     f"{section.points.shape[0]} crossings")
        figures.save(fig, path, fmt)


# The crossings' dots, in points: about 4 pixels across at the saved 200 dpi (single pixels
# left sparse sections faint).
DOT_SIZE = 1.5


def _boundary(ax, section) -> None:
    """The curve ``D = 0`` of ``section.boundary`` (where the energy surface meets the
    section), the axes' limits those of the crossings and the curve."""
    boundary = getattr(section, "boundary", None)
    if boundary is None:
        return
    x, y, D = boundary
    if not (np.nanmin(D) < 0 < np.nanmax(D)):
        return
    contour = ax.contour(x, y, D, levels=[0.0], colors="0.35", linewidths=0.7)
    ax.plot([], [], color="0.35", lw=0.7, label="energy boundary $H = E$")
    points = [path.vertices for path in contour.get_paths() if len(path.vertices)]
    crossings = [np.column_stack(line.get_data()) for line in ax.lines
                 if len(line.get_xdata())]
    if points:  # the contour's grid reaches far beyond the curve: limits of what is drawn
        xy = np.vstack(points + crossings)
        low, high = np.nanmin(xy, axis=0), np.nanmax(xy, axis=0)
        pad = 0.04 * (high - low)
        ax.set_xlim(low[0] - pad[0], high[0] + pad[0])
        ax.set_ylim(low[1] - pad[1], high[1] + pad[1])


def _section_tex(section: str) -> str:
    """``q1=0`` as mathtext ``q_1 = 0``."""
    name, _, value = section.partition("=")
    return f"{name[0]}_{{{name[1:]}}} = {value}"
