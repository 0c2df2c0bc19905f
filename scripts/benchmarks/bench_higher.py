"""Fixed-endpoint spline (and Pais-Uhlenbeck) at growing node counts: the window assembly's
Newton, build and solve, wall and CPU time, iterations, error against the exact cubic.

Usage: python scripts/benchmarks/bench_higher.py [--scheme fixed|vddvp] [--scene spline] N [N ...]
Each N runs in this process after one warm-up at N = 101 (CasADi functions are cached per
system); peak memory is the process's maximum resident size so far.
"""

import argparse
import os
import resource
import time

import numpy as np

from ddvp_nlp import GridOptions, load_scene, solve_bvp_higher
from ddvp_nlp.io import machine


def run(scene, config, nodes, scheme, solver):
    t_a, q_a, t_b, q_b = scene.ends(config, nodes, scene.boundary.t_span)
    wall, cpu = time.perf_counter(), time.process_time()
    solution = solve_bvp_higher(scene.system, t_a, q_a, t_b, q_b, nodes=nodes, scheme=scheme,
                                params=config.params, options=GridOptions(solver=solver))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    error = float(np.max(np.abs(solution.q - scene.exact_motion(solution.t, config.params))))
    return solution, wall, cpu, error


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("nodes", type=int, nargs="+")
    parser.add_argument("--scene", default="spline")
    parser.add_argument("--scheme", default="fixed")
    parser.add_argument("--solver", default="newton")
    args = parser.parse_args()
    scene = load_scene(args.scene)
    config = scene.resolve()
    run(scene, config, 101, args.scheme, args.solver)  # warm-up: builds the window functions
    print(f"load average {os.getloadavg()[0]:.2f}; scene {args.scene}, {args.scheme}, "
          f"solver {args.solver}")
    print("| N | status | iterations | build s | solve s | wall s | CPU s | error vs exact | "
          "peak RSS MB |")
    print("|---|---|---|---|---|---|---|---|---|")
    for nodes in args.nodes:
        solution, wall, cpu, error = run(scene, config, nodes, args.scheme, args.solver)
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"| {nodes} | {solution.status.code} | {solution.stats['iterations_total']} | "
              f"{solution.timing['build_s']:.3f} | {solution.timing['solve_s']:.3f} | "
              f"{wall:.3f} | {cpu:.3f} | {error:.2e} | {peak:.0f} |", flush=True)
    print(f"\nmachine: {machine()}")


if __name__ == "__main__":
    main()
