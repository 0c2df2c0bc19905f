"""Redraw the documentation's comparison figures from the data they were drawn from, with the
package's current figure code and house style (``ddvp_nlp/io/figures.py``).

A comparison takes minutes to hours to run (the long horizons); its rows are kept beside its
figure (``work_precision.csv``), so a change of the figure code needs only this: each
``docs/work_precision/SCENE/work_precision.png`` and each ``horizons.png`` (a panel per horizon)
redrawn from the CSVs next to them, nothing re-run. Figures whose data are not
kept (``growth.png`` of the horizons, the stress map) are left as they are and listed.

    python scripts/pages/redraw_figures.py [--root docs/work_precision]

Seconds; no timing is shown.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from ddvp_nlp.io import plot_horizons, plot_work_precision
from ddvp_nlp.studies import read_rows

ROOT = Path(__file__).resolve().parents[2]

TITLE = "{scene}: error against run time"


def redraw_comparisons(root: Path) -> list[Path]:
    """Every ``work_precision.png`` below ``root`` with a ``work_precision.csv`` beside it, but
    a long horizon's (its case's ``horizons.png`` shows it)."""
    drawn = []
    for table in sorted(root.rglob("work_precision.csv")):
        folder = table.parent
        if folder.name.startswith("horizon_"):
            continue
        scene = folder.name.split("_e0")[0]  # kepler_e0.6 -> kepler
        target = folder / "work_precision.png"
        plot_work_precision(read_rows(table), target, title=TITLE.format(scene=scene))
        drawn.append(target)
    return drawn


def redraw_horizons(root: Path) -> list[Path]:
    """Every ``horizons.png`` from its horizons' CSVs and the unit its ``horizons.md`` states."""
    drawn = []
    for summary in sorted(root.rglob("horizons.md")):
        folder = summary.parent
        match = re.search(r"in units of ([0-9.eE+-]+)", summary.read_text())
        unit = float(match.group(1)) if match else 1.0
        results = {}
        for table in sorted(folder.glob("horizon_*/work_precision.csv"),
                            key=lambda p: float(p.parent.name.split("_", 1)[1])):
            results[float(table.parent.name.split("_", 1)[1])] = read_rows(table)
        if not results:
            continue
        scene = folder.name.split("_e0")[0]
        target = folder / "horizons.png"
        plot_horizons(results, target, title=TITLE.format(scene=scene), unit=unit)
        drawn.append(target)
    return drawn


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", default=str(ROOT / "docs" / "work_precision"))
    root = Path(parser.parse_args().root)
    drawn = redraw_comparisons(root) + redraw_horizons(root)
    for path in drawn:
        print(f"redrawn {path}")
    kept = sorted(set(root.rglob("*.png")) - set(drawn))
    for path in kept:
        print(f"left as it was (its data are not kept): {path}")


if __name__ == "__main__":
    main()
