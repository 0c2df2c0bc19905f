"""IPOPT on the whole action at growing N, beside the default Newton and a hand-written CasADi
Opti + IPOPT script (``opti_bvp.py``), measured side by side in one run.

The problem is ``bench_bvp.py``'s pendulum: ``q(0) = 0.5``, ``q(18)`` the end of a fixed-step
march from ``p(0) = 0.5``, vddvp, N nodes. Three processes per N, each timed as a whole (user +
system CPU and peak memory of that process, from ``wait4``; wall beside):

- ``ddvp bvp pendulum --solver ipopt`` (the command line, every phase: the fixed-step starts,
  then the released times);
- ``ddvp bvp pendulum --solver newton`` (the default path);
- ``opti_bvp.py`` from the point ddvp_nlp's released phase starts from (written to a file by a
  fourth process, not timed): the same rows divided by the mean step, IPOPT with its defaults
  but the tolerance.

Printed: one row per process, the ratios IPOPT / Opti and IPOPT / Newton (CPU and wall), the
growth of ddvp IPOPT's CPU time per iteration from the smallest to the largest N (``N^x``), the
targets of issue 29 (1e6: IPOPT <= 40 s CPU and <= 4 GB, verified; within 1.5x of Opti at 1e5
and 1e6; per iteration at most N^1.1; Newton 1e6 <= 10 s, <= 700 MB) and the load average at
the start and the end.

    python scripts/benchmarks/bench_ipopt.py           (N = 1e4, 1e5, 1e6: about 5 minutes alone)
    python scripts/benchmarks/bench_ipopt.py --sizes 10000,100000
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
T_END = 18.0


def end_position() -> float:
    from ddvp_nlp import load_scene, march

    run = march(load_scene("pendulum").system, [0.5], [0.5], (0.0, T_END), tau0=0.01,
                scheme="fixed")
    return float(run.q[-1, 0])


def child(command: list[str]) -> dict:
    """Run ``command``; its output, exit code, wall seconds, CPU seconds (user + system) and
    peak memory (MB) as the kernel accounted that one process."""
    started = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               text=True)
    out = process.stdout.read()
    _, status, usage = os.wait4(process.pid, 0)
    process.returncode = os.waitstatus_to_exitcode(status)
    return {"out": out, "code": process.returncode, "wall": time.perf_counter() - started,
            "cpu": usage.ru_utime + usage.ru_stime, "user": usage.ru_utime,
            "system": usage.ru_stime, "mb": usage.ru_maxrss / 1024}


def write_start(nodes: int, q_end: float, path: str) -> None:
    """The point the released phase of ``solve_bvp`` starts from (its default start, by Newton),
    as ``t``, ``q``, ``p`` in ``path``: the fixed-step problem on uniform times, then on the
    times its solution predicts (``predicted_times``), each solved by ``solve_bvp`` with fixed
    steps, the two start phases the package runs before it releases the times."""
    from ddvp_nlp import GridOptions, load_scene, solve_bvp
    from ddvp_nlp.solvers.bvp import predicted_times

    system = load_scene("pendulum").system
    newton = GridOptions(solver="newton")
    uniform = solve_bvp(system, [0.5], [q_end], (0.0, T_END), nodes=nodes, scheme="fixed",
                        options=newton)
    times = predicted_times(system, uniform.t, uniform.q, uniform.p,
                            system.parameter_vector(None))
    moved = {"t": times, **{name: np.column_stack([np.interp(times, uniform.t, column)
                                                    for column in getattr(uniform, name).T])
                            for name in ("q", "p")}}
    start = solve_bvp(system, [0.5], [q_end], (0.0, T_END), nodes=nodes, scheme="fixed",
                      times=times, guess=moved, options=newton)
    np.savez(path, t=start.t, q=start.q, p=start.p)


def ddvp_row(nodes: int, solver: str, q_end: float, folder: str) -> dict:
    out = f"{folder}/{solver}-{nodes}"
    run = child([sys.executable, "-m", "ddvp_nlp.cli", "bvp", "pendulum", "--nodes", str(nodes),
                 "--solver", solver, "--set", f"t_end={T_END}", "--set", f"q_end={q_end!r}",
                 "--no-plot", "--out", out])
    meta = json.loads((Path(out) / "meta.json").read_text()) \
        if (Path(out) / "meta.json").exists() else {}
    message = meta.get("message", run["out"][-300:])
    last = re.search(r"; (\d+) iterations", message)
    total = int(meta.get("newton_iterations", -1))
    final = int(last.group(1)) if last else -1
    return {"N": nodes, "who": f"ddvp {solver}", "status": meta.get("status", "error"),
            "phases": [total - final, final], "iterations": total,
            "verified": "verified" in message,
            "inner": sum((meta.get("timing") or {}).get(k, 0.0) for k in ("build_s", "solve_s")),
            **run}


def opti_row(nodes: int, q_end: float, folder: str) -> dict:
    start = f"{folder}/start-{nodes}.npz"
    made = child([sys.executable, __file__, "--write-start", str(nodes), repr(q_end), start])
    if made["code"] != 0:
        raise RuntimeError(made["out"])
    run = child([sys.executable, str(HERE / "opti_bvp.py"), str(nodes), "--q-end", repr(q_end),
                 "--start", start])
    result = json.loads(run["out"].strip().splitlines()[-1]) if run["code"] == 0 else {}
    return {"N": nodes, "who": "opti (hand-written)", "status": result.get("status", "error"),
            "phases": [result.get("iterations", -1)], "iterations": result.get("iterations", -1),
            "verified": result.get("canonical", 1) <= 1e-10, **run}


def print_rows(rows) -> None:
    print("| N | solver | status | iterations (starts + final) | CPU s (user + sys) | wall s | "
          "peak MB | CPU s / iteration | solve's own s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        per = r["cpu"] / max(1, r["iterations"])
        print(f"| {r['N']:.0e} | {r['who']} | {r['status']} | {r['iterations']} "
              f"({' + '.join(map(str, r['phases']))}) | {r['cpu']:.2f} ({r['user']:.2f} + "
              f"{r['system']:.2f}) | {r['wall']:.2f} | {r['mb']:.0f} | {per:.3g} | "
              f"{r.get('inner', float('nan')):.2f} |", flush=True)


def summary(rows) -> None:
    by = {(r["N"], r["who"]): r for r in rows}
    sizes = sorted({r["N"] for r in rows})
    print()
    for nodes in sizes:
        ipopt, opti, newton = (by.get((nodes, w)) for w in
                               ("ddvp ipopt", "opti (hand-written)", "ddvp newton"))
        if ipopt and opti:
            print(f"N = {nodes:.0e}: ddvp IPOPT / hand-written Opti = "
                  f"{ipopt['cpu'] / opti['cpu']:.2f} CPU, {ipopt['wall'] / opti['wall']:.2f} "
                  f"wall (target <= 1.5 at 1e5 and 1e6)")
        if ipopt and newton:
            print(f"N = {nodes:.0e}: ddvp IPOPT / ddvp Newton = "
                  f"{ipopt['cpu'] / newton['cpu']:.2f} CPU, "
                  f"{ipopt['wall'] / newton['wall']:.2f} wall")
    ipopts = [by[(n, "ddvp ipopt")] for n in sizes if (n, "ddvp ipopt") in by and n > 100]
    if len(ipopts) >= 2:
        sizes_log = np.log([r["N"] for r in ipopts])
        whole = np.polyfit(sizes_log, np.log([r["cpu"] / max(1, r["iterations"])
                                              for r in ipopts]), 1)[0]
        inner = np.polyfit(sizes_log, np.log([r["inner"] / max(1, r["iterations"])
                                              for r in ipopts]), 1)[0]
        base = by.get((100, "ddvp ipopt"), {"cpu": 0.0})["cpu"]
        beyond = np.polyfit(sizes_log, np.log([(r["cpu"] - base) / max(1, r["iterations"])
                                               for r in ipopts]), 1)[0]
        print(f"ddvp IPOPT: time per iteration grows like N^{beyond:.2f} (CPU beyond the "
              f"{base:.2f} s of a run at N = 100: start-up), N^{whole:.2f} (whole processes' "
              f"CPU), N^{inner:.2f} (the solve's own build + solve seconds, wall: waiting "
              f"included on a loaded machine) from N = {ipopts[0]['N']:.0e} to "
              f"{ipopts[-1]['N']:.0e} (target: at most N^1.1)")
    big = by.get((1_000_000, "ddvp ipopt"))
    if big:
        print(f"1e6 IPOPT: {big['cpu']:.1f} s CPU (target <= 40), {big['mb'] / 1024:.2f} GB "
              f"(target <= 4), {'verified' if big['verified'] else 'NOT verified'}")
    big = by.get((1_000_000, "ddvp newton"))
    if big:
        print(f"1e6 Newton: {big['cpu']:.1f} s CPU (target <= 10), {big['mb']:.0f} MB "
              f"(target <= 700)")


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--write-start":
        write_start(int(sys.argv[2]), float(sys.argv[3]), sys.argv[4])
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="10000,100000,1000000")
    parser.add_argument("--no-opti", action="store_true", help="leave out the Opti reference")
    args = parser.parse_args()
    sizes = [int(float(s)) for s in args.sizes.split(",")]
    print(f"load average at the start: {os.getloadavg()}", flush=True)
    q_end = end_position()
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        # the start-up a process pays whatever N (imports, scene, a tiny solve)
        rows.append(ddvp_row(100, "ipopt", q_end, folder))
        for nodes in sizes:
            rows.append(ddvp_row(nodes, "ipopt", q_end, folder))
            if not args.no_opti:
                rows.append(opti_row(nodes, q_end, folder))
            rows.append(ddvp_row(nodes, "newton", q_end, folder))
            print(f"N = {nodes:.0e} done, load {os.getloadavg()}", file=sys.stderr, flush=True)
    print_rows(rows)
    summary(rows)
    print(f"\nload average at the end: {os.getloadavg()}")
    from ddvp_nlp.io import machine

    print(f"machine: {machine()}")


if __name__ == "__main__":
    main()
