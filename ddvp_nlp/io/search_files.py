"""An orbit search on disk: ``orbits.csv`` (one row per orbit found), ``failures.csv`` (each
failed seed with its reason), ``orbits.png`` (every orbit found in the plane of the positions,
coloured by its verdict, beside its period and stability index) and ``meta.json`` (what was
searched) as one set."""

from __future__ import annotations

import csv
import io

import numpy as np

from . import atomic, figures
from .orbit_figures import COLOURS, index_limits
from .run_folder import figure_writer

COLUMNS = ("period", "index", "verdict", "returns", "symmetric", "seeds", "q1", "q2", "p1", "p2",
           "closure", "grid_period", "grid_index", "note")


def orbit_rows(search) -> list[dict]:
    """One row per orbit found: its period, exact-flow stability index, verdict, start and the
    grid's refined period and index (NaN where it was not refined)."""
    rows = []
    for orbit in search.orbits:
        grid = orbit.solution is not None and orbit.solution.success
        rows.append({
            "period": orbit.period, "index": orbit.index, "verdict": orbit.verdict,
            "returns": orbit.returns, "symmetric": orbit.symmetric, "seeds": orbit.seeds,
            **dict(zip(("q1", "q2", "p1", "p2"), map(float, orbit.start), strict=True)),
            "closure": orbit.closure,
            "grid_period": float(orbit.solution.t[-1] - orbit.solution.t[0]) if grid
            else float("nan"),
            "grid_index": float(orbit.stability.indices.real[0]) if orbit.stability is not None
            and orbit.stability.indices.size else float("nan"),
            "note": orbit.note})
    return rows


def _csv(rows: list[dict], columns) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue()


def write_search(out, scene_name: str, search, *, plot: bool = True,
                 interruptible=None) -> list[dict]:
    """The set of files of an orbit search (module docstring); returns the orbits' rows."""
    rows = orbit_rows(search)
    failures = [{"seed": " ".join(f"{v:.8g}" for v in failed.seed), "reason": failed.reason}
                for failed in search.failures]
    searched = search.searched
    meta = {"command": "periodic", "mode": "search", "scene": scene_name,
            "orbits": len(rows), "failed_seeds": len(failures), "cpu_seconds": search.seconds,
            "searched": searched.describe(), "energy": searched.energy,
            "section": searched.section, "window": list(searched.window),
            "seeds": searched.seeds, "accessible": searched.accessible,
            "reversing": None if searched.reversing is None else list(searched.reversing),
            "max_returns": searched.max_returns, "jitter": getattr(searched, "jitter", None)}
    with atomic.output_folder(out) as folder:
        def draw(handle):
            plot_search(search, f"{scene_name}: periodic orbits at E = {searched.energy:.8g} "
                                f"({searched.section})", handle)

        figure = figure_writer(folder, "orbits.png", draw if plot and rows else None,
                               interruptible)
        folder.commit({"orbits.csv": atomic.text(_csv(rows, COLUMNS)),
                       "failures.csv": atomic.text(_csv(failures, ("seed", "reason"))),
                       "orbits.png": figure}, meta)
    return rows


def plot_search(search, title: str, path, fmt: str = "png") -> None:
    """Two panels: every orbit found in the plane ``(q1, q2)`` coloured by its verdict, and each
    orbit's period against its stability index (symmetric log scale)."""
    with figures.styled():
        fig = figures.new_figure(figures.TEXT_WIDTH, 3.0)
        plane, table = fig.subplots(1, 2)
        labels: dict = {}  # mirror images share a point: one label "3,4"
        for j, orbit in enumerate(search.orbits):
            colour = COLOURS.get(orbit.verdict, "0.4")
            plane.plot(orbit.path[:, 0], orbit.path[:, 1], "-", lw=0.7, color=colour)
            table.plot(orbit.index, orbit.period, "o", ms=4, color=colour)
            key = (f"{orbit.index:.3g}", f"{orbit.period:.4g}")
            labels.setdefault(key, ((orbit.index, orbit.period), []))[1].append(str(j + 1))
        for point, numbers in labels.values():
            table.annotate(",".join(numbers), point, fontsize="x-small", xytext=(3, 3),
                           textcoords="offset points")
        for verdict, colour in COLOURS.items():
            if any(o.verdict == verdict for o in search.orbits):
                table.plot([], [], "o", ms=4, color=colour, label=verdict)
        plane.set_xlabel("$q_1$")
        plane.set_ylabel("$q_2$")
        plane.set_aspect("equal", adjustable="datalim")
        plane.set_title(f"{len(search.orbits)} orbits")
        for level in (-2, 2):
            table.axvline(level, color="0.5", lw=0.8, ls="--")
        indices = np.array([o.index for o in search.orbits], float)
        indices = indices[np.isfinite(indices)]
        index_limits(table, [indices], float(np.max(np.abs(indices), initial=0.0)), "x")
        table.set_xlabel(r"stability index $k = \mu + 1/\mu$")
        table.set_ylabel("period $T$")
        table.set_ylim(0, 1.1 * max((o.period for o in search.orbits), default=1.0))
        table.legend(fontsize="small")
        fig.suptitle(title)
        figures.save(fig, path, fmt)
