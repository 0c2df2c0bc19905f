"""Long runs (issue 38): what a long ``ddvp march`` writes and holds when it keeps every node and
when it keeps every 1000th (``--keep-every 1000``), and how soon Ctrl-C ends it.

Whole commands, each its own process (the command forks its supervised child; the figures are
of both, ``os.wait4``): CPU (user + sys) beside wall, peak RSS, the size of the run folder and
the part of the run that dominates (``meta.json``'s timing). Then SIGINT after ``--after``
seconds, sent to the process group as a terminal's Ctrl-C does, and to the parent only: the
wall time from the signal to the exit, the exit code, the status written and the nodes kept.
The load average is printed (the machine is shared). Issue 38's targets: a 1e7-step march
keeping every 1000th node writes under 10 MB; Ctrl-C after 10 s exits within 2 s plus the
writing of what is kept.

    python scripts/benchmarks/bench_long_runs.py [--after 10] [--steps 10000000]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TARGET_MB = 10.0
TARGET_EXIT_S = 2.0


def command(args: list[str], out: Path) -> list[str]:
    return [sys.executable, "-m", "ddvp_nlp.cli", "march", "pendulum", *args, "--no-plot",
            "--no-progress", "--out", str(out)]


def run(argv: list[str], *, signal_after: float | None = None, group: bool = True) -> dict:
    """One command: CPU, wall, peak RSS; with ``signal_after``, SIGINT then, and the exit's
    wall time after it."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    started = time.perf_counter()
    child = subprocess.Popen(argv, env=env, start_new_session=True,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    sent = None
    if signal_after is not None:
        time.sleep(signal_after)
        sent = time.perf_counter()
        if group:
            os.killpg(child.pid, signal.SIGINT)
        else:
            os.kill(child.pid, signal.SIGINT)
    _, status, usage = os.wait4(child.pid, 0)
    ended = time.perf_counter()
    return {"code": os.waitstatus_to_exitcode(status), "wall": ended - started,
            "cpu": usage.ru_utime + usage.ru_stime, "rss_mb": usage.ru_maxrss / 1024,
            "after_signal": None if sent is None else ended - sent}


def folder(out: Path) -> dict:
    meta = json.loads((out / "meta.json").read_text())
    size = sum(f.stat().st_size for f in out.iterdir() if f.is_file()) / 1e6
    timing = {k: v for k, v in meta.get("timing", {}).items() if isinstance(v, float)}
    top = max(timing, key=timing.get) if timing else "-"
    return {"status": meta["status"], "steps": meta["steps"], "nodes": meta["nodes"],
            "mb": size, "dominant": f"{top} {timing.get(top, 0):.2f} s",
            "skipped": "accuracy_skipped" in meta}


def line(label: str, figures: dict, written: dict) -> str:
    after = figures["after_signal"]
    return (f"| {label} | {written['steps']} | {written['nodes']} | {written['mb']:.2f} | "
            f"{figures['rss_mb']:.0f} | {figures['cpu']:.2f} | {figures['wall']:.2f} | "
            f"{'-' if after is None else f'{after:.2f}'} | {figures['code']} | "
            f"{written['status']} | {written['dominant']} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--after", type=float, default=10.0, help="seconds before SIGINT")
    parser.add_argument("--steps", type=int, default=10_000_000,
                        help="steps of the thinned march (default 1e7)")
    args = parser.parse_args()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}; "
          f"{os.cpu_count()} cores")
    print("| run | steps | nodes kept | folder MB | peak RSS MB | CPU s | wall s | "
          "exit after SIGINT s | exit | status | dominant part |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    long = ["--set", "t_end=1e7"]
    cases = [
        (f"{args.steps:.0e} steps, --keep-every 1000",
         [*long, "--max-steps", str(args.steps), "--keep-every", "1000"], {}),
        ("1e6 steps, every node", [*long, "--max-steps", "1000000"], {}),
        ("1e6 steps, --keep-every 1000", [*long, "--max-steps", "1000000", "--keep-every",
                                          "1000"], {}),
        (f"t_end=1e7 (as issued), SIGINT to the group at {args.after:g} s", long,
         {"signal_after": args.after}),
        (f"t_end=1e7 (as issued), SIGINT to the parent at {args.after:g} s", long,
         {"signal_after": args.after, "group": False}),
        (f"t_end=1e7, --max-steps 1e9 (still marching), SIGINT to the group at "
         f"{args.after:g} s", [*long, "--max-steps", "1000000000"],
         {"signal_after": args.after}),
        (f"t_end=1e7, --max-steps 1e9, --keep-every 1000, SIGINT to the group at "
         f"{args.after:g} s", [*long, "--max-steps", "1000000000", "--keep-every", "1000"],
         {"signal_after": args.after}),
    ]
    verdicts = []
    with tempfile.TemporaryDirectory() as scratch:
        for i, (label, argv, how) in enumerate(cases):
            out = Path(scratch) / f"run{i}"
            figures = run(command(argv, out), **how)
            written = folder(out)
            print(line(label, figures, written), flush=True)
            if i == 0:
                verdicts.append(f"a {args.steps:.0e}-step march keeping every 1000th node "
                                f"wrote {written['mb']:.2f} MB (target < {TARGET_MB:g} MB)")
            if figures["after_signal"] is not None:
                verdicts.append(f"{label}: exit {figures['after_signal']:.2f} s after the "
                                f"signal (target {TARGET_EXIT_S:g} s plus the writing)")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for text in verdicts:
        print("- " + text)


if __name__ == "__main__":
    main()
