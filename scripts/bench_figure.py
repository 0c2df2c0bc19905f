"""What the run figure costs: ``ddvp march paper_pendulum`` with and without ``--no-plot``,
each as its own process, alternated, after one warm-up run (compiled chunks cached), and the
figure's import and drawing timed in one process.

CPU time (user + sys of the child process) is the figure of merit: the machine is shared, so
wall time is printed beside it, not instead. Issue 19's target: the figure at most a fifth of
a warm run's CPU time.

    python scripts/bench_figure.py [--repeats 5] [--scene paper_pendulum]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time


def timed_run(argv: list[str]) -> tuple[float, float]:
    """``(cpu, wall)`` seconds of one child process running ``argv``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall


def in_process(scene_name: str, folder: str) -> tuple[float, float]:
    """CPU seconds of importing the figure code and of drawing the run's figure, in a fresh
    process that has marched the scene first (what ``ddvp march`` does before drawing)."""
    code = f"""
import time
from ddvp_nlp import load_scene, march
from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.io.runs import run_energies
scene = load_scene({scene_name!r})
config = scene.resolve({{}})
solution = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                 tau0=config.tau0, params=config.params)
energies = run_energies(scene.system, Scheme(), solution,
                        scene.system.parameter_vector(config.params))
started = time.process_time()
from ddvp_nlp.io.plotting import plot_trajectory
imported = time.process_time()
plot_trajectory(solution, scene, Scheme(), {folder!r} + "/figure.png", energies=energies)
print(imported - started, time.process_time() - imported)
"""
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                         text=True).stdout.split()
    return float(out[0]), float(out[1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--scene", default="paper_pendulum")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        ddvp = [sys.executable, "-m", "ddvp_nlp.cli", "march", args.scene, "--no-progress",
                "--out", os.path.join(folder, "run")]
        timed_run(ddvp)  # warm-up: compiled chunks into the cache
        runs = {"with figure": [], "--no-plot": []}
        for _ in range(args.repeats):
            runs["with figure"].append(timed_run(ddvp))
            runs["--no-plot"].append(timed_run([*ddvp, "--no-plot"]))
        imports, draws = zip(*(in_process(args.scene, folder) for _ in range(args.repeats)),
                             strict=True)
    print(f"ddvp march {args.scene}, {args.repeats} runs each, alternated (CPU = user + sys)")
    print(f"{'':14s} {'CPU median':>10s} {'CPU min':>8s} {'wall median':>11s}")
    medians = {}
    for name, values in runs.items():
        cpu = sorted(c for c, _ in values)
        wall = sorted(w for _, w in values)
        medians[name] = cpu[len(cpu) // 2]
        print(f"{name:14s} {medians[name]:10.2f} {cpu[0]:8.2f} {wall[len(wall) // 2]:11.2f}")
    figure = medians["with figure"] - medians["--no-plot"]
    print(f"figure: {figure:.2f} s CPU of {medians['with figure']:.2f} s "
          f"({figure / medians['with figure']:.0%} of the run; target at most 20%)")
    print(f"in one process: import of the figure code {sorted(imports)[len(imports) // 2]:.3f} s,"
          f" drawing and writing the PNG {sorted(draws)[len(draws) // 2]:.3f} s CPU (medians)")


if __name__ == "__main__":
    main()
