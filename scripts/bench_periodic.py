"""Newton (SuperLU) against IPOPT on the periodic problem, side by side in one run.

    python scripts/bench_periodic.py [--repeats 3]

Each case starts both solvers from the same nodes (the default start: the march from the
section's point to its return, resampled on N intervals), so the times are the solvers' and the
verification's (residuals recomputed, the accuracy check), not the start's. Times are the best
of ``--repeats`` calls after one warm-up call (which builds the CasADi functions and the IPOPT
problem, both cached), CPU time beside wall time; the ratio is IPOPT's over Newton's.
"""

from __future__ import annotations

import argparse
import functools
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_march import timed  # noqa: E402

from ddvp_nlp import GridOptions, load_scene  # noqa: E402
from ddvp_nlp.solvers.periodic.solve import parse_section, solve_periodic  # noqa: E402
from ddvp_nlp.solvers.periodic.start import (  # noqa: E402
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    header = ("| scene | N | solver | status | iterations | wall s | CPU s | first call wall s "
              "| period | largest residual |")
    print(header)
    print("|---" * 10 + "|")
    for name, nodes, options in cases():
        system = load_scene(name).system
        guess = start_nodes(system, nodes, options)
        measured = {}
        for solver in ("newton", "ipopt"):
            run = functools.partial(solve_periodic, system, nodes=nodes, guess=guess,
                                    options=GridOptions(solver=solver), **options)
            first = time.perf_counter()
            run()
            first = time.perf_counter() - first
            cpu, wall, orbit = timed(args.repeats, run)
            measured[solver] = (cpu, wall)
            print(f"| {name} | {nodes} | {solver} | {orbit.status.code} | "
                  f"{orbit.stats['iterations']} | {wall:.3f} | {cpu:.3f} | {first:.2f} | "
                  f"{orbit.stats['period']:.10f} | "
                  f"{max(orbit.stats['residuals'].values()):.1e} |", flush=True)
        (n_cpu, n_wall), (i_cpu, i_wall) = measured["newton"], measured["ipopt"]
        print(f"| {name} | {nodes} | ipopt / newton | | | {i_wall / n_wall:.1f}x | "
              f"{i_cpu / n_cpu:.1f}x | | | |", flush=True)


if __name__ == "__main__":
    main()
