"""What asking for an error costs: ``march(..., target_error=E)`` (pilot, choice, one or two
runs) against the march at the largest ``tau0`` that just meets ``E`` (found by bisection on
``tau0``, each run judged by the accuracy check at ``global_tol = E``), side by side.

For each case the row gives the chosen ``tau0`` and its verdict, the whole call's CPU (pilot
and runs), the ``tau0`` that just meets the target and the CPU of that one run (the least a
user who knew it would pay), and their ratio. CPU of this process (``time.process_time``),
warm (each case's compiled code is loaded by a first short march); wall beside.

    python scripts/benchmarks/bench_target_error.py [--bisections 8]
"""

from __future__ import annotations

import argparse
import dataclasses
import time
import warnings

from ddvp_nlp import Tolerance, load_scene, march
from ddvp_nlp.io import machine

CASES = [("kepler", {"e": 0.6}, 1e-4), ("kepler", {"e": 0.6}, 1e-2),
         ("henon_heiles", {}, 1e-3), ("pendulum", {}, 1e-4),
         ("paper_pendulum", {"t_end": 1000.0}, 1e-2)]


def timed(function):
    cpu, wall = time.process_time(), time.perf_counter()
    result = function()
    return time.process_time() - cpu, time.perf_counter() - wall, result


def just_meets(scene, config, target: float, start: float, bisections: int):
    """The largest tau0 whose march is accurate at ``target`` (geometric bisection between a
    step that fails and one that passes), and its run's CPU and wall."""
    tolerance = dataclasses.replace(Tolerance(), global_tol=target)

    def run(tau):
        return march(scene.system, config.q0, config.p0, (config.t0, config.t_end), tau0=tau,
                     params=config.params, accuracy=tolerance)

    def accurate(solution):
        return solution.success and solution.verdict.name == "accurate"

    good, bad = start, start
    while not accurate(run(good)):
        good /= 4
    while accurate(run(bad)):
        bad *= 4
        if bad > 64 * start:
            break
    for _ in range(bisections):
        middle = (good * bad) ** 0.5
        if accurate(run(middle)):
            good = middle
        else:
            bad = middle
    cpu, wall, solution = timed(lambda: run(good))
    return good, cpu, wall, solution


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bisections", type=int, default=8)
    args = parser.parse_args()
    warnings.simplefilter("ignore", RuntimeWarning)
    print(machine())
    print("\n| case | target | tau0 chosen | verdict | runs | CPU s (whole call) | wall s | "
          "tau0 that just meets it | its run's CPU s | ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, overrides, target in CASES:
        scene = load_scene(name)
        config = scene.resolve(overrides)
        march(scene.system, config.q0, config.p0, (config.t0, config.t0 + 10 * config.tau0),
              tau0=config.tau0, params=config.params)  # load the compiled code
        cpu, wall, solution = timed(lambda scene=scene, config=config, target=target: march(
            scene.system, config.q0, config.p0, (config.t0, config.t_end), tau0=config.tau0,
            params=config.params, target_error=target))
        record = solution.march.target_error
        chosen = record["tau0"]
        best, best_cpu, _, _ = just_meets(scene, config, target, chosen, args.bisections)
        label = name + "".join(f", {k} = {v:g}" for k, v in overrides.items())
        print(f"| {label} | {target:g} | {chosen:.4g} | "
              f"{solution.verdict.name} | {len(record['runs'])} | {cpu:.3f} | "
              f"{wall:.3f} | {best:.4g} | {best_cpu:.3f} | {cpu / best_cpu:.2f} |", flush=True)
    print(f"\n{machine()}")


if __name__ == "__main__":
    main()
