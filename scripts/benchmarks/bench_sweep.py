"""Stress grid on 1 and on 2 local Dask workers, timed side by side in one run.

Both runs take the same path: a LocalCluster of N single-threaded worker processes, started
inside the timing (its start-up counts), and the grid sent to its scheduler by ``ddvp stress
--scheduler``. They must give the same rows (the timing column and the row checksum, which
covers it, aside). The compiled chunks are built once before the timings, so neither run pays
the C compiler.

    python scripts/benchmarks/bench_sweep.py [--quick]

About five minutes on two cores (``--quick``: the short grid, seconds).
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings

import dask
from distributed import LocalCluster

from ddvp_nlp.cli import main as ddvp
from ddvp_nlp.io import machine
from ddvp_nlp.runner import read_csv

# columns that differ between two runs of the same grid: its run time, and the checksum over it
TIMING = ("seconds", "row_sha256")


def stress(out: str, quick: bool, *where: str) -> list[dict]:
    """The rows of ``ddvp stress`` into ``out``, sent ``where`` (its options)."""
    code = ddvp(["stress", "--out", out, "--no-progress", *(["--quick"] if quick else []),
                 *where])
    if code != 0:
        raise SystemExit(f"ddvp stress exited {code}")
    return read_csv(f"{out}/stress.csv", missing_ok=False)


def differences(a: dict, b: dict) -> list[str]:
    """What differs between two rows, the timing aside."""
    return [f"{k} {a.get(k)!r} / {b.get(k)!r}" for k in a.keys() | b.keys()
            if k not in TIMING and a.get(k) != b.get(k)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the quick grid (seconds)")
    args = parser.parse_args()
    warnings.simplefilter("ignore", RuntimeWarning)
    with tempfile.TemporaryDirectory() as scratch:
        started = time.perf_counter()
        stress(f"{scratch}/warm", args.quick, "--workers", "1")  # fills the compiled cache
        print(f"warm-up in this process (compiles the chunks once): "
              f"{time.perf_counter() - started:.1f} s")
        timings, results = {}, {}
        for workers in (1, 2):
            started = time.perf_counter()
            with dask.config.set({"distributed.scheduler.worker-saturation": 1.0}):
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1,
                                       processes=True, dashboard_address=None)
            try:
                results[workers] = stress(f"{scratch}/w{workers}", args.quick,
                                          "--scheduler", cluster.scheduler_address)
            finally:
                cluster.close()
            timings[workers] = time.perf_counter() - started
    first = {row["key"]: row for row in results[1]}
    second = {row["key"]: row for row in results[2]}
    print("| workers | tasks | wall-clock s |\n|---|---|---|")
    for workers in (1, 2):
        print(f"| {workers} | {len(results[workers])} | {timings[workers]:.1f} |")
    print(f"speed-up with 2 workers: {timings[1] / timings[2]:.2f} (target: at least 1.7)")
    same = [key for key in first if key in second and not differences(first[key], second[key])]
    print(f"same rows (timing aside): {len(same)} of {len(first | second)}")
    for key in sorted(first.keys() | second.keys()):
        if key not in same:
            print(f"  differs: {key}: " + ", ".join(differences(first.get(key, {}),
                                                                 second.get(key, {}))))
    print(f"machine: {machine()}")


if __name__ == "__main__":
    main()
