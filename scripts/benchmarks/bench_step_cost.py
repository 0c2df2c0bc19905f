"""Per-step cost of the compiled march on systems of a user's kind, beside the paper's pendulum:
a 2-dof system with trigonometric terms (a spherical pendulum in angles, whose azimuth winds, the
system of issue 49), the same started with its azimuth offset by 1e3 and 1e5 (a winding angle
after a long run, or a coordinate offset by a constant: the march's cost must not depend on
either), and a 2-dof system with cosines only. CPU per step of a warm ``march(...,
accuracy=None)`` (the best of ``--repeats``, the compiled chunks cached; the paper's pendulum to
``5 t_end``, for about as many steps as the others), wall time beside it;
ratios against the paper's pendulum measured in the same run. Beside them the hand-written C
march of the spherical pendulum (``c_march.c``: ``c_march_sphere``, the same equations, Newton
stop and acceptance, ``gcc -O2``), with the library's RK4 predictor and with extrapolation from
three nodes; the march's ratio is taken against the faster. Each round runs every row once,
interleaved (the load hits them alike); each row is its best round by CPU. Issue 49's targets:
the spherical pendulum at most 3x the paper's pendulum per step, and within 2x the C march.

    python scripts/benchmarks/bench_step_cost.py [--repeats 5] [--t-end 2000]
"""

from __future__ import annotations

import argparse
import ctypes
import tempfile
import time

import casadi as ca
import numpy as np

# the script's own folder is on the path when it runs
from bench_march import c_march_library  # noqa: E402

from ddvp_nlp import HamiltonianSystem, load_scene, march
from ddvp_nlp.io import machine


def spherical(q, p, t):
    return p[0] ** 2 / 2 + p[1] ** 2 / (2 * ca.sin(q[0]) ** 2) - ca.cos(q[0])


def two_cosines(q, p, t):
    return p[0] ** 2 / 2 + p[1] ** 2 / 2 - ca.cos(q[0]) - ca.cos(q[1])


def interleaved(runs: dict, repeats: int) -> dict:
    """``{label: (cpu, wall, steps)}``, each row the fastest (by CPU) of ``repeats`` rounds
    that run every row once, after one warm-up round; a run returns its number of steps."""
    found = {}
    for round_ in range(repeats + 1):
        for label, run in runs.items():
            cpu, wall = time.process_time(), time.perf_counter()
            steps = run()
            cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
            if round_ and (label not in found or cpu < found[label][0]):
                found[label] = (cpu, wall, steps)
    return found


C_PREDICTORS = {0: "RK4 predictor, as the library", 2: "extrapolation from three nodes"}


def c_sphere_runs(lib, t_end: float) -> tuple[dict, dict]:
    """The C march of the spherical pendulum from each azimuth and predictor, and its Newton
    updates per step (filled in by the runs)."""
    capacity = int(t_end / 0.05 * 2) + 16
    t, z, H = np.empty(capacity + 1), np.empty((capacity + 1, 4)), np.empty(capacity + 1)
    runs, updates = {}, {}
    for offset in (0.0, 1e3, 1e5):
        for predictor, label in C_PREDICTORS.items():
            name = f"C march (c_march_sphere, {label}), azimuth from {offset:g}"
            count = ctypes.c_long(0)

            def run(offset=offset, predictor=predictor, count=count, name=name):
                steps = lib.c_march_sphere(np.array([2.0, offset, 0.0, 1.2]), 0.0, 0.05, t_end,
                                           capacity, 1e-10, predictor, t, z, H,
                                           ctypes.byref(count))
                if steps <= 0:
                    raise SystemExit(f"{name} failed at step {-steps}")
                updates[name] = count.value / steps
                return steps
            runs[name] = run
    return runs, updates


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
    runs = {label: (lambda run=run: run().steps) for label, run in runs.items()}
    print(machine())
    with tempfile.TemporaryDirectory() as folder:
        c_runs, updates = c_sphere_runs(c_march_library(folder), args.t_end)
        found = interleaved({**runs, **c_runs}, args.repeats)
    base = found["paper_pendulum (1 dof, the paper's example)"]
    print("\n| system | steps | CPU per step (us) | wall per step (us) | CPU ratio to "
          "paper_pendulum |\n|---|---|---|---|---|")
    for label, (cpu, wall, steps) in found.items():
        if label in c_runs:
            continue
        print(f"| {label} | {steps} | {1e6 * cpu / steps:.3f} | {1e6 * wall / steps:.3f} | "
              f"{(cpu / steps) / (base[0] / base[2]):.2f} |")
    print("\n| spherical pendulum, azimuth from | march() CPU us / step | C march CPU us / step "
          "(RK4; extrapolation) | Newton updates / step in C (RK4; extrapolation) "
          "| march() / faster C, CPU | march() / faster C, wall | target |\n"
          "|---|---|---|---|---|---|---|")
    for offset in (0.0, 1e3, 1e5):
        ours = found[f"spherical pendulum in angles, azimuth from {offset:g}"]
        c = [found[f"C march (c_march_sphere, {label}), azimuth from {offset:g}"]
             for label in C_PREDICTORS.values()]
        if any(steps != ours[2] for _, _, steps in c):
            raise SystemExit(f"the C march took {[s for _, _, s in c]} steps, march() {ours[2]}")
        fastest = min(c, key=lambda row: row[0])
        ratio = ours[0] / fastest[0]
        counts = "; ".join(
            f"{updates[f'C march (c_march_sphere, {label}), azimuth from {offset:g}']:.2f}"
            for label in C_PREDICTORS.values())
        print(f"| {offset:g} | {1e6 * ours[0] / ours[2]:.3f} | "
              f"{1e6 * c[0][0] / ours[2]:.3f}; {1e6 * c[1][0] / ours[2]:.3f} | {counts} | "
              f"{ratio:.2f} | {ours[1] / fastest[1]:.2f} | <= 2: "
              f"{'met' if ratio <= 2 else 'MISSED'} |")
    print(f"\n{machine()}")


if __name__ == "__main__":
    main()
