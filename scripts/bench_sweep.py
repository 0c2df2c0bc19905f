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

from ddvp_nlp.stress import stress


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the quick grid (seconds)")
    args = parser.parse_args()
    warnings.simplefilter("ignore", RuntimeWarning)
    with tempfile.TemporaryDirectory() as scratch:
        started = time.perf_counter()
        stress(f"{scratch}/warm", quick=args.quick, workers=1)  # fills the compiled cache
        print(f"warm-up in this process (compiles the chunks once): "
              f"{time.perf_counter() - started:.1f} s")
        timings, results = {}, {}
        for workers in (1, 2):
            started = time.perf_counter()
            with dask.config.set({"distributed.scheduler.worker-saturation": 1.0}):
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1,
                                       processes=True, dashboard_address=None)
            try:
                results[workers] = stress(f"{scratch}/w{workers}", quick=args.quick,
                                          scheduler=cluster.scheduler_address)
            finally:
                cluster.close()
            timings[workers] = time.perf_counter() - started
    same = all({k: v for k, v in a.items() if k != "seconds"}
               == {k: v for k, v in b.items() if k != "seconds"}
               for a, b in zip(results[1], results[2], strict=True))
    print("| workers | tasks | wall-clock s |\n|---|---|---|")
    for workers in (1, 2):
        print(f"| {workers} | {len(results[workers])} | {timings[workers]:.1f} |")
    print(f"speed-up with 2 workers: {timings[1] / timings[2]:.2f} (target: at least 1.7)")
    print(f"same rows (timing aside): {same}")
    print(f"machine: {platform.machine()}, {platform.python_version()}")


if __name__ == "__main__":
    main()
