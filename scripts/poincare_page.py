"""Regenerate docs/poincare/README.md: Henon-Heiles sections at E = 1/12, 1/8 and 1/6.

Each energy: 20 orbits from seeded starts on q1 = 0 (the section's momentum from H = E), marched
together (``march_ensemble``, vddvp) to t = 1000, crossings with q1 increasing located on the
cubic Hermite interpolant of their interval. A few minutes on two cores.

    python scripts/poincare_page.py [--out docs/poincare]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from ddvp_nlp.cli import main as ddvp

ENERGIES = {"1/12": 1 / 12, "1/8": 1 / 8, "1/6": 1 / 6}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="docs/poincare")
    parser.add_argument("--orbits", type=int, default=20)
    parser.add_argument("--t-end", type=float, default=1000.0)
    args = parser.parse_args()
    out = Path(args.out)
    lines = ["# Poincare sections of Henon-Heiles", "",
             f"`python scripts/poincare_page.py` ({args.orbits} orbits per energy, vddvp, "
             f"t_end = {args.t_end:g}, section q1 = 0 crossed upwards; seeded starts). Each "
             "orbit keeps its own discrete energy level; the table gives the largest nodal energy "
             "error `|H(z_k) - E|` over all orbits.", "",
             "| E | crossings | failed orbits | largest nodal energy error | seconds |",
             "|---|---|---|---|---|"]
    for label, energy in ENERGIES.items():
        folder = out / f"E_{label.replace('/', '_')}"
        started = time.perf_counter()
        code = ddvp(["poincare", "henon_heiles", "--energy", repr(energy), "--orbits",
                     str(args.orbits), "--t-end", repr(args.t_end), "--out", str(folder)])
        seconds = time.perf_counter() - started
        section = np.load(folder / "section.npz")
        orbits = (folder / "orbits.csv").read_text().splitlines()[1:]
        failed = sum(",reached t_end," not in row for row in orbits)
        error = float(np.max(section["energy_errors"]))
        crossings = section["points"].shape[0]
        lines.append(f"| {label} | {crossings} | {failed} | {error:.2e} | {seconds:.0f} |")
        print(f"E = {label}: exit {code}, {crossings} crossings, {failed} failed, {seconds:.0f} s")
    lines += [""] + [f"![E = {label}](E_{label.replace('/', '_')}/section.png)"
                     for label in ENERGIES] + [""]
    (out / "README.md").write_text("\n".join(lines))


if __name__ == "__main__":
    main()
