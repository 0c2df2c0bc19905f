"""What the accuracy check costs: each scene's march with the default check (the verdict against
the reference flow) beside the same march without it (``accuracy=None``), side by side.

Warm runs (the compiled chunk and the reference's block functions loaded from the cache), the
two variants interleaved ``--repeats`` times; CPU time of this process (``time.process_time``)
beside wall time, the median and the range of each, and the ratio of the medians; the load
average printed (the machine is shared). Each row says what the check measured against and how
far: the reference flow stops at ``t_drift`` (a drifted run), so on a drifted run it covers only
the nodes before it; an accurate run is measured over all of them.

    python scripts/benchmarks/bench_accuracy.py [--repeats 7]
        [--out docs/benchmarks/bench_accuracy.md]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
import warnings
from pathlib import Path

from ddvp_nlp import load_scene, march
from ddvp_nlp.io import machine

ROOT = Path(__file__).resolve().parents[2]

CASES = [("paper_pendulum", {}), ("kepler", {}), ("henon_heiles", {}), ("fpu", {}),
         ("harmonic", {"t_end": 2000.0})]


def timed(function):
    cpu, wall = time.process_time(), time.perf_counter()
    result = function()
    return time.process_time() - cpu, time.perf_counter() - wall, result


def bench(name, overrides, repeats):
    scene = load_scene(name)
    config = scene.resolve(overrides)

    def run(check):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            options = {} if check else {"accuracy": None}
            return march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                         tau0=config.tau0, params=config.params, **options)

    run(True), run(False)  # compile or load everything once
    times = {True: [], False: []}
    for _ in range(repeats):
        for check in (False, True):
            cpu, wall, solution = timed(lambda check=check: run(check))
            times[check].append((cpu, wall))
            if check:
                checked = solution
    return checked, times


def row(name, overrides, solution, times):
    accuracy = solution.verdict.as_dict()
    med = {check: (statistics.median(c for c, _ in times[check]),
                   statistics.median(w for _, w in times[check])) for check in times}
    span = {check: (min(c for c, _ in times[check]), max(c for c, _ in times[check]))
            for check in times}
    covered = accuracy["reference_until"]
    reach = ("the whole run" if accuracy["t_drift"] is None
             else f"t <= {covered:.4g} of {solution.t[-1]:.6g} (drifted)")
    label = name + ("" if not overrides else " " + ", ".join(f"{k} = {v:g}"
                                                             for k, v in overrides.items()))
    return (f"| {label} | {solution.steps} | {accuracy['verdict']} | "
            f"{med[False][0] * 1e3:.1f} ({span[False][0] * 1e3:.1f}-{span[False][1] * 1e3:.1f})"
            f" | {med[True][0] * 1e3:.1f} ({span[True][0] * 1e3:.1f}-"
            f"{span[True][1] * 1e3:.1f}) | {med[True][0] / med[False][0]:.2f} | "
            f"{med[False][1] * 1e3:.1f} | {med[True][1] * 1e3:.1f} | "
            f"{med[True][1] / med[False][1]:.2f} | {accuracy['estimate'].split(' (')[0]}, "
            f"{reach} |")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--out", default=str(ROOT / "docs" / "benchmarks" / "bench_accuracy.md"))
    args = parser.parse_args()
    lines = ["# The accuracy check's cost", "",
             f"`python scripts/benchmarks/bench_accuracy.py --repeats {args.repeats}`: each "
             f"march {args.repeats} "
             "times without and with the check, interleaved, warm; milliseconds of CPU "
             "(median, range) and wall (median); ratios of the medians.", "",
             f"Machine at the start: {machine()}", "",
             "| run | steps | verdict | CPU ms, no check | CPU ms, check | CPU ratio | wall ms, "
             "no check | wall ms, check | wall ratio | measured against |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for name, overrides in CASES:
        solution, times = bench(name, overrides, args.repeats)
        lines.append(row(name, overrides, solution, times))
        print(lines[-1], flush=True)
    end = os.getloadavg()
    lines += ["", f"Load average at the end {end[0]:.2f}, {end[1]:.2f}, {end[2]:.2f}.", ""]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines))
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
