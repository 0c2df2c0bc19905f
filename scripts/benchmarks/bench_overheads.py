"""What the commands spend beyond their own computation, measured side by side in one run: each
figure a whole process (user + system CPU from ``wait4``, its children included; wall beside),
the best of ``--repeats`` runs, the load average printed at the start and the end.

1. Start-up: ``python -c "import numpy, casadi"`` against ``python -c "import ddvp_nlp"``
   (target: at most 0.15 s CPU more) and a warm ``ddvp march harmonic --no-plot``.
2. ``ddvp poincare henon_heiles --energy 0.125 --orbits 20 --t-end 5000 --no-plot`` (about 9e4
   nodes an orbit, the issue's scale) against a process that only marches the same ensemble
   (the same starts, steps and two workers): target 1.3x. The same with the figure, for
   information.
3. ``ddvp compare kepler``: the whole command against the timed calls it made (``run_s`` x
   ``repeats`` of every row: a lower bound of the timed total, so the overhead printed is an
   upper bound); target: overhead at most the timed total. Warm (the compiled code cached by a
   first run, not counted).

    python scripts/benchmarks/bench_overheads.py [--repeats 3] [--only import,poincare,compare]
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_ipopt import child  # noqa: E402

from ddvp_nlp.io import machine  # noqa: E402

PYTHON = sys.executable
POINCARE = ["henon_heiles", "--energy", "0.125", "--orbits", "20", "--t-end", "5000"]
ENSEMBLE_ONLY = """
from ddvp_nlp import load_scene
from ddvp_nlp.solvers import march_ensemble
from ddvp_nlp.studies import section_starts
scene = load_scene("henon_heiles")
theta = scene.system.parameter_vector(None)
starts = section_starts(scene.system, theta, 0.125, "q1=0", 20)
march_ensemble(scene.system, starts[:, :2], starts[:, 2:], t_span=(0.0, 5000.0),
               tau0=scene.resolve({}).tau0, workers=2)
"""


def best(command, repeats: int) -> dict:
    """The run of least CPU among ``repeats`` (one warm-up before, not counted)."""
    child(command)
    runs = [child(command) for _ in range(repeats)]
    for run in runs:
        if run["code"] not in (0, 1):
            raise RuntimeError(f"{' '.join(command)}: exit {run['code']}\n{run['out'][-2000:]}")
    return min(runs, key=lambda r: r["cpu"])


def line(label: str, run: dict) -> None:
    print(f"| {label} | {run['cpu']:.3f} ({run['user']:.3f} + {run['system']:.3f}) | "
          f"{run['wall']:.3f} | {run['mb']:.0f} |", flush=True)


def header() -> None:
    print("| process | CPU s (user + sys) | wall s | peak MB |")
    print("|---|---|---|---|")


def start_up(repeats: int, folder: str) -> None:
    print("\n## Start-up\n")
    header()
    base = best([PYTHON, "-c", "import numpy, casadi"], repeats)
    package = best([PYTHON, "-c", "import ddvp_nlp"], repeats)
    marched = best([PYTHON, "-m", "ddvp_nlp.cli", "march", "harmonic", "--no-plot", "--out",
                    f"{folder}/march"], repeats)
    line("import numpy, casadi", base)
    line("import ddvp_nlp", package)
    line("ddvp march harmonic --no-plot (warm)", marched)
    print(f"\nimport ddvp_nlp beyond numpy and casadi: {package['cpu'] - base['cpu']:.3f} s CPU, "
          f"{package['wall'] - base['wall']:.3f} s wall (target <= 0.15 s CPU); "
          f"{(package['cpu'] - base['cpu']) / marched['cpu']:.0%} of the warm march's CPU")


def poincare(repeats: int, folder: str) -> None:
    print("\n## Poincare section\n")
    header()
    alone = best([PYTHON, "-c", ENSEMBLE_ONLY], repeats)
    command = best([PYTHON, "-m", "ddvp_nlp.cli", "poincare", *POINCARE, "--no-plot", "--out",
                    f"{folder}/poincare"], repeats)
    drawn = best([PYTHON, "-m", "ddvp_nlp.cli", "poincare", *POINCARE, "--out",
                  f"{folder}/poincare-drawn"], repeats)
    line("the ensemble alone (march_ensemble, 2 workers)", alone)
    line("ddvp poincare --no-plot", command)
    line("ddvp poincare (with the figure)", drawn)
    print(f"\nddvp poincare / the ensemble alone: {command['cpu'] / alone['cpu']:.2f} CPU, "
          f"{command['wall'] / alone['wall']:.2f} wall (target <= 1.3); with the figure "
          f"{drawn['cpu'] / alone['cpu']:.2f} CPU, {drawn['wall'] / alone['wall']:.2f} wall")


def compare(repeats: int, folder: str) -> None:
    print("\n## ddvp compare kepler\n")
    header()
    out = f"{folder}/compare"
    run = best([PYTHON, "-m", "ddvp_nlp.cli", "compare", "kepler", "--no-progress", "--out",
                out], repeats)
    line("ddvp compare kepler (warm)", run)
    with open(Path(out) / "work_precision.csv") as handle:
        rows = [r for r in csv.DictReader(handle) if r["run_s"] not in ("", "nan")]
    best_sum = sum(float(r["run_s"]) for r in rows)
    timed = sum(float(r["run_s"]) * int(r["repeats"]) for r in rows)
    overhead = run["cpu"] - timed
    print(f"\n{len(rows)} timed runs: best calls add up to {best_sum:.3f} s, the timed calls to "
          f"at least {timed:.3f} s (wall, as the command times them); the rest of the command "
          f"(warm-ups, references, errors, accuracy checks, start-up, files) at most "
          f"{overhead:.3f} s by the process's CPU ({overhead / timed:.2f}x the timed total), "
          f"{run['wall'] - timed:.3f} s by its wall time ({(run['wall'] - timed) / timed:.2f}x); "
          f"target <= 1x. On a loaded machine the timed calls' wall time includes waiting, so "
          f"the CPU figure understates the overhead and the wall figure overstates it.")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", default="import,poincare,compare")
    args = parser.parse_args()
    print(f"load average at the start: {os.getloadavg()}", flush=True)
    parts = {"import": start_up, "poincare": poincare, "compare": compare}
    with tempfile.TemporaryDirectory() as folder:
        for name in args.only.split(","):
            parts[name](args.repeats, folder)
    print(f"\nload average at the end: {os.getloadavg()}")
    print(f"machine: {machine()}")


if __name__ == "__main__":
    main()
