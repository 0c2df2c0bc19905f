"""Periodic orbits through the section x = 0 (crossing with x' > 0) found by
``find_periodic_orbits`` against a dense independent search, side by side: the Henon-Heiles
potential at E = 1/8 and the Barbanis-type potential ``(x^2 + y^2)/2 - x y^2`` at E = 0.1
(the built-in scenes ``henon_heiles`` and ``barbanis``), every orbit of period at most the bound.

The independent search shares nothing with the package but the potential, written again here by
hand: scipy's DOP853 (``solve_ivp`` with an event at x = 0, rtol 1e-12) carries every point of a
fine grid of the section's accessible region (``|p_y| <= sqrt(2 (E - V(0, y)))``, its ``y`` range
from the roots of ``V(0, y) = E`` about the well) to its upward returns, as many as the period
bound allows (the bound over the shortest first return on the grid), and from each grid minimum
of ``|P^k(u) - u|`` scipy's ``root`` (hybr, finite differences) solves ``P^k(u) = u``; converged
points are closed over their period, covers cut to their primitive orbit and duplicates (same
period, a shared crossing) kept once. The package's search is run with its defaults (and the
whole return map alone, ``reversing="none"``) to the same number of returns.

Run: python scripts/benchmarks/bench_search_count.py [--grid 60] [--period 15] [--returns 2]
     [--only henon_heiles] (quick: --grid 24 --returns 2)
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, root

from ddvp_nlp import find_periodic_orbits, load_scene
from ddvp_nlp.io import machine


class Potential:
    """``V(x, y)`` and its gradient, by hand, at an energy."""

    def __init__(self, name, energy, V, gradient):
        self.name, self.energy, self.V, self.gradient = name, energy, V, gradient

    def field(self, _t, z):
        x, y, px, py = z
        gx, gy = self.gradient(x, y)
        return [px, py, -gx, -gy]

    def start(self, u):
        """``(0, y, px, py)`` at the energy with ``px > 0``, or None."""
        y, py = u
        kinetic = 2 * (self.energy - self.V(0.0, y)) - py * py
        return None if not kinetic >= 0 else np.array([0.0, y, math.sqrt(kinetic), py])

    def box(self):
        """The ``y`` range about the well (roots of ``V(0, y) = E``) and ``max |p_y|``."""
        def level(y):
            return self.V(0.0, y) - self.energy
        lo = brentq(level, -10.0, 0.0) if level(-10.0) > 0 else -10.0
        hi = brentq(level, 0.0, 10.0) if level(10.0) > 0 else 10.0
        return (lo, hi), math.sqrt(2 * self.energy)


HENON_HEILES = Potential(
    "henon_heiles", 1 / 8, lambda x, y: (x * x + y * y) / 2 + x * x * y - y ** 3 / 3,
    lambda x, y: (x + 2 * x * y, y + x * x - y * y))
BARBANIS = Potential(
    "barbanis", 0.1, lambda x, y: (x * x + y * y) / 2 - x * y * y,
    lambda x, y: (x - y * y, y - 2 * x * y))


def returns(system: Potential, u, count: int, horizon: float):
    """(times, points u) of the first ``count`` upward crossings of x = 0 from ``u`` (the run
    stops at the last one)."""
    z0 = system.start(u)
    if z0 is None:
        return None

    def crossing(_t, z):
        return z[0]
    crossing.direction, crossing.terminal = 1.0, count + 1  # + 1: one at t = 0 is dropped
    run = solve_ivp(system.field, (0, horizon), z0, method="DOP853", rtol=1e-12, atol=1e-12,
                    events=crossing)
    t, z = run.t_events[0], run.y_events[0]
    keep = t > 1e-9
    return t[keep][:count], z[keep][:count][:, [1, 3]]


def dense_search(system: Potential, grid: int, bound: float, count: int | None):
    """The orbits of period <= ``bound`` (module docstring): (period, crossings) pairs, the
    number of returns searched (``count``, or as many as the bound allows) and the shortest
    first return."""
    (lo, hi), top = system.box()
    ys, pys = np.linspace(lo, hi, grid), np.linspace(-top, top, grid)
    first = [returns(system, (y, py), 1, 4 * bound) for y in ys for py in pys]
    shortest = min(f[0][0] for f in first if f is not None and f[0].size)
    count = count or max(int(bound // shortest), 1)
    images = np.full((grid, grid, count, 2), np.nan)
    times = np.full((grid, grid, count), np.nan)
    for i, y in enumerate(ys):
        for j, py in enumerate(pys):
            found = returns(system, (y, py), count, 3 * bound)
            if found is not None and found[0].size:
                k = found[0].size
                images[i, j, :k], times[i, j, :k] = found[1], found[0]
    U = np.stack(np.meshgrid(ys, pys, indexing="ij"), axis=-1)
    scale = np.array([hi - lo, 2 * top])
    orbits = []
    for k in range(count):
        gap = np.max(np.abs(images[:, :, k] - U) / scale, axis=-1)
        gap = np.where(np.isfinite(gap), gap, np.inf)
        padded = np.pad(gap, 1, constant_values=np.inf)
        for i in range(grid):
            for j in range(grid):
                if gap[i, j] < 0.5 and gap[i, j] <= padded[i:i + 3, j:j + 3].min():
                    orbit = _newton(system, U[i, j], k + 1, times[i, j, k])
                    if orbit is not None:
                        orbits.append(orbit)
    return [o for o in _distinct(orbits) if o[0] <= bound], count, shortest


def _newton(system, u0, k, t_guess):
    def residual(u):
        found = returns(system, u, k, 1.5 * t_guess)
        if found is None or found[0].size < k:
            return np.full(2, 1e3)
        return found[1][k - 1] - u
    solution = root(residual, u0, method="hybr", options={"xtol": 1e-12})
    if not solution.success or np.max(np.abs(residual(solution.x))) > 1e-9:
        return None
    t, u = returns(system, solution.x, k, 1.5 * t_guess)
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
        if not any(_same(period, crossings, p, c) for p, c in kept):
            kept.append((period, crossings))
    return kept


def _same(period, crossings, other_period, other_crossings, tol=1e-5):
    return abs(period - other_period) < 1e-6 * period and np.min(
        np.max(np.abs(other_crossings - crossings[0]), axis=1)) < tol


def package_search(name: str, energy: float, returns_: int, reversing: str):
    system = load_scene(name).system
    wall, cpu = time.perf_counter(), time.process_time()
    search = find_periodic_orbits(system, energy=energy, section="q1=0", max_returns=returns_,
                                  reversing=reversing, refine=False)
    cost = time.perf_counter() - wall, time.process_time() - cpu
    orbits = [(o.period, o.crossings) for o in search.orbits]
    return orbits, cost


def compare(system: Potential, grid: int, bound: float, count: int | None) -> None:
    wall, cpu = time.perf_counter(), time.process_time()
    dense, count, shortest = dense_search(system, grid, bound, count)
    dense_cost = time.perf_counter() - wall, time.process_time() - cpu
    rows = [(f"scipy DOP853 + root ({grid} x {grid} grid)", dense, dense_cost)]
    for reversing, label in (("auto", "defaults"), ("none", "whole return map alone")):
        orbits, cost = package_search(system.name, system.energy, count, reversing)
        rows.insert(len(rows) - 1, (f"find_periodic_orbits, {label}",
                                    [o for o in orbits if o[0] <= bound], cost))
    print(f"\n{system.name}, E = {system.energy:g}, section x = 0 (x' > 0), period <= {bound:g}, "
          f"up to {count} returns (the shortest first return on the grid is {shortest:.4g})")
    print(f"{'search':48s} {'orbits':>6s} {'CPU s':>8s} {'wall s':>8s}")
    for label, orbits, cost in rows:
        print(f"{label:48s} {len(orbits):6d} {cost[1]:8.1f} {cost[0]:8.1f}")
    for label, orbits, _ in rows[:-1]:
        missed = [p for p, c in dense if not any(_same(p, c, q, d, 1e-4) for q, d in orbits)]
        extra = [q for q, d in orbits if not any(_same(q, d, p, c, 1e-4) for p, c in dense)]
        print(f"  {label}: missed {[round(p, 8) for p in missed] or 'none'}; not in the dense "
              f"search {[round(p, 8) for p in extra] or 'none'}")
    print(f"  periods (dense search): {[round(p, 8) for p, _ in dense]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--grid", type=int, default=60, help="dense grid side (default 60)")
    parser.add_argument("--period", type=float, default=15.0, help="period bound (default 15)")
    parser.add_argument("--returns", type=int, default=None,
                        help="upward returns searched (default: the bound over the shortest "
                             "first return on the grid)")
    parser.add_argument("--only", default="henon_heiles,barbanis",
                        help="systems, comma-separated (default both)")
    args = parser.parse_args()
    systems = {s.name: s for s in (HENON_HEILES, BARBANIS)}
    for name in args.only.split(","):
        compare(systems[name.strip()], args.grid, args.period, args.returns)
    print(f"\nmachine: {machine()}")


if __name__ == "__main__":
    main()
