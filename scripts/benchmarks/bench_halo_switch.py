"""Branch switching onto the CR3BP's halo families, checked against an independent differential
correction, side by side in one run.

    python scripts/benchmarks/bench_halo_switch.py [--orbits 20] [--nodes 201] [--tol T]
                                                   [--figure PATH]

The Earth-Moon L1 Lyapunov family is followed from E = -1.5935 towards -1.585 (step 0.0005, the
guide's command, on the scene's 201 nodes by default) to its branch point, where
``follow_periodic_family`` with ``Continuation(step=0.0005, switch=Switch(orbits))`` takes the
kernel direction of the extended system and follows both halves of the new branch
(``solvers/periodic/switching.py``), each on the grid its period target asks for
(``Switch.tol``, ``branch_grid.py``; ``--tol 0``: on the family's grid). Each orbit's own
estimate of its period error (against the family's grid, not added to its period) is printed
beside its measured difference. Every orbit of both halves is then corrected by Howell's
differential correction (``halo_correction.py``: scipy's DOP853 and the variational equations,
nothing of the package) from the orbit's node 0 on ``y = 0``: once at the orbit's energy (its
period compared: ``T - T_dc``) and once at its ``z0`` (the Jacobi constant compared: ``C - C_dc``,
``C = -2E``). Target (issue 46): both within 1e-4 for 20 orbits of each half. The two halves are
each other's images under ``z -> -z``: the largest difference of their periods and energies,
and of the nodes' ``(x, y, -z)``, is printed too. CPU beside wall.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from halo_correction import correct  # noqa: E402

from ddvp_nlp import Continuation, Switch, follow_periodic_family, load_scene  # noqa: E402
from ddvp_nlp.io import machine  # noqa: E402


def switched(orbits: int, nodes: int, tol=None):
    """The followed family with both halves of its halo branch, and the CPU and wall seconds."""
    scene = load_scene("cr3bp")
    mu = scene.params["mu"]
    cpu, wall = time.process_time(), time.perf_counter()
    family = follow_periodic_family(
        scene.system, (-1.5935, -1.585), nodes=nodes, section="q2=0",
        guess=scene.periodic.guess(-1.5935, mu=mu),
        continuation=Continuation(step=0.0005, switch=Switch(orbits=orbits, **(
            {} if tol is None else {"tol": tol or None}))))
    return family, mu, time.process_time() - cpu, time.perf_counter() - wall


def compared(member, mu) -> dict:
    """One orbit beside its differential corrections (module docstring)."""
    orbit = member.orbit
    x0, z0, vy0 = orbit.q[0, 0], orbit.q[0, 2], orbit.p[0, 1] - orbit.q[0, 0]
    period, energy = float(orbit.orbit.period), float(member.energy)
    at_energy = correct(x0, z0, vy0, mu, period, jacobi_constant=-2 * energy)
    at_height = correct(x0, z0, vy0, mu, period)
    return {"E": energy, "z0": z0, "zmax": float(np.max(np.abs(orbit.q[:, 2]))),
            "T": period, "T_dc": at_energy.period, "dT": period - at_energy.period,
            "C": -2 * energy, "C_dc": at_height.jacobi, "dC": -2 * energy - at_height.jacobi,
            "iterations": (at_energy.iterations, at_height.iterations)}


def draw(family, path) -> None:
    """The followed family (grey) and both halves of the new branch: ``x-y`` and ``x-z``
    projections, the period against the energy."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (plane, height, periods) = plt.subplots(1, 3, figsize=(10, 3.2))
    for member in family.members:
        plane.plot(member.orbit.q[:, 0], member.orbit.q[:, 1], color="0.6", lw=0.6)
    periods.plot([m.energy for m in family.members],
                 [m.orbit.orbit.period for m in family.members], "o-", color="0.5", ms=3,
                 label="followed family")
    looks = (("tab:blue", "o", 6, "none"), ("tab:red", ".", 3, "tab:red"))
    for branch, (colour, marker, size, face) in zip(family.branches, looks, strict=False):
        members = branch.family.members
        for member in members:
            q = member.orbit.q
            plane.plot(q[:, 0], q[:, 1], color=colour, lw=0.5, alpha=0.6)
            height.plot(q[:, 0], q[:, 2], color=colour, lw=0.5)
        periods.plot([m.energy for m in members], [m.orbit.orbit.period for m in members],
                     marker, color=colour, ms=size, mfc=face, ls="none",
                     label=f"half {branch.label}")
    for point in family.bifurcations:
        periods.axvline(point.energy, color="k", lw=0.6, ls=":")
    plane.set(xlabel="x", ylabel="y", title="x-y")
    height.set(xlabel="x", ylabel="z", title="x-z")
    periods.set(xlabel="E", ylabel="period", title="period")
    periods.legend(fontsize=7)
    for axis in (plane, height):
        axis.set_aspect("equal", adjustable="datalim")
    fig.suptitle("CR3BP Earth-Moon: L1 Lyapunov family, switched onto the halo branch")
    fig.tight_layout()
    fig.savefig(path, dpi=130)


def report(family, mu, cpu: float, wall: float, nodes: int) -> tuple[float, float]:
    """The run's tables (module docstring); ``(largest gap, largest |z|)``."""
    print(f"{family.message}; {len(family.members)} orbits")
    print(f"{family.switched}")
    print(f"follow and switch: {cpu:.1f} s CPU, {wall:.1f} s wall (family: N = "
          f"{nodes - 1}, {family.seconds:.1f} s wall; halves: "
          + ", ".join(f"{b.label} {b.family.seconds:.1f} s wall" for b in family.branches) + ")")
    worst, height = 0.0, 0.0
    for branch in family.branches:
        print(f"\nhalf {branch.label}: {branch.family.message}")
        errors = branch.family.grid.get("errors") or [None] * len(branch.family.members)
        print("| # | N | E | z0 | max abs z | T | T_dc (same E) | T - T_dc | estimate of it "
              "| C | C_dc (same z0) | C - C_dc | DC iterations |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for j, member in enumerate(branch.family.members):
            row = compared(member, mu)
            worst = max(worst, abs(row["dT"]), abs(row["dC"]))
            height = max(height, row["zmax"])
            said = "-" if errors[j] is None else f"{errors[j] * row['T']:.2e}"
            print(f"| {j + 1} | {member.orbit.t.size - 1} | {row['E']:.9f} | {row['z0']:+.6f} | "
                  f"{row['zmax']:.6f} | {row['T']:.9f} | {row['T_dc']:.9f} | {row['dT']:+.2e} | "
                  f"{said} | {row['C']:.9f} | {row['C_dc']:.9f} | {row['dC']:+.2e} | "
                  f"{row['iterations']} |")
    if len(family.branches) == 2:
        a, b = (br.family.members for br in family.branches)
        pairs = list(zip(a, b, strict=False))
        mirror = np.array([1.0, 1.0, -1.0])
        print(f"\nmirror images (z -> -z), {len(pairs)} pairs: largest |E+ - E-| "
              f"{max(abs(u.energy - v.energy) for u, v in pairs):.1e}, |T+ - T-| "
              f"{max(abs(u.orbit.orbit.period - v.orbit.orbit.period) for u, v in pairs):.1e}, "
              f"nodes {max(np.max(np.abs(u.orbit.q - v.orbit.q * mirror)) for u, v in pairs):.1e}")
    print(f"\nlargest |T - T_dc|, |C - C_dc|: {worst:.2e} (target 1e-4)")
    return worst, height


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--orbits", type=int, default=20)
    parser.add_argument("--nodes", type=int, default=201)
    parser.add_argument("--tol", type=float, default=None,
                        help="Switch(tol=...): the halves' relative period target (default: "
                             "Switch's; 0: none, the halves on the family's grid)")
    parser.add_argument("--baseline", action="store_true",
                        help="first the same with --tol 0 (the halves on the family's grid), "
                             "and a summary of both side by side")
    parser.add_argument("--figure", default=None, metavar="PATH",
                        help="draw the family and both halves (x-y, x-z, period against E)")
    args = parser.parse_args(argv)
    runs = ([("family's grid (tol 0)", 0.0)] if args.baseline else []) + [
        (f"tol {args.tol if args.tol is not None else Switch().tol:g}", args.tol)]
    rows, ok = [], True
    for name, tol in runs:
        print(f"\n## {name}\n")
        family, mu, cpu, wall = switched(args.orbits, args.nodes, tol)
        worst, height = report(family, mu, cpu, wall, args.nodes)
        grids = sorted({b.family.grid.get("intervals", args.nodes - 1) for b in family.branches})
        rows.append((name, grids, worst, height, cpu, wall))
        ok = worst < 1e-4 and all(br.family.complete for br in family.branches)
    print("\n| run | halves' N | largest gap | largest abs(z) | CPU | wall |")
    print("|---|---|---|---|---|---|")
    for name, grids, worst, height, cpu, wall in rows:
        print(f"| {name} | {', '.join(map(str, grids))} | {worst:.2e} | {height:.3f} | "
              f"{cpu:.1f} s | {wall:.1f} s |")
    if len(rows) == 2:
        print(f"CPU ratio {rows[1][4] / rows[0][4]:.2f}, wall ratio {rows[1][5] / rows[0][5]:.2f}, "
              f"gap ratio {rows[1][2] / rows[0][2]:.2f}")
    if args.figure:
        draw(family, args.figure)
    print(f"machine: {machine()}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
