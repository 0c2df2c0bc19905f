"""Newton (SuperLU) against IPOPT on the periodic problem, side by side in one run.

    python scripts/benchmarks/bench_periodic.py [--repeats 3] [--only solvers,rotation]

Rotations (``--only rotation``): the pendulum's rotation at E = 2.5 (section q1 = 0, q1 an
angle) for N = 100, 200, 400, 800 from ``solve_periodic``'s default start (the predicted grid,
then continuation in N: ``solvers/periodic/refinement.py``), Newton and IPOPT, with the
iterations of every level; beside it IPOPT from the old start (the march on equally spaced
times, ``max_iter`` 400), which Newton could not solve at any N. Targets (issue 29): N = 800 in
at most 0.3 s with Newton or IPOPT, iteration counts flat in N.

Solvers (``--only solvers``):

Each case starts both solvers from the same nodes (the default start: the march from the
section's point to its return, resampled on N intervals), so the times are the solvers' and the
verification's (residuals recomputed, the accuracy check), not the start's. Times are the best
of ``--repeats`` calls after one warm-up call (which builds the CasADi functions and the IPOPT
problem, both cached), CPU time beside wall time; the ratio is IPOPT's over Newton's.
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_march import timed  # noqa: E402

from ddvp_nlp import GridOptions, load_scene  # noqa: E402
from ddvp_nlp.io import machine  # noqa: E402
from ddvp_nlp.solvers import parse_section, solve_periodic  # noqa: E402

# internals, named explicitly: the first guess's pieces, timed apart (not workbench names)
from ddvp_nlp.solvers.periodic.first_orbit import (  # noqa: E402
    march_to_return,
    resample,
    section_point,
)


def cases():
    eight = load_scene("figure_eight").periodic
    eight_options = {"energy": eight.energy, "section": eight.section, "start": eight.start,
                     "integrals": eight.integrals}
    return [("pendulum", 100, {"energy": 0.5, "section": "p1=0"}),
            ("pendulum", 400, {"energy": 0.5, "section": "p1=0"}),
            ("figure_eight", 600, eight_options)]


def start_nodes(system, nodes, options):
    """The default start of ``solve_periodic``, computed once for both solvers."""
    theta = system.parameter_vector(None)
    index, value, label = parse_section(options["section"], system.n)
    q, p = options.get("start") or (np.ones(system.n), np.ones(system.n))
    point = section_point(system, theta, options["energy"], index, value,
                          np.concatenate([q, p]), label)
    t, z = resample(*march_to_return(system, theta, point, index, value, "vddvp"), nodes)
    return {"t": t, "q": z[:, :system.n], "p": z[:, system.n:]}


def rotations(repeats: int) -> None:
    """The rotation by continuation against IPOPT from uniform times (module docstring)."""
    system = load_scene("pendulum").system
    theta = system.parameter_vector(None)
    point = section_point(system, theta, 2.5, 1, 0.0, np.ones(2), "q1=0")
    traced = march_to_return(system, theta, point, 1, 0.0, "vddvp", True)
    print("\n| N | start | solver | status | iterations per level | wall s | CPU s |")
    print("|---|---|---|---|---|---|---|")
    for nodes in (100, 200, 400, 800):
        t, z = resample(*traced, nodes, angles=(0,))
        uniform = {"t": t, "q": z[:, :1], "p": z[:, 1:]}
        measured = {}
        for label, solver, guess, most in (("continuation", "newton", None, None),
                                           ("continuation", "ipopt", None, None),
                                           ("uniform times", "ipopt", uniform, 400)):
            run = functools.partial(solve_periodic, system, energy=2.5, nodes=nodes + 1,
                                    section="q1=0", angles=("q1",), guess=guess,
                                    options=GridOptions(solver=solver, max_iter=most))
            cpu, wall, orbit = timed(repeats, run)
            measured[label, solver] = (cpu, wall)
            levels = orbit.stats.get("levels") or [{"iterations": orbit.stats["iterations"]}]
            print(f"| {nodes} | {label} | {solver} | {orbit.status.code} | "
                  f"{' + '.join(str(level['iterations']) for level in levels)} | {wall:.3f} | "
                  f"{cpu:.3f} |", flush=True)
        old = measured["uniform times", "ipopt"]
        for solver in ("newton", "ipopt"):
            new = measured["continuation", solver]
            print(f"| {nodes} | uniform IPOPT / continuation {solver} | | | | "
                  f"{old[1] / new[1]:.1f}x | {old[0] / new[0]:.1f}x |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", default="solvers,rotation")
    args = parser.parse_args()
    print(f"load average at the start: {os.getloadavg()}", flush=True)
    if "rotation" in args.only:
        rotations(args.repeats)
    if "solvers" in args.only:
        solvers(args.repeats)
    print(f"\nload average at the end: {os.getloadavg()}")
    print(f"machine: {machine()}")


def solvers(repeats: int) -> None:
    header = ("| scene | N | solver | status | iterations | wall s | CPU s | first call wall s "
              "| period | largest residual |")
    print(header)
    print("|---" * 10 + "|")
    for name, nodes, options in cases():
        system = load_scene(name).system
        guess = start_nodes(system, nodes, options)
        measured = {}
        for solver in ("newton", "ipopt"):
            run = functools.partial(solve_periodic, system, nodes=nodes + 1, guess=guess,
                                    options=GridOptions(solver=solver), **options)
            first = time.perf_counter()
            run()
            first = time.perf_counter() - first
            cpu, wall, orbit = timed(repeats, run)
            measured[solver] = (cpu, wall)
            print(f"| {name} | {nodes} | {solver} | {orbit.status.code} | "
                  f"{orbit.stats['iterations']} | {wall:.3f} | {cpu:.3f} | {first:.2f} | "
                  f"{orbit.orbit.period:.10f} | "
                  f"{max(orbit.orbit.residuals.values()):.1e} |", flush=True)
        (n_cpu, n_wall), (i_cpu, i_wall) = measured["newton"], measured["ipopt"]
        print(f"| {name} | {nodes} | ipopt / newton | | | {i_wall / n_wall:.1f}x | "
              f"{i_cpu / n_cpu:.1f}x | | | |", flush=True)


if __name__ == "__main__":
    main()
