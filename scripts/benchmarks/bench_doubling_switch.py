"""Branch switching at a period doubling of Henon-Heiles' axis family, checked against an
independent shooting of the doubled orbits, side by side in one run.

    python scripts/benchmarks/bench_doubling_switch.py [--orbits 20] [--nodes 201 401]

The orbit on the axis ``x = 0`` (the scene's section ``py = 0``, its start) is followed from
E = 0.13 towards 0.14 (step 0.005) to its first period doubling (E = 0.13529 on the exact flow),
where ``follow_periodic_family`` with ``Continuation(step=0.005, switch=Switch(orbits))`` takes
the direction on the grid of the orbit traversed twice and follows the branch of period near
``2T`` (``solvers/periodic/doubling.py``). Every orbit of the branch is then shot by
``doubled_shooting.py`` (scipy's DOP853 and the variational equations, nothing of the package)
from its node 0: once at its energy (the period compared: ``T - T_sh``) and once through its
``x0`` (the energy compared: ``E - E_sh``). Each shot orbit's ``|phi_{T/2}(z0) - z0|`` shows it is
not the axis orbit traversed twice. Run at each ``--nodes``; the gaps' ratio between the first
two grids is printed (order 2: about 4 from N to 2N). CPU beside wall.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from doubled_shooting import shoot  # noqa: E402

from ddvp_nlp import Continuation, Switch, follow_periodic_family, load_scene  # noqa: E402
from ddvp_nlp.io import machine  # noqa: E402


def switched(orbits: int, nodes: int):
    """The followed axis family with its doubled branch, and the CPU and wall seconds."""
    scene = load_scene("henon_heiles")
    settings = scene.periodic
    cpu, wall = time.process_time(), time.perf_counter()
    family = follow_periodic_family(
        scene.system, (0.13, 0.14), nodes=nodes, section=settings.section,
        start=settings.start, continuation=Continuation(step=0.005, switch=Switch(orbits=orbits)))
    return family, time.process_time() - cpu, time.perf_counter() - wall


def compared(member) -> dict:
    """One doubled orbit beside its two shootings (module docstring)."""
    orbit = member.orbit
    x0, y0, px0 = orbit.q[0, 0], orbit.q[0, 1], orbit.p[0, 0]
    period, level = float(orbit.orbit.period), float(member.energy)
    at_energy = shoot(x0, y0, px0, period, energy_level=level)
    through = shoot(x0, y0, px0, period)
    return {"E": level, "x0": x0, "xmax": float(np.max(np.abs(orbit.q[:, 0]))), "T": period,
            "T_sh": at_energy.period, "dT": period - at_energy.period, "E_sh": through.energy,
            "dE": level - through.energy, "half": at_energy.half,
            "iterations": (at_energy.iterations, through.iterations)}


def report(orbits: int, nodes: int) -> dict:
    family, cpu, wall = switched(orbits, nodes)
    print(f"\nN = {nodes - 1}: {family.message}; {len(family.members)} orbits")
    for j, point in enumerate(family.bifurcations):
        print(f"bifurcation {j + 1}: {point.kind} at E = {point.energy:.10f} (exact flow "
              f"{point.extra.get('exact_energy')})")
    print(family.switched)
    print(f"follow and switch: {cpu:.1f} s CPU, {wall:.1f} s wall")
    worst = {"dT": 0.0, "dE": 0.0, "half": np.inf, "complete": True, "count": 0}
    for branch in family.branches:
        print(f"branch {branch.label}: {branch.family.message}")
        print("| # | E | x0 | max abs x | T | T_sh (same E) | T - T_sh | E_sh (same x0) | "
              "E - E_sh | shot: abs(phi_T/2 - z0) | iterations |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for j, member in enumerate(branch.family.members):
            row = compared(member)
            worst["dT"] = max(worst["dT"], abs(row["dT"]))
            worst["dE"] = max(worst["dE"], abs(row["dE"]))
            worst["half"] = min(worst["half"], row["half"])
            print(f"| {j + 1} | {row['E']:.9f} | {row['x0']:+.6f} | {row['xmax']:.6f} | "
                  f"{row['T']:.9f} | {row['T_sh']:.9f} | {row['dT']:+.2e} | "
                  f"{row['E_sh']:.9f} | {row['dE']:+.2e} | {row['half']:.2e} | "
                  f"{row['iterations']} |")
        worst["complete"] &= branch.family.complete
        worst["count"] += len(branch.family.members)
    print(f"largest abs(T - T_sh) {worst['dT']:.2e}, abs(E - E_sh) {worst['dE']:.2e}; "
          f"smallest abs(phi_T/2 - z0) of the shot orbits {worst['half']:.2e}")
    return {**worst, "branches": len(family.branches), "cpu": cpu, "wall": wall}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--orbits", type=int, default=20)
    parser.add_argument("--nodes", type=int, nargs="+", default=[201, 401])
    args = parser.parse_args(argv)
    found = [report(args.orbits, nodes) for nodes in args.nodes]
    if len(found) >= 2 and found[1]["dT"] > 0 and found[1]["dE"] > 0:
        print(f"\nratio N = {args.nodes[0] - 1} to {args.nodes[1] - 1}: abs(T - T_sh) "
              f"{found[0]['dT'] / found[1]['dT']:.2f}, abs(E - E_sh) "
              f"{found[0]['dE'] / found[1]['dE']:.2f}")
    print(f"machine: {machine()}")
    good = all(f["complete"] and f["branches"] == 1 and f["count"] == args.orbits
               for f in found)
    return 0 if good else 1


if __name__ == "__main__":
    sys.exit(main())
