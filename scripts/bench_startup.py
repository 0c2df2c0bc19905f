"""What a whole warm ``ddvp march`` costs beside its solve, side by side in one run: the
interpreter with numpy and casadi (the floor), ``import ddvp_nlp``, matplotlib's import (what
the figure code loads), ``ddvp march SCENE --no-plot`` and ``ddvp march SCENE`` with its
figure. Each is its own process, the five alternated, after one warm-up of each (compiled
chunks in the cache); medians of ``--repeats``.

CPU time (user + sys of the whole process) is the figure of merit: the machine is shared, so
wall time is printed beside it, with the load average. Issue 38's targets: the warm march with
its figure at most 1.0 s CPU, with ``--no-plot`` at most 0.6 s.

    python scripts/bench_startup.py [--repeats 7] [--scene paper_pendulum] [--format png]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from importlib.metadata import version

TARGETS = {"march --no-plot": 0.6, "march with figure": 1.0}


def timed_run(argv: list[str]) -> tuple[float, float]:
    """``(cpu, wall)`` seconds of one child process running ``argv``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), wall


def ddvp_command() -> list[str]:
    """The installed ``ddvp`` script beside this interpreter, else ``python -m ddvp_nlp.cli``."""
    script = os.path.join(os.path.dirname(sys.executable), "ddvp")
    return [script] if os.path.exists(script) else [sys.executable, "-m", "ddvp_nlp.cli"]


def machine_line() -> str:
    versions = ", ".join(f"{name} {version(name)}" for name in ("numpy", "casadi", "matplotlib"))
    bytecode = ("not written (PYTHONDONTWRITEBYTECODE)" if os.environ.get("PYTHONDONTWRITEBYTECODE")
                else "written")
    return (f"{platform.node()}: {platform.platform()}, {os.cpu_count()} cores, Python "
            f"{platform.python_version()}, {versions}; bytecode {bytecode}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--scene", default="paper_pendulum")
    parser.add_argument("--format", default="png", choices=("png", "svg", "pdf"))
    args = parser.parse_args()
    python = sys.executable
    backend = "agg" if args.format == "png" else args.format
    with tempfile.TemporaryDirectory() as folder:
        plain = os.path.join(folder, "no-plot")
        drawn = os.path.join(folder, "figure")
        march = [*ddvp_command(), "march", args.scene, "--no-progress", "--format", args.format]
        cases = {
            "numpy + casadi": [python, "-c", "import numpy, casadi"],
            "import ddvp_nlp": [python, "-c", "import ddvp_nlp"],
            "+ matplotlib": [python, "-c", "import numpy, casadi, matplotlib.figure, "
                             f"matplotlib.backends.backend_{backend}"],
            "march --no-plot": [*march, "--out", plain, "--no-plot"],
            "march with figure": [*march, "--out", drawn],
        }
        for argv in cases.values():  # warm-up: compiled chunks into the cache
            timed_run(argv)
        load_before = os.getloadavg()
        times = {name: [] for name in cases}
        timings = []
        for _ in range(args.repeats):
            for name, argv in cases.items():
                times[name].append(timed_run(argv))
            with open(os.path.join(plain, "meta.json")) as file:
                timings.append(json.load(file).get("timing", {}))
        load_after = os.getloadavg()
        figure_bytes = os.path.getsize(os.path.join(drawn, f"trajectory.{args.format}"))

    print(machine_line())
    print(f"ddvp march {args.scene} --format {args.format}: {args.repeats} runs of each, "
          f"alternated, warm cache; load average {load_before[0]:.2f} before, "
          f"{load_after[0]:.2f} after (1 min)")
    print(f"{'':20s} {'CPU median':>10s} {'CPU min':>8s} {'wall median':>11s} {'target':>7s}"
          f" {'CPU/target':>10s}")
    cpu = {}
    for name, values in times.items():
        cpu[name] = statistics.median(c for c, _ in values)
        wall = statistics.median(w for _, w in values)
        target = TARGETS.get(name)
        tail = f" {target:7.2f} {cpu[name] / target:10.2f}" if target else ""
        print(f"{name:20s} {cpu[name]:10.3f} {min(c for c, _ in values):8.3f} {wall:11.3f}"
              + tail)
    parts = {
        "interpreter + numpy + casadi": cpu["numpy + casadi"],
        "import ddvp_nlp beyond them": cpu["import ddvp_nlp"] - cpu["numpy + casadi"],
        "the command beyond the import (parser, scene, march, files)":
            cpu["march --no-plot"] - cpu["import ddvp_nlp"],
        "the figure (with --no-plot and without)":
            cpu["march with figure"] - cpu["march --no-plot"],
        "  of which matplotlib's import": cpu["+ matplotlib"] - cpu["numpy + casadi"],
    }
    parts["  of which drawing and writing"] = (parts["the figure (with --no-plot and without)"]
                                               - parts["  of which matplotlib's import"])
    print(f"where the CPU of the march with its figure ({cpu['march with figure']:.3f} s) goes,"
          " by differences of medians:")
    for name, value in parts.items():
        print(f"  {name:62s} {value:6.3f} s")
    march_parts = {key: statistics.median(t.get(key, 0.0) for t in timings)
                   for key in ("build_s", "solve_s", "verify_s", "accuracy_s")}
    print("  the march's own timing (meta.json, wall, medians): "
          + ", ".join(f"{key[:-2]} {value:.3f} s" for key, value in march_parts.items()))
    top = max((name for name in parts if not name.startswith("  ")), key=parts.get)
    print(f"dominant: {top.strip()} ({parts[top]:.3f} s); figure file {figure_bytes / 1e3:.0f} kB")
    for name, target in TARGETS.items():
        verdict = "met" if cpu[name] <= target else f"MISSED by {cpu[name] - target:.3f} s"
        print(f"target {name}: at most {target:.2f} s CPU, median {cpu[name]:.3f} s: {verdict}")


if __name__ == "__main__":
    main()
