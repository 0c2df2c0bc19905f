"""Regenerate the work-precision reports the README shows, into docs/work_precision/SCENE/.

Each scene runs every method that applies (``ddvp compare`` with its defaults) on its default
horizon, Kepler at e = 0.6 and FPU at omega = 50. A scene takes from seconds (harmonic) to about
three minutes (paper_pendulum, to t = 10000). Run it with nothing else busy on the machine:
the run times are what is compared.

    python scripts/work_precision.py [--scenes paper_pendulum,harmonic] [--out docs/work_precision]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from ddvp_nlp import load_scene
from ddvp_nlp.io.work_precision import work_precision
from ddvp_nlp.studies.compare import ERROR_KINDS, cheapest

SCENES = {
    "paper_pendulum": {},
    "harmonic": {},
    "pendulum": {},
    "kepler": {"e": 0.6},
    "henon_heiles": {},
    "fpu": {"omega": 50.0},
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default=",".join(SCENES))
    parser.add_argument("--out", default="docs/work_precision")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    for name in args.scenes.split(","):
        started = time.perf_counter()
        folder = Path(args.out) / name
        rows = work_precision(load_scene(name), overrides=SCENES[name], out=folder,
                              repeats=args.repeats, progress=True)
        failed = sum(r["status"] != "success" for r in rows)
        print(f"{name}: {len(rows)} runs ({failed} did not reach t_end) in "
              f"{time.perf_counter() - started:.0f} s -> {folder}/summary.md")
        for kind, label in ERROR_KINDS.items():
            winners = []
            for level in (1e-2, 1e-4, 1e-6, 1e-8):
                ranking = cheapest(rows, kind, level)
                if ranking:
                    winners.append(f"{level:.0e}: {ranking[0][0]}")
            print(f"  {label.split(' max')[0]}: " + ", ".join(winners))


if __name__ == "__main__":
    main()
