"""Regenerate docs/comparison/README.md: published numbers beside ours, and which method is
cheapest at which error and horizon on the built-in scenes.

1. SUNDIALS' ark_kepler example (leapfrog, e = 0.6) to T = 50: H(T) - H0 per step.
2. Kane, Marsden and Ortiz's double well as redone by Sharma (2020): H = p^2/2 + (q^4 - q^2)/2,
   p(0) = 0, the midpoint scheme with the energy rule (vddvp) at h0 = 0.1 and 0.01, against
   fixed-step midpoint over the same number of steps.
3. ``compare(scene, methods, horizons=HORIZONS)`` on the built-in scenes of `CASES`: the
   crossover horizons in words (measured numbers only), ``SCENE/crossover.png``,
   ``SCENE/horizons.png`` and every run in ``SCENE/runs.csv``.

    python scripts/pages/comparison_page.py [--out docs/comparison] [--t-end 100] [--quick]

Parts 1-2 take seconds and show no timing; part 3 some minutes of runs on a quiet machine
(``--quick``: the double well to t = 20 and horizons 10 and 100 only; ``--from-runs``: part 3
redrawn from the ``runs.csv`` files on disk, in seconds).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ddvp_nlp import Output, Scene, compare, load_scene, march
from ddvp_nlp.discrete import Scheme, interval_energies
from ddvp_nlp.io import machine
from ddvp_nlp.solvers import find_compiler

# an internal, named explicitly: one fixed-step run of a baseline (not a workbench name)
from ddvp_nlp.solvers.baselines.fixed_step import fixed_step_run
from ddvp_nlp.studies import CompareOptions, HorizonComparison

ROOT = Path(__file__).resolve().parents[2]

ARK_KEPLER = {1e-3: -1.0321e-7, 5e-4: -2.583e-8, 2.5e-4: -6.460e-9, 1.25e-4: -1.615e-9,
              6.25e-5: -4.037e-10}
SHARMA = {(0.74, 0.1): "0.100-0.107", (0.995, 0.1): "0.10-0.45",
          (0.74, 0.01): "near 0.01", (0.995, 0.01): "grows about 4-fold"}
SHARMA_FIXED = {0.74: "about 1e-8", 0.995: "about 1e-6"}
# Part 3: the scenes, the methods compared on each (an energy-conserving pair, a symplectic
# one, an explicit fourth-order one and adaptive DOP853) and the horizons, in the scene's time
# units.
METHODS_COMPARED = "vddvp,avf,stormer_verlet,rk4,dop853"
CASES = {"harmonic": {}, "pendulum": {}}
HORIZONS = [10.0, 100.0, 1000.0, 10000.0]
QUICK_HORIZONS = [10.0, 100.0]
TIMING = CompareOptions(halvings=3, repeats=5, budget_s=1.0, max_steps=2_000_000)


def double_well(q, p, t):
    return p[0] ** 2 / 2 + (q[0] ** 4 - q[0] ** 2) / 2


def kepler_table() -> list[str]:
    scene = load_scene("kepler")
    theta = scene.system.parameter_vector({"e": 0.6})
    lines = ["| dt | steps | SUNDIALS H(T) - H0 | ours (`leapfrog`) | ours / theirs - 1 | "
             "`stormer_verlet` (kick-drift-kick) |", "|---|---|---|---|---|---|"]
    for dt, published in ARK_KEPLER.items():
        found = {}
        for method in ("leapfrog", "stormer_verlet"):
            solution = fixed_step_run(scene.system, method, np.array([0.4, 0.0]),
                                      np.array([0.0, 2.0]), tau=dt, t_end=50.0, t0=0.0,
                                      theta=theta, compiler=find_compiler("auto"))
            found[method] = float(scene.system.energy(solution.q[-1:], solution.p[-1:],
                                                      solution.t[-1:], theta)[0]) + 0.5
        lines.append(f"| {dt:g} | {solution.steps} | {published:.4g} | "
                     f"{found['leapfrog']:.4e} | {found['leapfrog'] / published - 1:+.1e} | "
                     f"{found['stormer_verlet']:.3e} |")
    return lines


def double_well_table(t_end: float) -> list[str]:
    lines = ["| q(0) | h0 | steps | Sharma: steps | ours: steps min-max | ours: interval "
             "energy drift (vddvp) | ours: H drift at nodes (vddvp) | Sharma: fixed steps | "
             "ours: fixed-step midpoint H drift, same steps |", "|---" * 9 + "|"]
    for q0 in (0.74, 0.995):
        scene = Scene(double_well, n=1, q0=[q0], p0=[0.0], tau0=0.1, t_end=t_end,
                      name="double_well")
        system, theta = scene.system, np.zeros(0)
        for h0 in (0.1, 0.01):
            run = march(system, [q0], [0.0], (0.0, t_end), tau0=h0, scheme="vddvp",
                        output=Output(progress=False))
            interval = interval_energies(system, Scheme(), run.t, run.q, run.p, theta)
            nodes = system.energy(run.q, run.p, run.t, theta)
            fixed = march(
                system,
                [q0],
                [0.0],
                (0.0, t_end),
                tau0=t_end / run.steps,
                scheme="fixed",
                output=Output(progress=False),
            )
            fixed_H = system.energy(fixed.q, fixed.p, fixed.t, theta)
            tau = np.diff(run.t)
            lines.append(
                f"| {q0} | {h0} | {run.steps} ({run.status.code}) | {SHARMA[q0, h0]} | "
                f"{tau[:-1].min():.4g}-{tau[:-1].max():.4g} | "
                f"{np.max(np.abs(interval - interval[0])):.1e} | "
                f"{np.max(np.abs(nodes - nodes[0])):.1e} | {SHARMA_FIXED[q0]} | "
                f"{np.max(np.abs(fixed_H - fixed_H[0])):.1e} |")
    return lines


def horizons_section(out: Path, horizons, from_runs: bool = False) -> list[str]:
    """Part 3: per scene, the crossovers in words and the figures (module docstring); with
    ``from_runs`` from the ``runs.csv`` an earlier run wrote (no run, no new timing)."""
    lines = ["## Which method is cheapest, by error and horizon", "",
             f"`compare(scene, \"{METHODS_COMPARED}\", horizons={horizons})`, every run timed "
             f"{TIMING.repeats} times after a warm-up (cost: the best wall time; the figures "
             "draw that same time with a bar to the slowest call and an open marker at its "
             "CPU time, which is also in `runs.csv`). Both errors are absolute: the trajectory "
             "error max_k max_i |z_k,i - z_ref,i(t_k)| against the exact solution, the energy "
             "error max_k |H(z_k) - H(z_0)|. The rule (`studies/horizons_choice.py`): a "
             "method's cost at an error is read off its Pareto front, interpolated in log cost "
             "against log error, and between two measured horizons in log cost against log T; a "
             "crossover is the horizon from which another method is cheapest.", ""]
    for name, settings in CASES.items():
        folder = out / name
        folder.mkdir(parents=True, exist_ok=True)
        if from_runs:
            study = HorizonComparison.read_csv(folder / "runs.csv")
        else:
            study = compare(name, METHODS_COMPARED, params=settings or None, options=TIMING,
                            horizons=horizons)
            study.to_csv(folder / "runs.csv")
        study.plot_crossover(folder / "crossover.png", title=f"{name}: cheapest method")
        study.plot(folder / "horizons.png", title=f"{name}: error against run time")
        lines += [f"### `{name}`", "", *study.crossover_words(), "",
                  *conserving_words(study), "",
                  f"![{name} crossover]({name}/crossover.png)", "",
                  f"![{name} work-precision]({name}/horizons.png)", ""]
    measured = (out / "measured_on.txt")
    if not from_runs:
        measured.write_text(machine() + "\n")
    lines += [f"Measured on: {measured.read_text().strip()}", ""]
    return lines


def conserving_words(study) -> list[str]:
    """The horizons from which an energy-conserving method becomes the cheapest, in words, by
    wall time and by CPU time."""
    conserving = {r["method"]: r["energy_conserving"] for r in study.rows}
    found = []
    for kind in ("energy_error", "trajectory_error"):
        cpu = {(c.error, c.before, c.after): c
               for c in study.crossovers(kind=kind, cost="cpu_s")}
        for crossing in study.crossovers(kind=kind):
            after = crossing.after
            if after and conserving[after] and not (
                    crossing.before and conserving[crossing.before]):
                before = f"`{crossing.before}`" if crossing.before else "none reached it"
                by_cpu = cpu.get((crossing.error, crossing.before, after))
                found.append(f"{kind.replace('_', ' ')} <= {crossing.error:.0e}: `{after}` "
                             f"from {crossing.where()} by wall time"
                             + (f", from {by_cpu.where()} by CPU time" if by_cpu else
                                ", no such crossover by CPU time")
                             + f" (before it {before})")
    if not found:
        return ["No energy-conserving method takes over from another kind of method between "
                "the horizons measured."]
    return ["An energy-conserving method becomes the cheapest at: " + "; ".join(found) + "."]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "docs" / "comparison"))
    parser.add_argument("--t-end", type=float, default=100.0)
    parser.add_argument("--quick", action="store_true",
                        help="the double well to t = 20, horizons 10 and 100 only")
    parser.add_argument("--from-runs", action="store_true",
                        help="part 3 from the runs.csv files of an earlier run (no new runs): "
                             "its words and figures redrawn")
    args = parser.parse_args()
    if args.quick:
        args.t_end = 20.0
    text = "\n".join([
        "# Published numbers, reproduced", "",
        "Regenerate: `python scripts/pages/comparison_page.py` (minutes: the horizons' runs). "
        "Tests: "
        "`tests/library/baselines/test_alternatives.py` (the SUNDIALS numbers to 1%). "
        "Which method is cheapest "
        "over 10 to 10^5 periods: [../work_precision/horizons/README.md]"
        "(../work_precision/horizons/README.md).", "",
        "## SUNDIALS `ark_kepler`, leapfrog", "",
        "Kepler, e = 0.6, q0 = (0.4, 0), p0 = (0, 2), H0 = -0.5, to T = 50; SUNDIALS' "
        "`ARKODE_SPRK_LEAPFROG_2_2` is drift-kick-drift, our `leapfrog`. The kick-drift-kick "
        "form (`stormer_verlet`) ends on the other side of H0, 31 times larger.", "",
        *kepler_table(), "",
        "## Kane-Marsden-Ortiz double well, as redone by Sharma (2020)", "",
        f"H = p^2/2 + (q^4 - q^2)/2, p(0) = 0, midpoint discrete Lagrangian with the energy "
        f"rule (`vddvp`), to t = {args.t_end:g} (the last, cut step left out of the range). "
        "Sharma's columns are as reported; the fixed-step comparison uses our number of "
        "energy-rule steps.", "",
        *double_well_table(args.t_end), "",
        *horizons_section(Path(args.out), QUICK_HORIZONS if args.quick else HORIZONS,
                          from_runs=args.from_runs)])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "README.md").write_text(text)
    print(text)
    print(f"wrote {out / 'README.md'}")


if __name__ == "__main__":
    main()
