"""What the run figure costs: ``ddvp march paper_pendulum`` with and without ``--no-plot``,
each as its own process, alternated, after one warm-up run (compiled chunks cached), and, in
fresh processes that have marched the scene first, matplotlib's import (as the command's own
process imports it: ``load_matplotlib(help_tables=False)``, without the help tables) and the
drawing timed apart (CPU and wall).

CPU time (user + sys) is the figure of merit: the machine is shared, so wall time is printed
beside it, not instead, with the load average. Issue 30's target: the figure of
``ddvp march paper_pendulum``, matplotlib's import included, at most 0.5 s of CPU.

    python scripts/benchmarks/bench_figure.py [--repeats 5] [--scene paper_pendulum] [--format png]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time

from ddvp_nlp.io import machine


def timed_run(argv: list[str]) -> tuple[float, float]:
    """``(cpu, wall)`` seconds of one child process running ``argv``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall


def in_process(scene_name: str, folder: str, fmt: str) -> tuple[float, ...]:
    """CPU and wall seconds of importing matplotlib (what the figure code imports, lazily) and
    of drawing and writing the run's figure, in a fresh process that has marched the scene
    first (what ``ddvp march`` does before drawing)."""
    code = f"""
import time
from ddvp_nlp import load_scene, march
from ddvp_nlp.discrete import Scheme
from ddvp_nlp.io import run_energies
scene = load_scene({scene_name!r})
config = scene.resolve({{}})
solution = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                 tau0=config.tau0, params=config.params)
energies = run_energies(scene.system, Scheme(), solution,
                        scene.system.parameter_vector(config.params))
import sys
assert "matplotlib" not in sys.modules, "matplotlib was imported before the figure"
cpu, wall = time.process_time(), time.perf_counter()
from ddvp_nlp.io import plot_trajectory
from ddvp_nlp.io.figures import load_matplotlib
load_matplotlib(help_tables=False)  # as the command's own process imports it
import matplotlib.backends.backend_{'agg' if fmt == 'png' else fmt}
cpu_import, wall_import = time.process_time(), time.perf_counter()
plot_trajectory(solution, scene, Scheme(), {folder!r} + "/figure.{fmt}", energies=energies,
                fmt={fmt!r})
print(cpu_import - cpu, time.process_time() - cpu_import,
      wall_import - wall, time.perf_counter() - wall_import)
"""
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                         text=True).stdout.split()
    return tuple(float(v) for v in out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--scene", default="paper_pendulum")
    parser.add_argument("--format", default="png", choices=("png", "svg", "pdf"))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        ddvp = [sys.executable, "-m", "ddvp_nlp.cli", "march", args.scene, "--no-progress",
                "--out", os.path.join(folder, "run"), "--format", args.format]
        timed_run(ddvp)  # warm-up: compiled chunks into the cache
        runs = {"with figure": [], "--no-plot": []}
        for _ in range(args.repeats):
            runs["with figure"].append(timed_run(ddvp))
            runs["--no-plot"].append(timed_run([*ddvp, "--no-plot"]))
        inside = [in_process(args.scene, folder, args.format) for _ in range(args.repeats)]
    print(f"ddvp march {args.scene} --format {args.format}, {args.repeats} runs each, "
          f"alternated (CPU = user + sys); load average {os.getloadavg()[0]:.2f}")
    print(f"{'':14s} {'CPU median':>10s} {'CPU min':>8s} {'wall median':>11s}")
    medians = {}
    for name, values in runs.items():
        cpu = sorted(c for c, _ in values)
        wall = sorted(w for _, w in values)
        medians[name] = cpu[len(cpu) // 2]
        print(f"{name:14s} {medians[name]:10.2f} {cpu[0]:8.2f} {wall[len(wall) // 2]:11.2f}")
    figure = medians["with figure"] - medians["--no-plot"]
    print(f"figure by difference of the commands: {figure:.2f} s CPU of "
          f"{medians['with figure']:.2f} s")
    cpu_import, cpu_draw, wall_import, wall_draw = (sorted(v)[len(v) // 2]
                                                    for v in zip(*inside, strict=True))
    total = sorted(a + b for a, b, _, _ in inside)[len(inside) // 2]
    print(f"in one process (medians): matplotlib import {cpu_import:.3f} s CPU "
          f"({wall_import:.3f} s wall), drawing and writing {cpu_draw:.3f} s CPU "
          f"({wall_draw:.3f} s wall)")
    print(f"figure with import: {total:.3f} s CPU (target at most 0.5 s: "
          f"{'met' if total <= 0.5 else 'MISSED'})")
    print(f"machine: {machine()}")


if __name__ == "__main__":
    main()
