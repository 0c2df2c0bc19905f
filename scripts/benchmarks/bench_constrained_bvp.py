"""Fixed ends of a constrained system (issue 48): the Cartesian pendulum's rotation from angle 0
to 2.5 in one time unit, ``solve_bvp`` with ``fixed`` and ``vddvp`` steps, by the grid's Newton
(sparse LU) and by IPOPT on the same rows, side by side in one process: status, verdict, the
largest trajectory error against the continuous constrained solution, |g| and the hidden
constraint, iterations, CPU and wall seconds, and IPOPT's CPU over Newton's.

    python scripts/benchmarks/bench_constrained_bvp.py                 # N = 1001, 10001
    python scripts/benchmarks/bench_constrained_bvp.py --sizes 201     # quick
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from ddvp_nlp import GridOptions, HamiltonianSystem, solve_bvp
from ddvp_nlp.io import machine


def hamiltonian(q, p, t):
    return (p[0] ** 2 + p[1] ** 2) / 2 + q[1]


def rod(q, t):
    return q[0] ** 2 + q[1] ** 2 - 1


def point(angle):
    return np.array([np.sin(angle), -np.cos(angle)])


def run(system, nodes: int, scheme: str, solver: str) -> dict:
    cpu, wall = time.process_time(), time.perf_counter()
    solution = solve_bvp(system, point(0.0), point(2.5), (0.0, 1.0), nodes=nodes,
                         scheme=scheme, options=GridOptions(solver=solver))
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    record = solution.constraints
    return {"status": solution.status.name.lower(),
            "verdict": solution.verdict.name if solution.verdict else "-",
            "error": solution.verdict.error_max if solution.verdict else float("nan"),
            "g": record.constraint_residual.max(), "hidden": record.hidden_residual.max(),
            "iterations": solution.stats["iterations_total"], "cpu": cpu, "wall": wall}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="1001,10001", help="node counts, comma-separated")
    parser.add_argument("--schemes", default="fixed,vddvp")
    args = parser.parse_args()
    system = HamiltonianSystem(hamiltonian, 2, name="cartesian", constraints=rod)
    for scheme in args.schemes.split(","):  # the blocks built once, before any is timed
        for solver in ("newton", "ipopt"):
            run(system, 21, scheme, solver)
    print("| N | scheme | solver | status | verdict | error / S | max abs g | max hidden | "
          "iterations | CPU s | wall s | CPU / Newton's |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for nodes in (int(v) for v in args.sizes.split(",")):
        for scheme in args.schemes.split(","):
            newton_cpu = None
            for solver in ("newton", "ipopt"):
                r = run(system, nodes, scheme, solver)
                newton_cpu = r["cpu"] if solver == "newton" else newton_cpu
                print(f"| {nodes} | {scheme} | {solver} | {r['status']} | {r['verdict']} | "
                      f"{r['error']:.3e} | {r['g']:.1e} | {r['hidden']:.1e} | "
                      f"{r['iterations']} | {r['cpu']:.2f} | {r['wall']:.2f} | "
                      f"{r['cpu'] / newton_cpu:.2f} |", flush=True)
    print()
    print(machine())


if __name__ == "__main__":
    main()
