"""Ensemble speed: M Henon-Heiles orbits by march_ensemble against a loop of march() calls, side by
side in one run (CPU and wall time, best of the repeats after a warm-up).

    python scripts/bench_ensemble.py [--orbits 20] [--t-end 500] [--repeats 3]
"""

from __future__ import annotations

import argparse
import tempfile

import numpy as np

# scripts/ is on the path when a script runs: the one timer of the benchmarks
from bench_march import timed  # noqa: E402

from ddvp_nlp import load_scene, march
from ddvp_nlp.solvers.ensemble import march_ensemble
from ddvp_nlp.studies.poincare import section_starts


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--orbits", type=int, default=20)
    parser.add_argument("--t-end", type=float, default=500.0)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    system = load_scene("henon_heiles").system
    theta = system.parameter_vector(None)
    starts = section_starts(system, theta, 1 / 8, "q1=0", args.orbits)
    q0s, p0s = starts[:, :2], starts[:, 2:]
    with tempfile.TemporaryDirectory() as cache:
        def ensemble():
            return march_ensemble(system, q0s, p0s, tau0=0.05, t_end=args.t_end,
                                  cache_dir=cache)

        def loop():
            return [march(system, q, p, tau0=0.05, t_end=args.t_end, cache_dir=cache)
                    for q, p in zip(q0s, p0s, strict=True)]

        rows = [("loop of march()", *timed(args.repeats, loop)),
                ("march_ensemble()", *timed(args.repeats, ensemble))]
    steps = sum(s.steps for s in rows[0][3])
    same = all(np.array_equal(a.t, b.t) for a, b in zip(rows[0][3], rows[1][3], strict=True))
    print(f"\n## Henon-Heiles, E = 1/8, {args.orbits} orbits to t = {args.t_end:g} "
          f"({steps} steps in all)\n")
    print("| method | CPU s | wall s | orbits / CPU s | CPU us / step | CPU ratio to loop |")
    print("|---|---|---|---|---|---|")
    for label, cpu, wall, _ in rows:
        print(f"| {label} | {cpu:.3f} | {wall:.3f} | {args.orbits / cpu:.1f} | "
              f"{cpu / steps * 1e6:.3f} | {cpu / rows[0][1]:.2f} |")
    print(f"\n- the ensemble's nodes equal the loop's, orbit by orbit: {same}")


if __name__ == "__main__":
    main()
