"""The fixed-endpoint solve with its accuracy check, whole command and parts, at 1e5 and 1e6
nodes: issue 37's targets.

The problem: the pendulum over t in [0, 18] (about 2.7 periods) from q = 0.5 to the end a
fixed-step march reaches (``bench_bvp.py``'s pendulum case), written on the command line as

    ddvp bvp pendulum --nodes N --set t_end=18 --set q_end=-0.44705455007896405

Each row is one whole ``ddvp bvp`` process (CPU user + sys and peak memory from ``wait4``,
wall beside), with the solve's own parts read back from its ``meta.json``: the solve (Newton or
IPOPT, the starts, the verification) and the accuracy check's CPU (``accuracy_cpu_s``: the
shooting solution near the grid and the verdict). "Newton alone" is the whole command's CPU
less the check's: the O(N) banded Newton with everything around it, the reference the issue's
ratio is taken against.

    python scripts/benchmarks/bench_bvp_check.py [--sizes 100000,1000000] [--solvers newton,ipopt]
                                                 [--repeats 1]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

Q_END = "-0.44705455007896405"  # the fixed-step march's q(18) (bench_bvp.py endpoints)
TARGETS = {  # (solver, N): (CPU s, peak MB) of the whole command
    ("auto", 1_000_000): (10.0, 800.0),
    ("ipopt", 1_000_000): (40.0, 4096.0),
}
RATIO_TARGET = 2.0  # at 1e5: the whole command against Newton alone


def project_root() -> Path:
    for folder in Path(__file__).resolve().parents:
        if (folder / "ddvp_nlp").is_dir():
            return folder
    raise SystemExit("bench_bvp_check.py: no ddvp_nlp/ in a folder above this script")


def one(nodes: int, solver: str) -> dict:
    """One whole ``ddvp bvp`` process: its CPU, wall and peak memory, and its meta.json."""
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch) / "run"
        argv = [sys.executable, "-m", "ddvp_nlp.cli", "bvp", "pendulum", "--nodes", str(nodes),
                "--set", "t_end=18", "--set", f"q_end={Q_END}", "--solver", solver,
                "--no-plot", "--no-progress", "--out", str(out)]
        started = time.perf_counter()
        child = subprocess.Popen(argv, cwd=project_root(), stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True)
        _, status, usage = os.wait4(child.pid, 0)
        wall = time.perf_counter() - started
        stdout, stderr = child.stdout.read(), child.stderr.read()
        child.stdout.close(), child.stderr.close()
        code = os.waitstatus_to_exitcode(status)
        if not (out / "meta.json").exists():
            raise SystemExit(f"ddvp bvp exited {code} without a run:\n{stderr[-2000:]}")
        meta = json.loads((out / "meta.json").read_text())
    timing = meta.get("timing", {})
    accuracy = meta.get("accuracy") or {}
    return {"N": nodes, "solver": solver, "exit": code, "status": meta.get("status"),
            "verdict": accuracy.get("verdict"), "cpu": usage.ru_utime + usage.ru_stime,
            "wall": wall, "peak_mb": usage.ru_maxrss / 1024,
            "check_cpu": float(timing.get("accuracy_cpu_s", float("nan"))),
            "solve_wall": float(timing.get("solve_s", float("nan"))),
            "estimate": accuracy.get("estimate", ""), "summary": stdout.splitlines()[:1]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="100000,1000000")
    parser.add_argument("--solvers", default="auto,ipopt")
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()
    sys.path.insert(0, str(project_root()))
    from ddvp_nlp.io import machine

    print(machine())
    print("\n| N | solver | status | verdict | CPU s (whole) | check CPU s | Newton alone CPU s "
          "| whole / alone | wall s | peak MB | target |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for nodes in (int(v) for v in args.sizes.split(",")):
        for solver in args.solvers.split(","):
            runs = [one(nodes, solver) for _ in range(args.repeats)]
            cpu = statistics.median(r["cpu"] for r in runs)
            check = statistics.median(r["check_cpu"] for r in runs)
            wall = statistics.median(r["wall"] for r in runs)
            peak = max(r["peak_mb"] for r in runs)
            alone = cpu - check
            target = TARGETS.get((solver, nodes))
            if target:
                verdict = (f"<= {target[0]:g} s, {target[1]:g} MB: "
                           + ("met" if cpu <= target[0] and peak <= target[1] else
                              f"MISSED ({cpu / target[0]:.2f}x CPU, {peak / target[1]:.2f}x "
                              "memory)"))
            elif nodes == 100_000 and solver == "auto":
                verdict = (f"whole <= {RATIO_TARGET:g}x alone: "
                           + ("met" if cpu <= RATIO_TARGET * alone else "MISSED"))
            else:
                verdict = ""
            r = runs[0]
            print(f"| {nodes} | {solver} | {r['status']} | {r['verdict']} | {cpu:.2f} | "
                  f"{check:.2f} | {alone:.2f} | {cpu / alone:.2f} | {wall:.2f} | {peak:.0f} | "
                  f"{verdict} |", flush=True)
    print("\nthe check measured against: " + runs[0]["estimate"][:200])
    print(machine())


if __name__ == "__main__":
    main()
