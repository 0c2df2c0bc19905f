"""Fixed-endpoint solver at growing N: build and solve time, iterations, residuals, peak memory.

The autonomous pendulum over about 2.7 periods (t in [0, 18], q(0) = 0.5, q(18) from a march
with p(0) = 0.5), solved from the default start (fixed steps from uniform motion, then the times
released) with the vddvp rule. Each N runs in its own process so that its peak memory is its own.

    python scripts/bench_bvp.py [N ...]        (default: 1000 10000 100000)
"""

from __future__ import annotations

import json
import platform
import resource
import subprocess
import sys

import numpy as np


def one(nodes: int, solver: str) -> dict:
    from ddvp_nlp import load_scene, march
    from ddvp_nlp.solvers.bvp import solve_bvp

    system = load_scene("pendulum").system
    reference = march(system, [0.5], [0.5], tau0=0.01, t_end=18.0, scheme="fixed")
    solution = solve_bvp(system, [0.5], reference.q[-1], (0.0, 18.0), nodes=nodes,
                         solver=solver)
    phases = solution.stats["phases"]
    return {"N": nodes, "solver": solver, "status": solution.status.code,
            "build_s": solution.timing["build_s"], "solve_s": solution.timing["solve_s"],
            "iterations": [ph["iterations"] for ph in phases],
            "canonical": solution.stats["canonical_residual_max"],
            "energy": solution.stats["energy_residual_max"],
            "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def main(argv: list[str]) -> None:
    if argv and argv[0] == "--one":
        print(json.dumps(one(int(argv[1]), argv[2])))
        return
    sizes = [int(a) for a in argv] or [1000, 10_000, 100_000]
    rows = []
    for solver in ("ipopt", "newton"):
        for nodes in sizes:
            out = subprocess.run([sys.executable, __file__, "--one", str(nodes), solver],
                                 check=True, capture_output=True, text=True).stdout
            rows.append(json.loads(out.strip().splitlines()[-1]))
            print(f"{solver} N={nodes}: {rows[-1]['status']}", file=sys.stderr, flush=True)
    print("| solver | N | status | build s | solve s | iterations (3 phases) | s / iteration "
          "| max canonical residual | max energy residual | peak MB |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        r["per_iteration"] = r["solve_s"] / max(1, sum(r["iterations"]))
        print(f"| {r['solver']} | {r['N']} | {r['status']} | {r['build_s']:.2f} | "
              f"{r['solve_s']:.3f} | {' + '.join(map(str, r['iterations']))} | "
              f"{r['per_iteration']:.4f} | {r['canonical']:.1e} | {r['energy']:.1e} | "
              f"{r['peak_mb']:.0f} |")
    print()
    for solver in ("ipopt", "newton"):
        mine = [r for r in rows if r["solver"] == solver]
        if len(mine) >= 2:
            exponent = np.polyfit(np.log([r["N"] for r in mine]),
                                  np.log([r["per_iteration"] for r in mine]), 1)[0]
            print(f"{solver}: time per iteration grows like N^{exponent:.2f} "
                  f"(N = {mine[0]['N']} .. {mine[-1]['N']}; target: at most N^1.2)")
    for nodes in sizes:
        pair = {r["solver"]: r for r in rows if r["N"] == nodes}
        print(f"N = {nodes}: solve time ipopt / newton = "
              f"{pair['ipopt']['solve_s'] / pair['newton']['solve_s']:.1f}")
    import casadi
    print(f"\nmachine: {platform.machine()}, {platform.processor() or 'cpu'}, "
          f"python {platform.python_version()}, casadi {casadi.__version__}, "
          f"numpy {np.__version__}")


if __name__ == "__main__":
    main(sys.argv[1:])
