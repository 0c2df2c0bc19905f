"""Periodic orbits of constrained systems (issue 48, ``solve_periodic`` on ``constraints=``),
measured side by side in one run:

1. the spherical pendulum's conical orbit at polar angles 0.3, 0.6, 1.1 for N = 20 ... 320:
   the period's error against ``2 pi / w`` (``w^2 = g / (L cos theta0)``), its order between
   successive N, the unfolding parameter, Newton's iterations, CPU beside wall per solve;
   and the multipliers (``periodic_stability``: the exact flow on the manifold) against
   ``2 cos(2 pi sqrt(1 + 3 cos^2 theta0))``;
2. the Cartesian pendulum's libration at E = -0.5, 0.5 (section p1 = 0, and q1 = 0 at 0.5)
   against the angle pendulum's period ``4 K(sin^2(theta_max / 2))``: the same columns, the
   solver that found it and the verdict.

    python scripts/benchmarks/bench_constrained_periodic.py
"""

from __future__ import annotations

import time

import numpy as np
from scipy.special import ellipk

from ddvp_nlp import HamiltonianSystem, periodic_stability, solve_periodic
from ddvp_nlp.io import machine

COUNTS = (20, 40, 80, 160, 320)


def sphere_h(q, p, t):
    return (p[0] ** 2 + p[1] ** 2 + p[2] ** 2) / 2 + q[2]


SPHERICAL = HamiltonianSystem(sphere_h, 3, name="spherical",
                              constraints=lambda q, t: q[0] ** 2 + q[1] ** 2 + q[2] ** 2 - 1)
CARTESIAN = HamiltonianSystem(lambda q, p, t: (p[0] ** 2 + p[1] ** 2) / 2 + q[1], 2,
                              name="cartesian",
                              constraints=lambda q, t: q[0] ** 2 + q[1] ** 2 - 1)


def timed(call):
    wall, cpu = time.perf_counter(), time.process_time()
    result = call()
    return result, time.perf_counter() - wall, time.process_time() - cpu


def table(system, energy, period, section, start, counts=COUNTS):
    print(f"{'N':>5} {'status':>12} {'verdict':>10} {'period error':>13} {'order':>6} "
          f"{'unfolding':>10} {'iter':>5} {'solver':>7} {'cpu s':>7} {'wall s':>7}")
    last = None
    for N in counts:
        solution, wall, cpu = timed(lambda N=N: solve_periodic(
            system, energy=energy, nodes=N + 1, section=section, start=start))
        error = abs(solution.orbit.period - period) / period
        order = np.log(last / error) / np.log(2) if last else float("nan")
        last = error
        verdict = solution.verdict.name if solution.verdict is not None else "-"
        print(f"{N:5d} {solution.status.code:>12} {verdict:>10} {error:13.3e} {order:6.3f} "
              f"{solution.orbit.unfolding:10.1e} {solution.stats['iterations_total']:5d} "
              f"{solution.stats['solver']:>7} {cpu:7.3f} {wall:7.3f}")
    return solution


def main() -> None:
    print("1. spherical pendulum, conical orbits (section q2 = 0)")
    for theta0 in (0.3, 0.6, 1.1):
        w = np.sqrt(1 / np.cos(theta0))
        energy = 0.5 * (w * np.sin(theta0)) ** 2 - np.cos(theta0)
        start = ([np.sin(theta0), 0.0, -np.cos(theta0)], [0.0, 1.0, 0.0])
        print(f"theta0 = {theta0}: E = {energy:.10g}, T = {2 * np.pi / w:.12g}")
        solution = table(SPHERICAL, energy, 2 * np.pi / w, "q2=0", start)
        stability, wall, cpu = timed(lambda s=solution: periodic_stability(SPHERICAL, s))
        expected = 2 * np.cos(2 * np.pi * np.sqrt(1 + 3 * np.cos(theta0) ** 2))
        print(f"  multipliers: index {stability.indices[0].real:.12f}, closed form "
              f"{expected:.12f}, difference {abs(stability.indices[0] - expected):.1e}; "
              f"trivial {np.round(stability.trivial.real, 9)}, {stability.verdict}; exact "
              f"period error {abs(stability.extra['exact_period'] * w / (2 * np.pi) - 1):.1e};"
              f" cpu {cpu:.3f} s, wall {wall:.3f} s")
    print("\n2. Cartesian pendulum, librations (start at the bottom)")
    for energy, section in ((-0.5, "p1=0"), (0.5, "p1=0"), (0.5, "q1=0")):
        amplitude = np.arccos(-energy)
        period = 4 * ellipk(np.sin(amplitude / 2) ** 2)
        print(f"E = {energy}, section {section}: amplitude {amplitude:.6f}, T = {period:.12g}")
        table(CARTESIAN, energy, period, section, ([0.0, -1.0], [1.0, 0.0]),
              counts=(40, 80, 160, 320))
    print()
    print(machine())


if __name__ == "__main__":
    main()
