"""The periodic-orbit search's seeds on worker processes against in this process, side by side
in one run: ``ddvp periodic hill --search --energy -2.14 --section q2=0`` with ``--workers 1``
and ``--workers 2`` (the whole command: start-up, the search, the refinement of every orbit on
the grid, the files), and ``find_periodic_orbits`` alone (``refine=False``: the seeds' returns
and shots only, the part the workers take) in this process after one warm-up.

CPU counts the command (or this process) and every child it waited for (the workers): wall
time falls only as far as a second core is free, and the CPU a worker costs (its start, the
blocks' messages) shows as CPU above the in-process run's. The runs alternate (1, 2, 2, 1,
...) so that a change of the machine's load falls on both. Each pair's orbit lists are
compared: the same periods and starts to the search's own tolerances.

    python scripts/benchmarks/bench_search_workers.py [--repeats 2] [--workers 2]
        [--skip-command] [--seeds 400]
"""

from __future__ import annotations

import argparse
import csv
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ddvp_nlp import find_periodic_orbits, load_scene
from ddvp_nlp.io import machine

# search.py's SAME (two orbits are one when their periods agree to it) and CLOSURE (an orbit's
# closure on the exact flow, relative to its size): its own tolerances, written again here (the
# scripts use the package's public names only)
SAME, CLOSURE = 1e-6, 1e-6
COMMAND = ["periodic", "hill", "--search", "--energy", "-2.14", "--section", "q2=0",
           "--no-plot"]


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def own_cpu() -> float:
    times = os.times()
    return times.user + times.system + times.children_user + times.children_system


def run_command(workers: int, folder: Path) -> tuple[float, float, list]:
    """(CPU with the workers, wall, the orbits' (period, start) rows) of one ``ddvp`` run."""
    out = folder / f"w{workers}-{time.monotonic_ns()}"
    c0, w0 = children_cpu(), time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "ddvp_nlp.cli", *COMMAND, "--workers",
                           str(workers), "--out", str(out)], capture_output=True, text=True)
    wall, cpu = time.perf_counter() - w0, children_cpu() - c0
    if done.returncode not in (0, 1):
        raise SystemExit(f"ddvp exited {done.returncode}: {done.stderr[-2000:]}")
    with open(out / "orbits.csv") as handle:
        rows = [(float(row["period"]), [float(row[n]) for n in ("q1", "q2", "p1", "p2")])
                for row in csv.DictReader(handle)]
    return cpu, wall, rows


def run_library(workers: int, seeds: int) -> tuple[float, float, list]:
    scene = load_scene("hill")
    c0, w0 = own_cpu(), time.perf_counter()
    search = find_periodic_orbits(scene.system, energy=-2.14, section="q2=0", seeds=seeds,
                                  refine=False, workers=workers)
    wall, cpu = time.perf_counter() - w0, own_cpu() - c0
    return cpu, wall, [(o.period, list(o.start)) for o in search.orbits]


def same(a: list, b: list) -> str:
    """Whether two orbit lists agree to the search's tolerances (periods to SAME, starts to
    the closure allowed of an orbit of its size)."""
    if len(a) != len(b):
        return f"NO: {len(a)} against {len(b)} orbits"
    worst_t = max((abs(x[0] - y[0]) / x[0] for x, y in zip(a, b, strict=True)), default=0.0)
    worst_z = max((np.max(np.abs(np.subtract(x[1], y[1]))) / np.max(np.abs(x[1]))
                   for x, y in zip(a, b, strict=True)), default=0.0)
    ok = worst_t <= SAME and worst_z <= CLOSURE
    return (f"{'yes' if ok else 'NO'} ({len(a)} orbits; periods to {worst_t:.1e}, starts to "
            f"{worst_z:.1e} of their size)")


def table(name: str, runs: dict) -> None:
    print(f"\n{name}")
    print("| workers | best CPU s (with workers) | best wall s | CPU / wall | orbits |")
    print("|---|---|---|---|---|")
    for workers, rows in runs.items():
        cpu, wall = min(r[0] for r in rows), min(r[1] for r in rows)
        print(f"| {workers} | {cpu:.2f} | {wall:.2f} | {cpu / wall:.2f} | {len(rows[-1][2])} |")
    (one, many) = runs.values()
    print(f"wall ratio 1 / {list(runs)[1]} workers: "
          f"{min(r[1] for r in one) / min(r[1] for r in many):.2f}; CPU ratio "
          f"{min(r[0] for r in many) / min(r[0] for r in one):.2f}; same orbits: "
          f"{same(one[-1][2], many[-1][2])}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seeds", type=int, default=400)
    parser.add_argument("--skip-command", action="store_true")
    args = parser.parse_args()
    order = [1, args.workers]
    library = {w: [] for w in order}
    run_library(1, 16)  # warm-up: the flows built (or loaded) and compiled
    for r in range(args.repeats):
        for workers in order if r % 2 == 0 else order[::-1]:
            library[workers].append(run_library(workers, args.seeds))
            print(f"  library, {workers} worker(s): CPU {library[workers][-1][0]:.2f} s, wall "
                  f"{library[workers][-1][1]:.2f} s, load {os.getloadavg()[0]:.2f}", flush=True)
    table(f"find_periodic_orbits(hill, energy=-2.14, section='q2=0', seeds={args.seeds}, "
          "refine=False): the search alone", library)
    if not args.skip_command:
        command = {w: [] for w in order}
        with tempfile.TemporaryDirectory() as folder:
            for r in range(args.repeats):
                for workers in order if r % 2 == 0 else order[::-1]:
                    command[workers].append(run_command(workers, Path(folder)))
                    print(f"  ddvp, {workers} worker(s): CPU {command[workers][-1][0]:.2f} s, "
                          f"wall {command[workers][-1][1]:.2f} s, load "
                          f"{os.getloadavg()[0]:.2f}", flush=True)
        table("ddvp " + " ".join(COMMAND) + " --workers N: the whole command", command)
    print(f"\nmachine: {machine()}")


if __name__ == "__main__":
    main()
