"""What the accuracy check costs: each scene's march with the default check (the verdict against
the reference flow) beside the same march without it (``accuracy=None``), side by side.

Warm runs: the compiled chunk and the check's compiled functions loaded from the cache (before
the timed runs the checked march is repeated until it has spent more CPU than the rent
``RentedBuffer`` pays before it compiles a check function, so a function not yet compiled is
bought in the warm-up); the two variants interleaved ``--repeats`` times; CPU time of this
process (``time.process_time``) beside wall time, the median and the range of each, and the
ratio of the medians; the load average printed (the machine is shared). Each row says what the
check measured against and how far: the reference flow stops at ``t_drift`` (a drifted run), so
on a drifted run it covers only the nodes before it; an accurate run is measured over all of
them.

    python scripts/benchmarks/bench_accuracy.py [--repeats 7]
        [--out docs/benchmarks/bench_accuracy.md] [--only RUN ...]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
import warnings
from pathlib import Path

import numpy as np

from ddvp_nlp import HamiltonianSystem, load_scene, march
from ddvp_nlp.io import machine

ROOT = Path(__file__).resolve().parents[2]

WARM_CPU_S = 0.6  # CPU of checked runs before the timed ones: more than a compile's rent

CASES = [("paper_pendulum", {}), ("kepler", {}), ("henon_heiles", {}), ("fpu", {}),
         ("harmonic", {"t_end": 2000.0}), ("sine_gordon", {"sites": 16})]
# Issue 49's lattice, a user's system (no scene): sine-Gordon on a ring of `sites` sites,
# H = sum p_i^2 / 2 + k (q_i+1 - q_i)^2 / 2 + (1 - cos q_i), from a standing wave at rest.
LATTICE = {"k": 1.0, "amplitude": 1.2, "t_end": 100.0, "tau0": 0.05}


def sine_gordon(sites: int):
    """``(system, q0, p0, span, tau0, params)`` of the lattice of ``sites`` sites."""
    import casadi as ca

    def hamiltonian(q, p, t, k):
        ring = ca.vertcat(q[1:], q[:1])
        return ca.sumsqr(p) / 2 + k * ca.sumsqr(ring - q) / 2 + ca.sum1(1 - ca.cos(q))

    system = HamiltonianSystem(hamiltonian, n=sites, params={"k": LATTICE["k"]},
                               name=f"sine-Gordon lattice, {sites} sites")
    q0 = LATTICE["amplitude"] * np.cos(2 * np.pi * np.arange(sites) / sites)
    return (system, q0, np.zeros(sites), (0.0, LATTICE["t_end"]), LATTICE["tau0"],
            {"k": LATTICE["k"]})


def problem(name, overrides):
    """``(system, q0, p0, span, tau0, params)`` of a case."""
    if name == "sine_gordon":
        return sine_gordon(overrides["sites"])
    scene = load_scene(name)
    config = scene.resolve(overrides)
    return (scene.system, config.q0, config.p0, (config.t0, config.t_end), config.tau0,
            config.params)


def timed(function):
    cpu, wall = time.process_time(), time.perf_counter()
    result = function()
    return time.process_time() - cpu, time.perf_counter() - wall, result


def bench(name, overrides, repeats):
    system, q0, p0, span, tau0, params = problem(name, overrides)

    def run(check):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            options = {} if check else {"accuracy": None}
            return march(system, q0, p0, span, tau0=tau0, params=params, **options)

    # warm: the march's chunk compiled or loaded, and the check's functions too (each is run
    # on CasADi's virtual machine until its rent, summed over processes in the cache, pays
    # for its compile: the checked march is repeated until it has spent WARM_CPU_S)
    run(False)
    spent = 0.0
    while spent < WARM_CPU_S:
        spent += timed(lambda: run(True))[0]
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
    parser.add_argument("--only", nargs="+", metavar="RUN", choices=[n for n, _ in CASES],
                        help="only these runs (the page is then not written)")
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
        if args.only and name not in args.only:
            continue
        solution, times = bench(name, overrides, args.repeats)
        lines.append(row(name, overrides, solution, times))
        print(lines[-1], flush=True)
    end = os.getloadavg()
    lines += ["", f"Load average at the end {end[0]:.2f}, {end[1]:.2f}, {end[2]:.2f}.", ""]
    if args.only:
        return
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines))
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
