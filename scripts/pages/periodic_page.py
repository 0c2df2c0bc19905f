"""Regenerate docs/periodic/README.md and its figures: periodic orbits at a prescribed energy
(solvers/periodic/).

    python scripts/pages/periodic_page.py [--out docs/periodic] [--quick]

The pendulum's family against 4 K(k), its rotations against 4 K(2/E)/sqrt(2E), two
two-dimensional Henon-Heiles families through x = 0, the figure-eight orbit, the convergence
table of the period (pendulum, rotations, harmonic oscillator, figure-eight) with the residuals
of every orbit, and Newton against IPOPT (``scripts/benchmarks/bench_periodic.py``, run as a
process of its own, its timings beside the machine and the date). A few minutes; ``--quick``
(smaller grids and families, one timed call) takes about one. Only the figures the page shows
are kept in ``--out``: the families' folders are written to a scratch folder first.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from ddvp_nlp import (
    GridOptions,
    periodic_stability,
    solve_periodic,
    solve_periodic_family,
)
from ddvp_nlp.io import machine, new_figure, plot_orbit, save, styled, write_family
from ddvp_nlp.scenes import load_scene

ROOT = Path(__file__).resolve().parents[2]
BENCH_PERIODIC = ROOT / "scripts" / "benchmarks" / "bench_periodic.py"
# The grids of the page, and of a quick run (minutes less; not for docs/)
FULL = {"family": np.linspace(0.1, 1.9, 19), "rotations": np.linspace(2.2, 4.0, 10),
        "henon": np.round(np.arange(0.02, 0.1601, 0.02), 3), "henon_nodes": (200, 400),
        "eight": 600, "eight_exact": 1200, "pendulum": (100, 200, 400, 800),
        "harmonic": (40, 80, 160, 320), "eight_sizes": (150, 300, 600, 1200),
        "bench": ["--repeats", "3"]}
QUICK = {"family": np.linspace(0.1, 1.9, 4), "rotations": np.linspace(2.2, 4.0, 3),
         "henon": np.array([0.04, 0.1]), "henon_nodes": (100, 200), "eight": 300,
         "eight_exact": 600, "pendulum": (100, 200), "harmonic": (40, 80),
         "eight_sizes": (150, 300), "bench": ["--repeats", "1", "--only", "solvers"]}

# Simo's period of his eight-decimal initial data: a reference for the orbit through his data,
# not for the orbit at the prescribed energy -1.287144 (six decimals) that is solved here.
SIMO_PERIOD = 6.32591398


# The exact periods the pendulum scene declares (problems/pendulum.py, PeriodicSettings.period):
# librations 4 K(E / 2), rotations 4 K(2 / E) / sqrt(2 E).
PENDULUM = load_scene("pendulum").periodic
pendulum_period = PENDULUM.period
rotation_period = PENDULUM.families["rotations"].period


def convergence_rows(name, sizes, exact, label=None, **options):
    scene = load_scene(name)
    rows, previous = [], None
    for N in sizes:
        solution = solve_periodic(scene.system, nodes=N + 1, **options)
        error = solution.orbit.period - exact
        order = np.log2(abs(previous / error)) if previous is not None else np.nan
        worst = max(solution.orbit.residuals.values())
        rows.append(f"| {label or name} | {N} | {solution.status.code} "
                    f"| {solution.stats['solver']} | {solution.orbit.period:.10f} "
                    f"| {error:.3e} | {'' if np.isnan(order) else f'{order:.3f}'} "
                    f"| {worst:.1e} |")
        previous = error
    return rows


def rotation_rows(out: Path, scratch: Path, energies):
    """Pendulum rotations (q1 an angle, section q1=0): a family E = 2.2 .. 4 at N = 200 against
    the exact period, and its figure."""
    pendulum = load_scene("pendulum")
    family = solve_periodic_family(pendulum.system, energies, nodes=201,
                                   section="q1=0", angles=("q1",))
    rows = write_family(scratch / "pendulum_rotations", pendulum, family, {}, plot=True,
                        section="q1=0", folders=False)
    keep_figure(scratch / "pendulum_rotations" / "family.png",
                out / "pendulum_rotations" / "family.png")
    solvers = [orbit.stats["solver"] for _, orbit in family]
    return [f"| {r['energy']:.1f} | {r['period']:.8f} | {rotation_period(r['energy']):.8f} | "
            f"{r['period'] - rotation_period(r['energy']):.2e} | {r['status']} | {solver} |"
            for r, solver in zip(rows, solvers, strict=True)]


def henon_heiles_field(t, z):
    x, y, px, py = z
    return [px, py, -x - 2 * x * y, -y - x * x + y * y]


def exact_return(orbit, period):
    """``|z(T) - z_0|_inf`` of the exact flow (DOP853, rtol 1e-12) from the orbit's node 0 over
    ``T``: a check that uses neither the scheme nor its equations."""
    z0 = np.concatenate([orbit.q[0], orbit.p[0]])
    run = solve_ivp(henon_heiles_field, (0.0, period), z0, method="DOP853", rtol=1e-12,
                    atol=1e-14)
    return float(np.max(np.abs(run.y[:, -1] - z0)))


def keep_figure(source: Path, target: Path) -> None:
    """Copy the figure the page shows out of a command's folder (its CSV and manifest stay
    behind: no page shows them)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(source, target)


def henon_heiles_rows(out: Path, energies, sizes):
    """The two 2-D families through x = 0 (and the invariant-plane one for the figure), at
    N = 200 and 400 by continuation in E, each orbit checked against the exact flow."""
    scene = load_scene("henon_heiles")
    coarse_nodes, fine_nodes = sizes
    families = {name: {"section": data.section, "start": data.start}
                for name, data in scene.periodic.families.items()}
    families["x = 0 (invariant line)"] = {"section": scene.periodic.section,
                                           "start": scene.periodic.start}
    found, rows = {}, []
    for name, data in families.items():
        coarse = solve_periodic_family(scene.system, energies, nodes=coarse_nodes + 1, **data)
        fine = solve_periodic_family(scene.system, energies, nodes=fine_nodes + 1,
                                     guess=coarse[0][1], **data)
        found[name] = fine
        for (energy, a), (_, b) in zip(coarse, fine, strict=True):
            if name.startswith("x = 0"):
                continue
            extrapolated = b.orbit.period + (b.orbit.period - a.orbit.period) / 3
            accuracy = b.verdict.as_dict()
            rows.append(f"| {name} | {energy:.2f} | {a.status.code}, {b.status.code} | "
                        f"{a.orbit.period:.8f} | {b.orbit.period:.8f} | "
                        f"{extrapolated:.8f} | {accuracy['verdict']} | "
                        f"{accuracy['local_error_max']:.1e} | "
                        f"{accuracy['error_max']:.1e} | "
                        f"{exact_return(b, extrapolated):.1e} | "
                        f"{max(b.orbit.residuals.values()):.1e} |")
    plot_henon_heiles(found, out / "henon_heiles.png")
    return rows


def plot_henon_heiles(found: dict, path: Path) -> None:
    with styled():
        fig = new_figure(11, 4.8)
        left, right = fig.subplots(1, 2)
        _henon_heiles_panels(left, right, found)
        save(fig, path)


def _henon_heiles_panels(left, right, found: dict) -> None:
    for (name, family), colour in zip(found.items(), ("C0", "C1", "C2"), strict=True):
        for energy, orbit in family:
            if orbit.success and round(energy, 3) in (0.04, 0.1, 0.16):
                left.plot(orbit.q[:, 0], orbit.q[:, 1], "-", color=colour, lw=0.9)
        ok = [(e, o.orbit.period) for e, o in family if o.success]
        right.plot(*zip(*ok, strict=True), "o-", color=colour, ms=4, label=name)
    x, y = np.meshgrid(np.linspace(-1, 1, 400), np.linspace(-0.6, 1.1, 400))
    left.contour(x, y, (x * x + y * y) / 2 + x * x * y - y ** 3 / 3, levels=[1 / 6],
                 colors="0.6", linewidths=0.8)
    left.set_aspect("equal")
    left.set_xlabel("$x = q_1$")
    left.set_ylabel("$y = q_2$")
    left.set_title("orbits at $E$ = 0.04, 0.10, 0.16 (grey: $V = 1/6$)")
    right.set_xlabel("energy $E$")
    right.set_ylabel("period $T$")
    right.set_title("period against energy, $N = 400$")
    right.legend()


def solver_table(arguments: list[str]) -> str:
    """``scripts/benchmarks/bench_periodic.py``'s table (its output, run as a process of its
    own); its last line names the machine and the date."""
    done = subprocess.run([sys.executable, str(BENCH_PERIODIC), *arguments], check=True,
                          capture_output=True, text=True)
    return done.stdout.rstrip()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "docs" / "periodic"))
    parser.add_argument("--quick", action="store_true",
                        help="smaller grids and families, one timed call (not for docs/)")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    grids = QUICK if args.quick else FULL
    with tempfile.TemporaryDirectory(prefix="periodic-page-") as scratch:
        page = build(out, Path(scratch), grids)
    if args.quick:
        page = page.replace("\n\n", "\n\nA quick run (`--quick`): smaller grids and "
                            "families than the text says.\n\n", 1)
    (out / "README.md").write_text(page)
    print(f"wrote {out / 'README.md'}")


def build(out: Path, scratch: Path, grids: dict) -> str:
    """The page's text; its figures written to ``out`` (the families' folders to
    ``scratch``)."""
    pendulum = load_scene("pendulum")
    family = solve_periodic_family(pendulum.system, grids["family"], nodes=201)
    rows = write_family(scratch / "pendulum_family", pendulum, family, {}, plot=True,
                        folders=False)
    keep_figure(scratch / "pendulum_family" / "family.png",
                out / "pendulum_family" / "family.png")
    family_table = [f"| {r['energy']:.2f} | {r['period']:.8f} | "
                    f"{pendulum_period(r['energy']):.8f} | "
                    f"{r['period'] - pendulum_period(r['energy']):.2e} | {r['status']} |"
                    for r in rows]

    eight = load_scene("figure_eight")
    data = eight.periodic
    options = {"energy": data.energy, "section": data.section, "start": data.start,
               "integrals": data.integrals}
    orbit = solve_periodic(eight.system, nodes=grids["eight"] + 1, **options)
    plot_orbit(orbit, f"figure-eight, E = {data.energy}, N = {grids['eight']}, "
                      f"T = {orbit.orbit.period:.8f}", out / "figure_eight.png")
    # the reference of the convergence table: the exact flow's orbit at the energy solved,
    # closed by DOP853 shooting from the finest discrete orbit
    eight_exact = periodic_stability(
        eight.system, solve_periodic(eight.system, nodes=grids["eight_exact"] + 1, **options),
        integrals=data.integrals).exact_orbit
    if not eight_exact.converged:
        raise SystemExit(f"the exact figure-eight at E = {data.energy} did not close "
                         f"(closure {eight_exact.closure:.1e})")
    simo_energy = float(eight.system.energy(eight.q0, eight.p0, 0.0, [])[0])

    table = [*convergence_rows("pendulum", grids["pendulum"], pendulum_period(0.5),
                               energy=0.5, section="p1=0"),
             *convergence_rows("pendulum", grids["pendulum"], rotation_period(2.5),
                               label="pendulum rotation", energy=2.5, section="q1=0",
                               angles=("q1",), options=GridOptions(max_iter=400)),
             *convergence_rows("harmonic", grids["harmonic"], np.pi, energy=0.3,
                               params={"w": 2.0}),
             *convergence_rows("figure_eight", grids["eight_sizes"], eight_exact.period,
                               **options)]
    rotations = rotation_rows(out, scratch, grids["rotations"])
    henon = henon_heiles_rows(out, grids["henon"], grids["henon_nodes"])
    solvers = solver_table(grids["bench"])
    return PAGE.format(family="\n".join(family_table), table="\n".join(table),
                       rotations="\n".join(rotations), henon="\n".join(henon),
                       solvers=solvers,
                       eight=orbit.message, eight_period=orbit.orbit.period,
                       eight_exact=eight_exact.period, eight_closure=eight_exact.closure,
                       simo_energy=simo_energy, simo_period=SIMO_PERIOD, machine=machine())


PAGE = """# Periodic orbits at a prescribed energy

Generated by `python scripts/pages/periodic_page.py` (a few minutes; it runs
`scripts/benchmarks/bench_periodic.py` for the solver table); the solver is
`ddvp_nlp/solvers/periodic/orbit.py` (`ddvp periodic SCENE --energy E --nodes N
[--section NAME=VALUE] [--family E1:E2:COUNT] [--solver newton|ipopt|auto]`).

Unknowns: node states and node times `t_0 .. t_N` of a closed grid of `N` intervals, plus the
unfolding parameters. Equations: canonical equations of every interval (`2nN`), `H(Q_k, P_k) = E`
on every interval (`N`: the scheme's interior energy equations with the prescribed energy;
the wrap-around energy equation is the dependent one and is dropped), closure (`2n`), `t_0 = 0`
and the section (2). That is one equation more than the `(N+1)(2n+1)` node values: the discrete
problem has no exact time-shift symmetry, so the phase condition is kept and an unfolding
parameter `lambda` (`z' = (J + lambda I) grad H`) is added; it comes out at round-off on every
orbit below. A symmetry with a conserved integral (translations and rotations of the three-body
problem) adds one phase condition and one unfolding parameter each.

Two solvers take the same square system. `newton`: the Jacobian (band plus closure corners plus
the unfolding columns) factored by SuperLU inside the fixed-endpoint solver's Newton iteration.
`ipopt` (`solvers/periodic/orbit_nlp.py`): objective 0, the same rows as equality constraints, every
step bounded below, exact Hessian; a feasibility problem, because the system is square with an
isolated solution (minimising the sum of squares would square the condition number and could
stop at a non-zero minimum). `auto` (the default): Newton, then IPOPT from the same start when
Newton's point fails its verification. Whichever found it, each orbit is verified by its own
unscaled residuals (canonical, the scheme's energy equations including the wrap-around one,
prescribed energy, closure, section) and by the accuracy check that does not trust the scheme
(`solvers/accuracy/judgement.py`: every interval against an RK4 step of the exact flow, and the
propagated global error estimate).

An angle coordinate (a scene's `periodic={{"angles": ("q1",)}}`, as `problems/pendulum.py`
declares; `solve_periodic(..., angles=("q1",))`) may close with whole turns, `q_N = q_0 + 2 pi w`;
`w` is taken from the start, whose march returns to a section on the angle one turn on.

## Pendulum: the family of librations against 4 K(k)

`k = sin(theta_max/2)`, `cos(theta_max) = 1 - E`; N = 200, natural-parameter continuation from
E = 0.1, the default start (a march from the turning point to its return).

![pendulum family](pendulum_family/family.png)

| E | discrete period | 4 K(k) | difference | status |
|---|---|---|---|---|
{family}

## Pendulum: rotations against 4 K(2/E) / sqrt(2E)

Above the separatrix (`E > 2`), on the section `q1 = 0`. One turn takes
`T = int_0^{{2 pi}} dq / p(q)`, `p = sqrt(2 (E - 1 + cos q))`; with `q = 2 phi`,
`E - 1 + cos q = E (1 - (2/E) sin^2 phi)`, so `T = 4 K(m) / sqrt(2E)` with the parameter
`m = 2/E` (`2 K(1/k) / k` in the librations' modulus `k^2 = E/2`);
`tests/library/periodic/test_orbit_solvers.py` checks it against a quadrature. N = 200,
continuation from E = 2.2. The steps of the discrete
rotation have a spike (3-5x the others at N = 100..800) where the level curve `p(q)` has an
inflection: there `w = f' H_zz f` changes sign, the `tau^2 w / 8` term of the interval energy
vanishes and the energy equation barely fixes the step (the midpoints `(Q_k, P_k)` lie on the
level curve and each node is where the tangent steps of two neighbouring midpoints meet, well
posed where the curve is convex; across an inflection one long step is needed). Elsewhere the
steps follow `tau |w|^(1/3)` = const, with one constant on each side of the inflections (0.0345
where `w > 0`, 0.0525 where `w < 0` at N = 100; measured). From the march resampled on equally
spaced times, which has no spike, Newton's monotone line search stalled at every N and IPOPT
took 13, 28, 69 and 296 iterations for N = 100, 200, 400, 800 at E = 2.5. The default start is
now the march on the predicted grid `tau ~ |w|^(-1/3)` (floored so that no predicted step
exceeds four typical ones: the spike is there), solved on N = 100 first and refined by
continuation in N (`solvers/periodic/refinement.py`: 100, 200, 400, 800, each level started
from the last one's nodes resampled by node index, which keeps the step distribution): Newton
converges in 5 iterations on every level, IPOPT in 5-7
(`python scripts/benchmarks/bench_periodic.py --only rotation`, below).

![pendulum rotations](pendulum_rotations/family.png)

| E | discrete period | 4 K(2/E)/sqrt(2E) | difference | status | solver |
|---|---|---|---|---|---|
{rotations}

## Henon-Heiles: two-dimensional orbits through x = 0

Besides the family on the invariant line `x = 0` (green), two families whose orbits move in
both coordinates, through the section `x = 0` (`problems/henon_heiles.py`, `periodic.families`):
the *loop* (from the circular motion of the linearised 1:1 oscillator; it crosses `x = 0` at
`y > 0` moving in `-x`) and the orbit *across* the axis `x = 0` (from the normal mode along `x`;
it crosses at `y < 0`). Each is continued in `E` from 0.02 at N = 200 (from the march's start)
and at N = 400 (from the N = 200 orbit at E = 0.02: from the march's start, N = 400 failed on
the orbit across at E = 0.02, close to the 1:1 resonance where the orbits separate). Checks that do
not use the scheme's equations: the accuracy check's largest local error (the exact flow over
each interval) and the closure of the exact flow from node 0 over the period, both relative
to the orbit's size, and the return of the exact flow
(DOP853, rtol 1e-12) from the N = 400 orbit's node 0 after the extrapolated period
`T_400 + (T_400 - T_200)/3`, which the discretisation error of node 0 bounds.

![Henon-Heiles families](henon_heiles.png)

| family | E | status | T_200 | T_400 | T_extr | accuracy | local error | closure | return | res. |
|---|---|---|---|---|---|---|---|---|---|---|
{henon}

Columns: status at N = 200 and 400; `T_extr` the extrapolated period; `local error` the
accuracy check's largest local error and `closure` the largest distance of the exact flow from
the orbit over the period, both relative to the orbit's size (N = 400); `return` the exact
flow's return distance; `res.` the largest residual (N = 400).

## Figure-eight (three equal masses, G = m = 1)

Simo's data, energy -1.287144, N = 600, section `x_3 = 0`, phase conditions for the
translations and the rotation. Period {eight_period:.8f} at N = 600 (the exact orbit at this
energy: {eight_exact:.8f}; Simo's data, at energy {simo_energy:.8f}: {simo_period}).
{eight}

![figure-eight](figure_eight.png)

## Convergence of the period

Order: `log2` of the ratio of successive errors. Every reference is the exact period at the
energy solved: `4 K(E/2)` and `4 K(2/E) / sqrt(2E)` for the pendulum (declared on the scene,
`PeriodicSettings.period`), `2 pi / w` for the oscillator, and for the figure-eight the exact
flow's orbit at E = -1.287144, closed by DOP853 shooting from the N = 1200 orbit
(`periodic_stability(...).exact_orbit`): period {eight_exact:.10f}, closure {eight_closure:.1e}.
Simo's {simo_period} is the period of his eight-decimal initial data, whose energy is
{simo_energy:.10f}, not -1.287144: measured against it, the errors stop falling at the
difference of the two orbits' periods and the last order is an artefact.

| scene | N | status | solver | period | error | order | largest residual |
|---|---|---|---|---|---|---|---|
{table}

## Newton against IPOPT

`python scripts/benchmarks/bench_periodic.py`: both solvers from the same start (the march to
the return), the solver and the verification timed, best of 3 after a warm-up; the first call
builds the CasADi functions and the IPOPT problem. On a shared machine (its load average is
printed with the table) the ratios, measured side by side, say more than the seconds.

{solvers}

The page's other numbers: {machine}
"""


if __name__ == "__main__":
    main()
