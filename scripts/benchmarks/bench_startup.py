"""What a whole warm ``ddvp march`` costs beside its solve, side by side in one run: the
interpreter with numpy and casadi (the floor), ``import ddvp_nlp``, matplotlib's import (as the
command's figure code imports it), ``ddvp march SCENE --no-plot`` and ``ddvp march SCENE`` with
its figure. Each is its own process, the five alternated, after one warm-up of each (compiled
chunks in the cache); medians of ``--repeats``. With ``--against FOLDER`` the same five run
with another source tree's ddvp_nlp too (e.g. a checkout of main), alternated with this one's,
so that before and after see the same load.

CPU time (user + sys of the whole process) is the figure of merit: the machine is shared, so
wall time is printed beside it, with the load average. Issue 38's targets: the warm march with
its figure at most 1.0 s CPU, with ``--no-plot`` at most 0.6 s.

Python compiles each module of ddvp_nlp from its source at every start when no bytecode is
cached (an editable install under PYTHONDONTWRITEBYTECODE=1); the machine line says how many
are cached, and ``--bytecode`` compiles them first (``compileall``), as an installed package
has them.

    python scripts/benchmarks/bench_startup.py [--repeats 7] [--scene paper_pendulum] [--format png]
                                    [--bytecode] [--against FOLDER]
"""

from __future__ import annotations

import argparse
import compileall
import importlib.util
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
from pathlib import Path

TARGETS = {"march --no-plot": 0.6, "march with figure": 1.0}


def timed_run(argv: list[str], env: dict, cwd: str) -> tuple[float, float]:
    """``(cpu, wall)`` seconds of one child process running ``argv``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, env=env, cwd=cwd)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), wall


def ddvp_command() -> list[str]:
    """The installed ``ddvp`` script beside this interpreter, else ``python -m ddvp_nlp.cli``."""
    script = os.path.join(os.path.dirname(sys.executable), "ddvp")
    return [script] if os.path.exists(script) else [sys.executable, "-m", "ddvp_nlp.cli"]


def source_tree() -> Path:
    """The source tree this script belongs to: the nearest folder above it holding
    ``ddvp_nlp/``; its ddvp_nlp is the one measured (first on the children's PYTHONPATH)."""
    for folder in Path(__file__).resolve().parents:
        if (folder / "ddvp_nlp" / "__init__.py").exists():
            return folder
    raise SystemExit("bench_startup.py: no ddvp_nlp/ in a folder above this script")


def package_folder() -> Path:
    return source_tree() / "ddvp_nlp"


def tree_environment(folder: Path) -> dict:
    """This process's environment with ``folder`` first on PYTHONPATH."""
    paths = [str(folder), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}


def bytecode_line() -> str:
    """How many of ddvp_nlp's modules have bytecode cached for this interpreter."""
    sources = list(package_folder().rglob("*.py"))
    cached = sum(Path(importlib.util.cache_from_source(str(path))).exists() for path in sources)
    writes = ("not written by imports (PYTHONDONTWRITEBYTECODE)"
              if os.environ.get("PYTHONDONTWRITEBYTECODE") else "written by imports")
    return f"ddvp_nlp bytecode cached for {cached} of {len(sources)} modules, {writes}"


def machine_line() -> str:
    versions = ", ".join(f"{name} {version(name)}" for name in ("numpy", "casadi", "matplotlib"))
    return (f"{platform.node()}: {platform.platform()}, {os.cpu_count()} cores, Python "
            f"{platform.python_version()}, {versions}; {bytecode_line()}")


# matplotlib as the command's figure code imports it (io/figures.py; a tree from before
# load_matplotlib imports it whole)
MATPLOTLIB = """
try:
    from ddvp_nlp.io.figures import load_matplotlib
except ImportError:
    import ddvp_nlp, matplotlib.figure
else:
    load_matplotlib(help_tables=False)
import matplotlib.backends.backend_{backend}
"""


def cases(args, folder: str) -> dict:
    """Each measured process: its name -> argv."""
    python = sys.executable
    backend = "agg" if args.format == "png" else args.format
    march = [*ddvp_command(), "march", args.scene, "--no-progress", "--format", args.format]
    return {
        "numpy + casadi": [python, "-c", "import numpy, casadi"],
        "import ddvp_nlp": [python, "-c", "import ddvp_nlp"],
        "+ matplotlib": [python, "-c", MATPLOTLIB.format(backend=backend)],
        "march --no-plot": [*march, "--out", os.path.join(folder, "no-plot"), "--no-plot"],
        "march with figure": [*march, "--out", os.path.join(folder, "figure")],
    }


def measure(args, trees: dict) -> dict:
    """``{tree: {case: [(cpu, wall), ...]}}`` and each tree's march timings and figure size,
    every case of every tree alternated, after one warm-up of each."""
    results = {tree: {"times": {}, "timings": []} for tree in trees}
    with tempfile.TemporaryDirectory() as folder:
        argvs = {tree: cases(args, os.path.join(folder, tree)) for tree in trees}
        # each case of one tree next to the same case of the other, so that the pair sees one
        # load, the first of the pair alternating
        runs = [[(tree, name, argvs[tree][name], env) for tree, env in trees.items()]
                for name in argvs["this tree"]]
        # every child starts in the scratch folder: started in a source tree, `python -c`
        # would import that tree's ddvp_nlp before any on PYTHONPATH
        for pair in runs:  # warm-up: compiled chunks into the cache
            for _, _, argv, env in pair:
                timed_run(argv, env, folder)
        for repeat in range(args.repeats):
            for pair in runs:
                for tree, name, argv, env in pair[::-1] if repeat % 2 else pair:
                    results[tree]["times"].setdefault(name, []).append(
                        timed_run(argv, env, folder))
        for tree in trees:
            with open(os.path.join(folder, tree, "no-plot", "meta.json")) as file:
                results[tree]["timing"] = json.load(file).get("timing", {})
            results[tree]["figure_bytes"] = os.path.getsize(
                os.path.join(folder, tree, "figure", f"trajectory.{args.format}"))
    return results


def report(tree: str, result: dict) -> dict:
    """Print one tree's table, where its CPU goes and the targets; return its CPU medians."""
    times = result["times"]
    print(f"{tree}:")
    print(f"  {'':20s} {'CPU median':>10s} {'CPU min':>8s} {'wall median':>11s} {'target':>7s}"
          f" {'CPU/target':>10s}")
    cpu = {}
    for name, values in times.items():
        cpu[name] = statistics.median(c for c, _ in values)
        wall = statistics.median(w for _, w in values)
        target = TARGETS.get(name)
        tail = f" {target:7.2f} {cpu[name] / target:10.2f}" if target else ""
        print(f"  {name:20s} {cpu[name]:10.3f} {min(c for c, _ in values):8.3f} {wall:11.3f}"
              + tail)
    figure = cpu["march with figure"] - cpu["march --no-plot"]
    parts = {
        "interpreter + numpy + casadi": cpu["numpy + casadi"],
        "import ddvp_nlp beyond them": cpu["import ddvp_nlp"] - cpu["numpy + casadi"],
        "the command beyond the import (parser, scene, march, files)":
            cpu["march --no-plot"] - cpu["import ddvp_nlp"],
        "the figure (with --no-plot and without)": figure,
        "  of which matplotlib's import": cpu["+ matplotlib"] - cpu["import ddvp_nlp"],
        "  of which drawing and writing": figure - (cpu["+ matplotlib"] - cpu["import ddvp_nlp"]),
    }
    print(f"  where the CPU of the march with its figure ({cpu['march with figure']:.3f} s) "
          "goes, by differences of medians:")
    for name, value in parts.items():
        print(f"    {name:62s} {value:6.3f} s")
    timing = result["timing"]
    print("    the march's own timing (meta.json, wall, last run): "
          + ", ".join(f"{key[:-2]} {timing.get(key, 0.0):.3f} s"
                      for key in ("build_s", "solve_s", "verify_s", "accuracy_s")))
    top = max((name for name in parts if not name.startswith("  ")), key=parts.get)
    print(f"  dominant: {top} ({parts[top]:.3f} s); figure file "
          f"{result['figure_bytes'] / 1e3:.0f} kB")
    for name, target in TARGETS.items():
        verdict = "met" if cpu[name] <= target else f"MISSED by {cpu[name] - target:.3f} s"
        print(f"  target {name}: at most {target:.2f} s CPU, median {cpu[name]:.3f} s: {verdict}")
    return cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--scene", default="paper_pendulum")
    parser.add_argument("--format", default="png", choices=("png", "svg", "pdf"))
    parser.add_argument("--bytecode", action="store_true",
                        help="compile ddvp_nlp's modules to bytecode first (compileall)")
    parser.add_argument("--against", default=None, metavar="FOLDER",
                        help="also run the ddvp_nlp of another source tree (a folder holding "
                             "ddvp_nlp/, put first on PYTHONPATH), alternated with this one")
    args = parser.parse_args()
    trees = {"this tree": tree_environment(source_tree())}
    if args.against:
        against = os.path.abspath(args.against)
        trees = {f"against {against}": tree_environment(Path(against)), **trees}
    if args.bytecode:
        compileall.compile_dir(str(package_folder()), quiet=1)
        if args.against:
            compileall.compile_dir(os.path.join(against, "ddvp_nlp"), quiet=1)
    load_before = os.getloadavg()
    results = measure(args, trees)
    load_after = os.getloadavg()
    print(machine_line())
    print(f"ddvp march {args.scene} --format {args.format}: {args.repeats} runs of each, "
          f"{'both trees ' if args.against else ''}alternated, warm cache; load average "
          f"{load_before[0]:.2f} before, {load_after[0]:.2f} after (1 min)")
    medians = {tree: report(tree, result) for tree, result in results.items()}
    if args.against:
        before, after = medians.values()
        print("this tree against the other (CPU medians): " + "; ".join(
            f"{name} {before[name]:.3f} -> {after[name]:.3f} s" for name in after))


if __name__ == "__main__":
    main()
