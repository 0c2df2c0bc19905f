"""Derivatives of grid solutions (issue 47), side by side in one run, CPU beside wall.

    python scripts/benchmarks/bench_grid_gradients.py [--nodes 100000] [--repeats 3]
                                                     [--only ends,period]

Fixed ends (``--only ends``): the pendulum ``H = p^2/2 + w^2 (1 - cos q)`` from ``q = 0.1`` to
``q = 0.5`` over two time units on ``--nodes`` nodes, ``solve_bvp`` without derivatives and
with ``derivatives=("q_end",)``, alternated, best of ``--repeats`` after a warm-up. Printed:
the solve's CPU and wall, the derivatives' own (the factorisation at the solution and the
forward solves, ``derivatives_cpu_s``), their directional checks' and the whole call's, and
the ratios to the solve (target: all derivatives in ``q_end`` for at most 2x the solve's CPU).

Period (``--only period``): ``dT/dw`` of the pendulum's discrete orbit at (E, w) = (0.5, 1),
(1.0, 1.3), (0.3, 0.8) against the closed form ``-4 E(m) / (w^2 (1 - m))``, ``m = E / (2
w^2)``, at N = 100, 200, 400 intervals, and the order fitted to the errors (target 2.00 +-
0.05); Kepler's ``dT/dmu`` at E = -0.5 against ``2 pi (-2E)^(-3/2)``.
"""

from __future__ import annotations

import argparse
import time

import casadi as ca
import numpy as np
from scipy.special import ellipe

from ddvp_nlp import HamiltonianSystem, solve_bvp, solve_periodic
from ddvp_nlp.io import machine


def pendulum():
    def H(q, p, t, w):
        return p[0] ** 2 / 2 + w ** 2 * (1 - ca.cos(q[0]))
    return HamiltonianSystem(H, 1, {"w": 1.0}, name="pendulum_w")


def kepler():
    def H(q, p, t, mu):
        return (p[0] ** 2 + p[1] ** 2) / 2 - mu / ca.sqrt(q[0] ** 2 + q[1] ** 2)
    return HamiltonianSystem(H, 2, {"mu": 1.0}, name="kepler_mu")


def clocked(call):
    wall, cpu = time.perf_counter(), time.process_time()
    value = call()
    return value, time.process_time() - cpu, time.perf_counter() - wall


def ends(nodes: int, repeats: int) -> None:
    system = pendulum()

    def solve(derivatives=None):
        return solve_bvp(system, [0.1], [0.5], (0.0, 2.0), nodes=nodes,
                         derivatives=derivatives)
    solve(), solve("q_end")  # warm: builds and compiles
    plain, deriv = [], []
    for _ in range(repeats):
        plain.append(clocked(solve))
        deriv.append(clocked(lambda: solve("q_end")))
    best_plain = min(plain, key=lambda r: r[1])
    best = min(deriv, key=lambda r: r[1])
    d = best[0].derivatives
    checks_cpu = sum(c["cpu_s"] for c in d["checks"].values())
    print(f"## fixed ends: pendulum, {nodes} nodes, derivatives in q_end "
          f"(best of {repeats}, warm)\n")
    print("| what | CPU s | wall s | CPU / solve's CPU |")
    print("|---|---|---|---|")
    solve_cpu, solve_wall = best_plain[1], best_plain[2]
    rows = [("solve, no derivatives", solve_cpu, solve_wall),
            ("derivatives: factorisation and solves", d["derivatives_cpu_s"],
             d["derivatives_wall_s"]),
            ("their directional checks", checks_cpu, None),
            ("all derivative work (with checks)", d["cpu_s"], d["wall_s"]),
            ("solve with derivatives=('q_end',)", best[1], best[2])]
    for label, cpu, wall in rows:
        wall_text = "-" if wall is None else f"{wall:.3f}"
        print(f"| {label} | {cpu:.3f} | {wall_text} | {cpu / solve_cpu:.2f} |")
    print(f"\nd p_end / d q_end = {d['p_end']['q_end'][0, 0]:.10g}, d p_start / d q_end = "
          f"{d['p_start']['q_end'][0, 0]:.10g}; check {d['checks']['q_end']['verdict']} "
          f"(relative error {d['checks']['q_end']['relative_error']:.2e}); error estimate "
          f"{d['error_estimate']:.2e} (nodes {d['nodes_error_estimate']:.2e})\n")


def period() -> None:
    system = pendulum()
    sizes = np.array([100, 200, 400])
    print("## dT/dw of the pendulum's discrete orbit against the closed form\n")
    print("| E | w | N | dT/dw | relative error | check | derivatives CPU s | solve CPU s |")
    print("|---|---|---|---|---|---|---|---|")
    for energy, w in [(0.5, 1.0), (1.0, 1.3), (0.3, 0.8)]:
        m = energy / (2 * w ** 2)
        exact = -4 * ellipe(m) / (w ** 2 * (1 - m))
        errors = []
        for N in sizes:
            orbit, cpu, _ = clocked(lambda energy=energy, N=N, w=w: solve_periodic(
                system, energy=energy, nodes=N + 1, params={"w": w}, derivatives="params"))
            d = orbit.derivatives
            value = d["period"]["params"][0]
            errors.append(abs(value - exact) / abs(exact))
            print(f"| {energy} | {w} | {N} | {value:.12g} | {errors[-1]:.3e} | "
                  f"{d['checks']['params']['verdict']} | {d['derivatives_cpu_s']:.4f} | "
                  f"{cpu:.3f} |")
        order = -np.polyfit(np.log(sizes), np.log(errors), 1)[0]
        print(f"| | | order | **{order:.3f}** | | | | |")
    energy = -0.5
    exact = 2 * np.pi * (-2 * energy) ** -1.5
    print(f"\n## Kepler dT/dmu at E = {energy} against 2 pi (-2E)^(-3/2) = {exact:.12g}\n")
    print("| N | dT/dmu | relative error | check | error estimate | nodes' estimate |")
    print("|---|---|---|---|---|---|")
    for N in sizes:
        orbit = solve_periodic(kepler(), energy=energy, nodes=N + 1, section="q2=0",
                               start=([1, 0], [0, 1]),
                               integrals=(lambda q, p: q[0] * p[1] - q[1] * p[0],),
                               derivatives="params")
        d = orbit.derivatives
        value = d["period"]["params"][0]
        print(f"| {N} | {value:.12g} | {abs(value - exact) / exact:.3e} | "
              f"{d['checks']['params']['verdict']} | {d['error_estimate']:.1e} | "
              f"{d['nodes_error_estimate']:.1e} |")
    print()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", default="ends,period")
    args = parser.parse_args()
    only = set(args.only.split(","))
    if "ends" in only:
        ends(args.nodes, args.repeats)
    if "period" in only:
        period()
    print(machine())


if __name__ == "__main__":
    main()
