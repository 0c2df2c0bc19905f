"""Regenerate docs/poincare/README.md: Henon-Heiles sections at E = 1/12, 1/8 and 1/6.

Each energy: 20 orbits from seeded starts on q1 = 0 (the section's momentum from H = E), marched
as one ensemble (``march_ensemble``, vddvp, two worker processes) to t = 1000, crossings with q1
increasing located on the cubic Hermite interpolant of their interval; each orbit's nodal energy
error in a table of its own. A few minutes on two cores (``--quick``: 4 orbits to t = 100,
seconds; not for docs/). The seconds column stands beside the machine and the date
(``ddvp_nlp.io.machine``). Each section's folder is written to a scratch folder; only its figure
is copied into ``--out``.

    python scripts/pages/poincare_page.py [--out docs/poincare] [--quick]
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from ddvp_nlp.cli import main as ddvp
from ddvp_nlp.io import machine

ROOT = Path(__file__).resolve().parents[2]

ENERGIES = {"1/12": 1 / 12, "1/8": 1 / 8, "1/6": 1 / 6}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "docs" / "poincare"))
    parser.add_argument("--orbits", type=int, default=20)
    parser.add_argument("--t-end", type=float, default=1000.0)
    parser.add_argument("--quick", action="store_true", help="4 orbits to t = 100")
    args = parser.parse_args()
    if args.quick:
        args.orbits, args.t_end = 4, 100.0
    out = Path(args.out)
    lines = ["# Poincare sections of Henon-Heiles", "",
             f"`python scripts/pages/poincare_page.py` ({args.orbits} orbits per energy, vddvp, "
             f"t_end = {args.t_end:g}, section q1 = 0 crossed upwards; seeded starts). Each "
             "orbit keeps its own discrete energy level; the table gives the largest nodal energy "
             "error `|H(z_k) - E|` over all orbits. The chaotic orbits (most at E = 1/6, some "
             "at 1/8) amplify round-off exponentially: a change in the last bits of the steps "
             "(another Newton, another machine) changes their steps and crossings, not the "
             "picture nor the size of the energy errors.", "",
             "| E | crossings | failed orbits | largest nodal energy error | seconds |",
             "|---|---|---|---|---|"]
    per_orbit = []
    scratch = tempfile.TemporaryDirectory(prefix="poincare-page-")
    for label, energy in ENERGIES.items():
        name = f"E_{label.replace('/', '_')}"
        folder = Path(scratch.name) / name
        started = time.perf_counter()
        code = ddvp(["poincare", "henon_heiles", "--energy", repr(energy), "--orbits",
                     str(args.orbits), "--t-end", repr(args.t_end), "--out", str(folder)])
        seconds = time.perf_counter() - started
        section = np.load(folder / "section.npz")
        orbits = (folder / "orbits.csv").read_text().splitlines()
        failed = sum(",success," not in row for row in orbits[1:])
        error = float(np.max(section["energy_errors"]))
        crossings = section["points"].shape[0]
        lines.append(f"| {label} | {crossings} | {failed} | {error:.2e} | {seconds:.0f} |")
        per_orbit += orbit_table(label, section, orbits)
        (out / name).mkdir(parents=True, exist_ok=True)
        shutil.copyfile(folder / "section.png", out / name / "section.png")
        print(f"E = {label}: exit {code}, {crossings} crossings, {failed} failed, {seconds:.0f} s")
    lines += ["", f"Seconds measured on: {machine()}", ""]
    lines += [f"![E = {label}](E_{label.replace('/', '_')}/section.png)"
              for label in ENERGIES] + [""] + per_orbit
    scratch.cleanup()
    (out / "README.md").write_text("\n".join(lines))
    print(f"wrote {out / 'README.md'}")


def orbit_table(label, section, orbits) -> list[str]:
    """Each orbit of one energy: its start, status, steps, crossings, nodal energy error and the
    accuracy check's verdict (``orbits.csv``'s rows, read by their header)."""
    import csv

    lines = [f"## E = {label}, orbit by orbit", "",
             "| orbit | start (q2, p2) | status | steps | crossings | nodal energy error | "
             "verdict | t_drift |", "|---|---|---|---|---|---|---|---|"]
    for row in csv.DictReader(orbits):
        k = int(row["orbit"])
        crossings = int(np.sum(section["orbit"] == k))
        drift = f"{float(row['t_drift']):.4g}" if row.get("t_drift") else ""
        lines.append(f"| {k} | ({float(row['start_q2']):.4f}, {float(row['start_p2']):.4f}) | "
                     f"{row['status']} | {row['steps']} | {crossings} | "
                     f"{row['nodal_energy_error']} | {row.get('accuracy', '')} | {drift} |")
    return lines + [""]


if __name__ == "__main__":
    main()
