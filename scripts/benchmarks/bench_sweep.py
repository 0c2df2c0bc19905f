"""Stress grid on 1 and on 2 local Dask workers, timed side by side in one run.

Both runs take the same path: a LocalCluster of N single-threaded worker processes, started
inside the timing (its start-up counts), and the grid sent to its scheduler. They must give the
same rows (timing columns aside). The compiled chunks are built once before the timings, so
neither run pays the C compiler.

    python scripts/bench_sweep.py [--quick]
"""

from __future__ import annotations

import argparse
import platform
import tempfile
import time
import warnings

import dask
from distributed import LocalCluster

from ddvp_nlp.runner.tasks import Workers
from ddvp_nlp.studies.stress_report import stress


def _equal(x, y) -> bool:
    return x == y or (isinstance(x, float) and isinstance(y, float) and x != x and y != y)


def _same(a: dict, b: dict) -> bool:
    """Equal rows, the timing column aside (NaN equals NaN)."""
    return a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a if k != "seconds")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the quick grid (seconds)")
    args = parser.parse_args()
    warnings.simplefilter("ignore", RuntimeWarning)
    with tempfile.TemporaryDirectory() as scratch:
        started = time.perf_counter()
        stress(f"{scratch}/warm", quick=args.quick)  # fills the compiled cache
        print(f"warm-up in this process (compiles the chunks once): "
              f"{time.perf_counter() - started:.1f} s")
        timings, results = {}, {}
        for workers in (1, 2):
            started = time.perf_counter()
            with dask.config.set({"distributed.scheduler.worker-saturation": 1.0}):
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1,
                                       processes=True, dashboard_address=None)
            try:
                results[workers] = stress(
                    f"{scratch}/w{workers}", quick=args.quick,
                    workers=Workers(scheduler=cluster.scheduler_address))
            finally:
                cluster.close()
            timings[workers] = time.perf_counter() - started
    same = [_same(a, b) for a, b in zip(results[1], results[2], strict=True)]
    print("| workers | tasks | wall-clock s |\n|---|---|---|")
    for workers in (1, 2):
        print(f"| {workers} | {len(results[workers])} | {timings[workers]:.1f} |")
    print(f"speed-up with 2 workers: {timings[1] / timings[2]:.2f} (target: at least 1.7)")
    print(f"same rows (timing aside): {sum(same)} of {len(same)}")
    for a, b, equal in zip(results[1], results[2], same, strict=True):
        if not equal:
            print(f"  differs: {a['key']}: " + ", ".join(
                f"{k} {a[k]!r} / {b[k]!r}" for k in a if k != "seconds" and not _equal(a[k], b[k])))
    print(f"machine: {platform.machine()}, {platform.python_version()}")


if __name__ == "__main__":
    main()
