"""Periodic orbits of the Henon-Heiles potential at E = 1/8 through the section x = 0 (crossing
with x' > 0): how many ``find_periodic_orbits`` finds against a dense independent search, side
by side, and which of the dense search's orbits it missed.

The independent search shares nothing with the package but the Hamiltonian: scipy's DOP853
(``solve_ivp`` with an event at x = 0, rtol 1e-12) carries every point of a fine grid of the
section's accessible region to its returns, and from each grid minimum of ``|P^k(u) - u|``
scipy's ``root`` (hybr, finite differences) solves ``P^k(u) = u``; converged points are closed
over their period, covers reduced to their primitive orbit and duplicates (same period, a shared
crossing) kept once.

Run: python scripts/checks/search_count.py [--grid 60] [--returns 2] [--period 15]
"""

from __future__ import annotations

import argparse
import time

import casadi as ca
import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import root

from ddvp_nlp import HamiltonianSystem, find_periodic_orbits

ENERGY = 1 / 8


def hamiltonian(q, p, t):
    return ca.sumsqr(p) / 2 + ca.sumsqr(q) / 2 + q[0] ** 2 * q[1] - q[1] ** 3 / 3


def field(_t, z):
    x, y, px, py = z
    return [px, py, -x - 2 * x * y, -y - x * x + y * y]


def crossing(_t, z):
    return z[0]


crossing.direction = 1.0


def start(u):
    """(0, y, px, py) at E with px > 0, or None."""
    y, py = u
    kinetic = 2 * (ENERGY - y * y / 2 + y ** 3 / 3) - py * py
    return None if kinetic < 0 else np.array([0.0, y, np.sqrt(kinetic), py])


def returns(u, count: int, horizon: float):
    """(times, points u) of the first ``count`` upward crossings of x = 0 from ``u``."""
    z0 = start(u)
    if z0 is None:
        return None
    run = solve_ivp(field, (0, horizon), z0, method="DOP853", rtol=1e-12, atol=1e-12,
                    events=crossing)
    t, z = run.t_events[0], run.y_events[0]
    keep = t > 1e-9
    return t[keep][:count], z[keep][:count, [1, 3]]


def dense_search(grid: int, count: int, horizon: float):
    ys, pys = np.linspace(-0.5, 0.75, grid), np.linspace(-0.5, 0.5, grid)
    images = np.full((grid, grid, count, 2), np.nan)
    times = np.full((grid, grid, count), np.nan)
    for i, y in enumerate(ys):
        for j, py in enumerate(pys):
            found = returns((y, py), count, horizon)
            if found is not None and found[0].size:
                k = found[0].size
                images[i, j, :k], times[i, j, :k] = found[1], found[0]
    orbits = []
    for k in range(count):
        U = np.stack(np.meshgrid(ys, pys, indexing="ij"), axis=-1)
        gap = np.max(np.abs(images[:, :, k] - U), axis=-1)
        gap = np.where(np.isfinite(gap), gap, np.inf)
        padded = np.pad(gap, 1, constant_values=np.inf)
        for i in range(grid):
            for j in range(grid):
                if gap[i, j] < 0.5 and gap[i, j] <= padded[i:i + 3, j:j + 3].min():
                    orbit = _newton(U[i, j], k + 1, times[i, j, k])
                    if orbit is not None:
                        orbits.append(orbit)
    return _distinct(orbits)


def _newton(u0, k, t_guess):
    def residual(u):
        found = returns(u, k, 1.5 * t_guess)
        if found is None or found[0].size < k:
            return np.full(2, 1e3)
        return found[1][k - 1] - u
    solution = root(residual, u0, method="hybr", options={"xtol": 1e-12})
    if not solution.success or np.max(np.abs(residual(solution.x))) > 1e-9:
        return None
    t, u = returns(solution.x, k, 1.5 * t_guess)
    period = t[k - 1]
    for j in range(k - 1):  # a cover: the start comes back sooner
        if np.max(np.abs(u[j] - solution.x)) < 1e-6:
            period = t[j]
            break
    crossings = [solution.x] + [row for row, time in zip(u, t, strict=True)
                                if time < period * (1 - 1e-9)]
    return period, np.array(crossings)


def _distinct(orbits):
    kept = []
    for period, crossings in sorted(orbits, key=lambda o: o[0]):
        if not any(abs(period - p) < 1e-6 * p and np.min(np.max(np.abs(c - crossings[0]),
                                                                axis=1)) < 1e-5
                   for p, c in kept):
            kept.append((period, crossings))
    return kept


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--grid", type=int, default=60, help="dense grid side (default 60)")
    parser.add_argument("--returns", type=int, default=2, help="upward returns (default 2)")
    parser.add_argument("--period", type=float, default=15.0, help="period bound (default 15)")
    parser.add_argument("--seeds", type=int, default=400, help="the package's seeds")
    args = parser.parse_args()
    system = HamiltonianSystem(hamiltonian, n=2, name="henon_heiles")
    ours, costs = {}, {}
    for reversing in ("none", "auto"):  # the whole map; + half orbits (x -> -x is a symmetry)
        wall, cpu = time.perf_counter(), time.process_time()
        search = find_periodic_orbits(system, energy=ENERGY, section="q1=0", seeds=args.seeds,
                                      max_returns=args.returns, reversing=reversing,
                                      refine=False)
        ours[reversing] = sorted(o.period for o in search.orbits if o.period <= args.period)
        costs[reversing] = time.perf_counter() - wall, time.process_time() - cpu
    wall, cpu = time.perf_counter(), time.process_time()
    dense = [p for p, _ in dense_search(args.grid, args.returns, 3 * args.period)
             if p <= args.period]
    dense_cost = time.perf_counter() - wall, time.process_time() - cpu
    print(f"Henon-Heiles, E = 1/8, section x = 0 (x' > 0), up to {args.returns} returns, "
          f"period <= {args.period:g}")
    print(f"{'search':44s} {'orbits':>6s} {'CPU s':>8s} {'wall s':>8s}")
    for reversing, label in (("none", "whole return map"),
                             ("auto", "half orbits and the whole map")):
        print(f"{f'find_periodic_orbits, {label}':44s} {len(ours[reversing]):6d} "
              f"{costs[reversing][1]:8.1f} {costs[reversing][0]:8.1f}")
    print(f"{'scipy DOP853 + root (' + str(args.grid) + '^2 grid)':44s} {len(dense):6d} "
          f"{dense_cost[1]:8.1f} {dense_cost[0]:8.1f}")
    ours = ours["none"]
    missed = [p for p in dense if not any(abs(p - q) < 1e-6 * p for q in ours)]
    extra = [q for q in ours if not any(abs(p - q) < 1e-6 * p for p in dense)]
    print(f"periods found by the dense search and not by the whole-map search: "
          f"{[round(p, 8) for p in missed] or 'none'}")
    print(f"periods found by the whole-map search and not by the dense search: "
          f"{[round(p, 8) for p in extra] or 'none'}")


if __name__ == "__main__":
    main()
