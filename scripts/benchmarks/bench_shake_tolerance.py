"""The long-run energy error against the constraint solve's tolerance: SHAKE and RATTLE (their
tolerance on ``|g|``) beside the constrained vddvp march (its Newton tolerance), on the Cartesian
pendulum (issue 48).

    python scripts/benchmarks/bench_shake_tolerance.py                 # 1e6 steps a run
    python scripts/benchmarks/bench_shake_tolerance.py --steps 100000 --no-figure

The orbit: the built-in ``cartesian_pendulum`` rotation (unit mass, rod and gravity, ``H =
|p|^2 / 2 + y``, from the bottom at speed 3, E = 3.5), regular and fast: its period is about
2.4, so a run of 1e6 steps of 0.01 holds about 4000 turns.

Why not the node energy alone: SHAKE and RATTLE are symplectic up to their constraint solve,
so their step error is a bounded oscillation of the node energy ``H(z_k)`` of the size of the
step squared (3.6e-4 and 1.0e-4 relative at step 0.01), which hides whatever the tolerance adds.
What the tolerance adds is a drift: each step leaves ``g`` up to ``tol``, a perturbation that is
neither symplectic nor reversible, so its energy error adds up from step to step. The study
measures that drift where the oscillation cannot hide it: the energy at the *same phase* of the
orbit, the node energy read (linearly interpolated) where the bob crosses the bottom
(``x = 0``, ``y < 0``, ``x`` increasing) in the first and in the last turn; the oscillation is a
function of the phase (a modified energy), so it cancels in the difference. The table gives:

- ``|g| max``: the largest constraint residual the solve left (``tol`` in the units of ``g``,
  which is ``x^2 + y^2 - 1``);
- ``node max``: ``max_k |H(z_k) - H(z_0)| / E`` (the step's oscillation);
- ``drift``: ``(H at the last bottom crossing - H at the first) / E`` (the same phase);
- ``tol share``: ``max_k |H(z_k) - H(z_k^tight)| / E``, the same method and step at the
  tolerance 1e-15 (as ``bench_rattle.py``): what the tolerance alone costs the node energy,
  and its growth (the largest value in the last tenth of the run over the first tenth);
- for vddvp, ``interval drift``: ``max_k |E_k - E_1| / E`` of the interval energies (what its
  energy rows conserve: the sum of the rows' residuals, recomputed unscaled on the nodes), at
  the Newton tolerance ``tol_N``: the march's Newton stops at ``tol_N`` (its residual test),
  the user's option being ``StepControl(tol=1e4 tol_N)`` (``constrained_steps.py``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from ddvp_nlp import HamiltonianSystem, StepControl, march
from ddvp_nlp.io import machine, new_figure, save, styled
from ddvp_nlp.solvers import find_compiler
from ddvp_nlp.solvers.baselines.rattle import rattle_run  # internal: measured

ROOT = Path(__file__).resolve().parents[2]
SHAKE_TOLERANCES = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-14)
NEWTON_TOLERANCES = (1e-8, 1e-10, 1e-12, 1e-14)
NEWTON_SHARE = 1e4  # StepControl.tol over the Newton's residual test (constrained_steps.py)
STEPS = (0.01, 0.003)
TIGHT = 1e-15  # the reference run's tolerance for the tolerance's share
Q0, P0, E = np.array([0.0, -1.0]), np.array([3.0, 0.0]), 3.5


def hamiltonian(q, p, t):
    return (p[0] ** 2 + p[1] ** 2) / 2 + q[1]


def rod(q, t):
    return q[0] ** 2 + q[1] ** 2 - 1


SYSTEM = HamiltonianSystem(hamiltonian, 2, name="cartesian_pendulum", constraints=rod)


def timed(function, *args, **kwargs):
    cpu, wall = time.process_time(), time.perf_counter()
    result = function(*args, **kwargs)
    return result, time.process_time() - cpu, time.perf_counter() - wall


def energy(q, p) -> np.ndarray:
    return 0.5 * np.sum(p ** 2, axis=1) + q[:, 1]


def same_phase_drift(q, p) -> float:
    """``(H at the last bottom crossing - H at the first) / E`` (module docstring)."""
    x, y = q[:, 0], q[:, 1]
    k = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0) & (y[:-1] < 0))
    if k.size < 2:
        return float("nan")
    H = energy(q, p)
    weight = -x[k] / (x[k + 1] - x[k])
    at = H[k] + weight * (H[k + 1] - H[k])
    return float((at[-1] - at[0]) / E)


def tenth_growth(values) -> float:
    tenth = max(values.size // 10, 1)
    return float(values[-tenth:].max() / max(values[:tenth].max(), np.finfo(float).tiny))


def shake_runs(steps: int, compiler) -> list[dict]:
    rows = []
    for method in ("shake", "rattle"):
        rattle_run(SYSTEM, Q0, P0, tau=STEPS[0], t_end=20 * STEPS[0], method=method,
                   compiler=compiler)  # builds and compiles the chunk (not measured)
        for tau in STEPS:
            tight = rattle_run(SYSTEM, Q0, P0, tau=tau, t_end=steps * tau, method=method,
                               tol=TIGHT, compiler=compiler)
            H_tight = energy(tight.q, tight.p)
            for tol in SHAKE_TOLERANCES:
                run, cpu, wall = timed(rattle_run, SYSTEM, Q0, P0, tau=tau, t_end=steps * tau,
                                       method=method, tol=tol, compiler=compiler)
                g = np.abs(run.q[:, 0] ** 2 + run.q[:, 1] ** 2 - 1)
                H = energy(run.q, run.p)
                share = np.abs(H - H_tight) / E if H.size == H_tight.size else np.array([np.nan])
                rows.append(dict(method=method, tau=tau, tol=tol, status=run.status.name.lower(),
                                 steps=run.t.size - 1, g=g.max(), node=np.abs(H - E).max() / E,
                                 drift=same_phase_drift(run.q, run.p), share=share.max(),
                                 growth=tenth_growth(share), cpu=cpu, wall=wall))
    return rows


def vddvp_runs(steps: int) -> list[dict]:
    march(SYSTEM, Q0, P0, (0, 20 * STEPS[0]), tau0=STEPS[0], accuracy=None)  # compiles
    rows = []
    for tau in STEPS:
        for tol in NEWTON_TOLERANCES:
            control = StepControl(max_steps=steps, tol=NEWTON_SHARE * tol)
            run, cpu, wall = timed(march, SYSTEM, Q0, P0, (0, 10 * steps * tau), tau0=tau,
                                   scheme="vddvp", steps=control, accuracy=None)
            rows.append(dict(method="vddvp", tau=tau, tol=tol, status=run.status.name.lower(),
                             steps=run.t.size - 1, mean_step=run.t[-1] / (run.t.size - 1),
                             g=run.constraints.constraint_residual.max(),
                             node=np.abs(energy(run.q, run.p) - E).max() / E,
                             drift=same_phase_drift(run.q, run.p),
                             interval=np.abs(np.cumsum(run.energy_residual)).max() / E,
                             growth=tenth_growth(np.abs(np.cumsum(run.energy_residual))),
                             cpu=cpu, wall=wall))
    return rows


def report(rows) -> None:
    print("| method | step | tol | status | steps | abs g max | node max abs(H - H0) / E | "
          "same-phase drift / E | tol share / E (SHAKE, RATTLE) or interval drift / E "
          "(vddvp) | its growth | CPU s | wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for row in rows:
        step = f"{row['tau']} (mean {row['mean_step']:.4f})" if "mean_step" in row else \
            f"{row['tau']}"
        share = row["interval"] if "interval" in row else row["share"]
        print(f"| {row['method']} | {step} | {row['tol']:.0e} | {row['status']} | "
              f"{row['steps']} | {row['g']:.1e} | {row['node']:.2e} | {row['drift']:+.2e} | "
              f"{share:.2e} | {row['growth']:.1f} | {row['cpu']:.2f} | {row['wall']:.2f} |")


STYLE = {("shake", 0.01): ("C2", "o", "-"), ("shake", 0.003): ("C2", "s", "--"),
         ("rattle", 0.01): ("C1", "o", "-"), ("rattle", 0.003): ("C1", "s", "--"),
         ("vddvp", 0.01): ("C0", "o", "-"), ("vddvp", 0.003): ("C0", "s", "--")}
NAMES = {"shake": "SHAKE", "rattle": "RATTLE", "vddvp": "vddvp"}
FLOOR = 1e-16  # drawn for a difference of zero (the same nodes as the tight run)


def plot(rows, steps: int, path: Path) -> None:
    """Left: what the tolerance costs the energy (SHAKE, RATTLE: against the same run at
    tolerance 1e-15; vddvp: its interval energy's drift); right: the largest node energy
    error, which the step sets."""
    with styled():
        fig = new_figure(7.0, 3.6)
        left, right = fig.subplots(1, 2, sharey=True)
        for (method, tau), (colour, marker, line) in STYLE.items():
            mine = [r for r in rows if r["method"] == method and r["tau"] == tau]
            tol = np.array([r["tol"] for r in mine])
            share = [r["interval"] if method == "vddvp" else r["share"] for r in mine]
            label = f"{NAMES[method]}, step {tau}" if method != "vddvp" else \
                f"vddvp, tau0 {tau}"
            left.plot(tol, np.maximum(share, FLOOR), line, marker=marker, color=colour,
                      ms=3.5, lw=1.0, label=label)
            right.plot(tol, [r["node"] for r in mine], line, marker=marker, color=colour,
                       ms=3.5, lw=1.0)
        for ax in (left, right):
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.invert_xaxis()
        left.set_xlabel("tolerance (SHAKE, RATTLE: $|g|$; vddvp: Newton)", fontsize="small")
        right.set_xlabel("tolerance (SHAKE, RATTLE: $|g|$; vddvp: Newton)", fontsize="small")
        left.set_ylabel("relative energy error")
        left.set_title("the tolerance's share: $\\max_k |H_k - H_k^{tight}|/E$;\n"
                       "vddvp: interval energy $\\max_k |E_k - E_1|/E$", fontsize="x-small")
        right.set_title("largest node energy error\n$\\max_k |H(z_k) - H(z_0)|/E$",
                        fontsize="x-small")
        right.legend(*left.get_legend_handles_labels(), loc="lower center", ncol=2,
                     fontsize="x-small")
        fig.suptitle(f"Cartesian pendulum, rotation $E = 3.5$, {steps:,} steps a run "
                     "($H^{tight}$: the same method and step at tolerance $10^{-15}$;\n"
                     "a point at $10^{-16}$: no difference from it)",
                     fontsize="small")
        save(fig, path)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "shake_tolerance.png")
    parser.add_argument("--no-figure", action="store_true")
    args = parser.parse_args(argv)
    print(machine() + "\n")
    rows = shake_runs(args.steps, find_compiler()) + vddvp_runs(args.steps)
    report(rows)
    if not args.no_figure:
        plot(rows, args.steps, args.out)
        print(f"\nwrote {args.out}")


if __name__ == "__main__":
    main()
