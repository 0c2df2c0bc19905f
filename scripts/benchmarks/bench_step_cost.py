"""Per-step cost of the compiled march on systems of a user's kind, beside the paper's pendulum:
a 2-dof system with trigonometric terms (a spherical pendulum in angles, whose azimuth winds, the
system of issue 49), the same started with its azimuth offset by 1e3 and 1e5 (a winding angle
after a long run, or a coordinate offset by a constant: the march's cost must not depend on
either), and a 2-dof system with cosines only. CPU per step of a warm ``march(...,
accuracy=None)`` (the best of ``--repeats``, the compiled chunks cached; the paper's pendulum to
``5 t_end``, for about as many steps as the others), wall time beside it;
ratios against the paper's pendulum measured in the same run. Issue 49's target: the spherical
pendulum at most 3x the paper's pendulum per step.

    python scripts/benchmarks/bench_step_cost.py [--repeats 5] [--t-end 2000]
"""

from __future__ import annotations

import argparse
import time

import casadi as ca

from ddvp_nlp import HamiltonianSystem, load_scene, march
from ddvp_nlp.io import machine


def spherical(q, p, t):
    return p[0] ** 2 / 2 + p[1] ** 2 / (2 * ca.sin(q[0]) ** 2) - ca.cos(q[0])


def two_cosines(q, p, t):
    return p[0] ** 2 / 2 + p[1] ** 2 / 2 - ca.cos(q[0]) - ca.cos(q[1])


def best(run, repeats: int) -> tuple[float, float, int]:
    """``(cpu, wall, steps)`` of the fastest of ``repeats`` warm runs (by CPU)."""
    run()
    found = None
    for _ in range(repeats):
        cpu, wall = time.process_time(), time.perf_counter()
        solution = run()
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        if found is None or cpu < found[0]:
            found = (cpu, wall, solution.t.size - 1)
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--t-end", type=float, default=2000.0)
    args = parser.parse_args()
    scene = load_scene("paper_pendulum")
    sphere = HamiltonianSystem(spherical, 2, name="spherical_pendulum_angles")
    cosines = HamiltonianSystem(two_cosines, 2, name="two_cosines")
    runs = {
        "paper_pendulum (1 dof, the paper's example)":
            lambda: scene.march(t_end=5 * args.t_end, accuracy=None),
        "two cosines (2 dof)": lambda: march(cosines, [2.0, 0.0], [0.0, 1.2], (0, args.t_end),
                                             tau0=0.05, accuracy=None),
    }
    for offset in (0.0, 1e3, 1e5):
        runs[f"spherical pendulum in angles, azimuth from {offset:g}"] = (
            lambda offset=offset: march(sphere, [2.0, offset], [0.0, 1.2], (0, args.t_end),
                                        tau0=0.05, accuracy=None))
    found = {label: best(run, args.repeats) for label, run in runs.items()}
    base = found["paper_pendulum (1 dof, the paper's example)"]
    print("| system | steps | CPU per step (us) | wall per step (us) | CPU ratio to "
          "paper_pendulum |\n|---|---|---|---|---|")
    for label, (cpu, wall, steps) in found.items():
        print(f"| {label} | {steps} | {1e6 * cpu / steps:.3f} | {1e6 * wall / steps:.3f} | "
              f"{(cpu / steps) / (base[0] / base[2]):.2f} |")
    print(f"\n{machine()}")


if __name__ == "__main__":
    main()
