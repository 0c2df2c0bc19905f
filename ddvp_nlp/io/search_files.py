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
           "closure", "grid_verdict", "grid_period", "grid_index", "grid_period_gap",
           "grid_start_gap", "grid_index_gap", "grid_index_off", "grid_error", "grid_landed",
           "note")


def orbit_rows(search) -> list[dict]:
    """One row per orbit found: its period, exact-flow stability index, verdict (of that
    index, with the search's tolerance), start and the grid's refinement: its verdict
    (``another orbit`` where the grid's orbit is not this one, ``search_grid.py``), period and
    index (NaN where it was not refined), and its gaps from the exact orbit."""
    rows = []
    for orbit in search.orbits:
        grid = orbit.solution is not None and orbit.solution.success
        check = getattr(orbit, "grid", None)
        rows.append({
            "period": orbit.period, "index": orbit.index, "verdict": orbit.verdict,
            "returns": orbit.returns, "symmetric": orbit.symmetric, "seeds": orbit.seeds,
            **dict(zip(("q1", "q2", "p1", "p2"), map(float, orbit.start), strict=True)),
            "closure": orbit.closure,
            "grid_verdict": check.verdict if check is not None else "not refined",
            "grid_period_gap": check.period_gap if check is not None else float("nan"),
            "grid_start_gap": check.start_gap if check is not None else float("nan"),
            "grid_index_gap": check.index_gap if check is not None else float("nan"),
            "grid_index_off": bool(check is not None and check.index_off),
            "grid_landed": check.landed if check is not None else "",
            "grid_error": check.estimate if check is not None else float("nan"),
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
            "max_returns": searched.max_returns, "jitter": getattr(searched, "jitter", None),
            "seeds_by_way": [{"where": where, "seeds": n, "accessible": a}
                             for where, n, a in getattr(searched, "parts", ())],
            "stability_tol": search.orbits[0].tol if search.orbits else None,
            "verdicts": [row["verdict"] for row in rows],
            "grid_verdicts": [row["grid_verdict"] for row in rows]}
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
        place_labels(table, [(",".join(numbers), point) for point, numbers in labels.values()])
        figures.save(fig, path, fmt)


# where a label goes from its point, in points, tried in turn: beside it, then further out on a
# leader line (the first place whose box meets no label placed before and no other point)
_OFFSETS = [(3, 3), (3, -9), (-3, 3), (-3, -9)] + [
    (round(r * np.cos(a)), round(r * np.sin(a))) for r in (14, 24, 36)
    for a in np.linspace(0, 2 * np.pi, 12, endpoint=False)]


def place_labels(axes, labels) -> list:
    """Each ``(text, (x, y))`` of ``labels`` annotated beside its point where its box stays in
    the axes and meets no label placed before it and no point's marker; further out with a
    leader line where the near places are taken (the search's points of nearly equal period
    and index: "6,7" was printed over "8,9"). Returns the annotations."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Text
    from matplotlib.transforms import Bbox

    figure = axes.figure
    if not hasattr(figure.canvas, "get_renderer"):
        FigureCanvasAgg(figure)
    figure.draw_without_rendering()  # the layout first: the points where they will be drawn
    renderer = figure.canvas.get_renderer()
    reach = 5 * figure.dpi / 72  # a marker's reach, in pixels (5 points)
    markers = [Bbox.from_extents(x - reach, y - reach, x + reach, y + reach)
               for x, y in (axes.transData.transform(point) for _, point in labels)]
    inside = axes.get_window_extent(renderer)
    taken, placed = [], []
    for j, (text, point) in enumerate(labels):
        others = markers[:j] + markers[j + 1:]
        for dx, dy in _OFFSETS + [_OFFSETS[0]]:  # nowhere free: beside it after all
            far = abs(dx) > 3
            note = axes.annotate(text, point, fontsize="x-small", xytext=(dx, dy),
                                 textcoords="offset points",
                                 ha="left" if dx >= 0 else "right",
                                 arrowprops={"arrowstyle": "-", "lw": 0.5, "color": "0.4",
                                             "shrinkA": 0, "shrinkB": 2} if far else None)
            note.set_in_layout(False)  # the layout stays the one the places were chosen in
            note.update_positions(renderer)  # the text where it will be drawn
            box = Text.get_window_extent(note, renderer).expanded(1.1, 1.2)
            within = inside.containsx(box.x0) and inside.containsx(box.x1) and \
                inside.containsy(box.y0) and inside.containsy(box.y1)
            if within and not any(box.overlaps(other) for other in taken + others):
                break
            note.remove()
        else:
            axes.add_artist(note)
        taken.append(box)
        placed.append(note)
    return placed
