"""Ensemble speed: M Henon-Heiles orbits (E = 1/8, starts on x = 0) by a loop of march() calls
and by march_ensemble on one and on two worker processes, side by side in one run. CPU time
counts this process and its worker processes; each row is the best of the repeats, after one
short warm-up march that loads the compiled chunk.

    python scripts/benchmarks/bench_ensemble.py [--orbits 20] [--t-end 500] [--repeats 3]

The issue's size is 100 orbits of 1e5 steps (``--orbits 100 --t-end 4800``, about 8.6e6
steps on this scene at tau0 = 0.05); ``--scale-to 100x1e5`` prints the time of that size
extrapolated from the measured rate per step, said to be extrapolated.
"""

from __future__ import annotations

import argparse
import ctypes
import pickle
import tempfile
import time

import numpy as np

# the script's own folder is on the path when it runs: the one timer of the benchmarks
from bench_march import C_KINDS, C_PREDICTORS, c_march_library, timed  # noqa: E402

from ddvp_nlp import Compilation, load_scene, march, march_ensemble
from ddvp_nlp.io import machine
from ddvp_nlp.studies import section_starts


def rows(args, system, q0s, p0s, cache):
    def loop():
        return [
            march(
                system, q, p, (0.0, args.t_end), tau0=0.05, compilation=Compilation(cache_dir=cache)
            )
            for q, p in zip(q0s, p0s, strict=True)
        ]

    def ensemble(workers):
        return lambda: march_ensemble(
            system,
            q0s,
            p0s,
            (0.0, args.t_end),
            tau0=0.05,
            workers=workers,
            compilation=Compilation(cache_dir=cache),
        )

    def unchecked():
        return march_ensemble(system, q0s, p0s, (0.0, args.t_end), tau0=0.05, workers=1,
                              accuracy=None, compilation=Compilation(cache_dir=cache))

    march(
        system, q0s[0], p0s[0], (0.0, 1.0), tau0=0.05, compilation=Compilation(cache_dir=cache)
    )  # compile / load
    found = [("loop of march()", *timed(args.repeats, loop, warm_up=False))]
    for workers in args.workers:
        found.append((f"march_ensemble(workers={workers})",
                      *timed(args.repeats, ensemble(workers), warm_up=False)))
    found.append(("march_ensemble(workers=1, accuracy=None)",
                  *timed(args.repeats, unchecked, warm_up=False)))
    return found


def c_loop(args, q0s, p0s, folder):
    """The same orbits marched one after another by the hand-written C march of the same
    scheme (``c_march.c``, its fastest predictor), no checks: CPU, wall and steps."""
    lib = c_march_library(folder)
    capacity = int(args.t_end / 0.05 * 4) + 16
    t, z, H = np.empty(capacity + 1), np.empty((capacity + 1, 4)), np.empty(capacity + 1)
    theta = np.zeros(4)
    best = None
    for predictor in C_PREDICTORS:
        count = ctypes.c_long(0)

        def run(predictor=predictor, count=count):
            steps = 0
            for q, p in zip(q0s, p0s, strict=True):
                steps += lib.c_march_fast(C_KINDS["henon_heiles"], 2, theta,
                                          np.concatenate([q, p]), 0.0, 0.05, args.t_end,
                                          capacity, 1e-10, predictor, t, z, H,
                                          ctypes.byref(count))
            return steps
        cpu, wall, steps = timed(args.repeats, run)
        if best is None or cpu < best[0]:
            best = (cpu, wall, steps, C_PREDICTORS[predictor])
    return best


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--orbits", type=int, default=20)
    parser.add_argument("--t-end", type=float, default=500.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--scale-to", default=None, metavar="MxSTEPS",
                        help="also print the times extrapolated to M orbits of STEPS steps")
    args = parser.parse_args()
    print(f"machine: {machine()}")
    system = load_scene("henon_heiles").system
    theta = system.parameter_vector(None)
    starts = section_starts(system, theta, 1 / 8, "q1=0", args.orbits)
    q0s, p0s = starts[:, :2], starts[:, 2:]
    with tempfile.TemporaryDirectory() as cache:
        found = rows(args, system, q0s, p0s, cache)
        c_cpu, c_wall, c_steps, c_predictor = c_loop(args, q0s, p0s, cache)
    loop = found[0]
    steps = sum(s.steps for s in loop[3])
    print(f"\n## Henon-Heiles, E = 1/8, {args.orbits} orbits to t = {args.t_end:g} "
          f"({steps} steps in all, {steps / args.orbits:.0f} per orbit)\n")
    print("| method | CPU s | wall s | CPU us / step | wall us / step | CPU ratio to loop "
          "| wall ratio to loop |")
    print("|---|---|---|---|---|---|---|")
    for label, cpu, wall, _ in found:
        print(f"| {label} | {cpu:.3f} | {wall:.3f} | {cpu / steps * 1e6:.3f} | "
              f"{wall / steps * 1e6:.3f} | {cpu / loop[1]:.2f} | {wall / loop[2]:.2f} |")
    print(f"| C march of the same scheme, one orbit after another (c_march.c, "
          f"{c_predictor} predictor; {c_steps} steps) | {c_cpu:.3f} | {c_wall:.3f} | "
          f"{c_cpu / c_steps * 1e6:.3f} | {c_wall / c_steps * 1e6:.3f} | "
          f"{c_cpu / loop[1]:.2f} | {c_wall / loop[2]:.2f} |")
    checked = next(row for row in found if row[0] == "march_ensemble(workers=1)")
    print(f"\n- march_ensemble(workers=1) with the accuracy check against the sequential C "
          f"march: CPU ratio {checked[1] / c_cpu:.2f}, wall {checked[2] / c_wall:.2f} (issue "
          f"37's and 49's target <= 1.5); without the check {found[-1][1] / c_cpu:.2f}")
    for label, cpu, wall, _ in found[1:]:
        if "workers=1" not in label:
            print(f"- {label} against the sequential C march: CPU ratio {cpu / c_cpu:.2f}, "
                  f"wall {wall / c_wall:.2f}")
    for label, _, _, solutions in found[1:]:
        if "accuracy=None" in label:
            continue
        same = all(np.array_equal(a.t, b.t) and np.array_equal(a.q, b.q)
                   and np.array_equal(a.p, b.p) and a.status is b.status
                   for a, b in zip(loop[3], solutions, strict=True))
        print(f"\n- {label}: nodes equal to the loop's, orbit by orbit: {same}")
    solution = loop[3][0]  # what a worker sends back per orbit: the pickled Solution
    started = time.process_time()
    for _ in range(5):
        blob = pickle.dumps(solution, protocol=pickle.HIGHEST_PROTOCOL)
        pickle.loads(blob)
    transfer = (time.process_time() - started) / 5
    print(f"\n- result transfer from a worker, orbit 0 ({solution.steps} steps): "
          f"{len(blob) / 1e6:.1f} MB pickled, pickle + unpickle {transfer * 1e3:.1f} ms CPU "
          f"({transfer / solution.steps * 1e6:.3f} us per step; the pipe not counted)")
    if args.scale_to:
        count, size = args.scale_to.lower().split("x")
        total = int(count) * float(size)
        print(f"\n- EXTRAPOLATED (not measured) to {count} orbits x {float(size):.0e} steps "
              f"= {total:.2e} steps, at the rates measured above:")
        for label, cpu, wall, _ in found:
            print(f"  - {label}: CPU {cpu / steps * total:.1f} s, wall "
                  f"{wall / steps * total:.1f} s")
    print(f"\nmachine: {machine()}")


if __name__ == "__main__":
    main()
