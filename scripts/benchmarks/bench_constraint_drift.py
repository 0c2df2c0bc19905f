"""The figure of issue 48: constraint residual and energy error against time, the constrained
march beside RATTLE and SHAKE, on the Cartesian pendulum over a long run.

    python scripts/benchmarks/bench_constraint_drift.py     # 1e6 steps: docs/constraint_drift.png
    python scripts/benchmarks/bench_constraint_drift.py --steps 20000 --out /tmp/drift.png

The pendulum ``H = |p|^2/2 + y`` on ``x^2 + y^2 = 1``, the default rotation of the built-in
scene (speed 3 at the bottom, ``E = 3.5``). ``vddvp`` marches it with energy-determined steps
from ``tau0``; RATTLE and SHAKE march the same span on the uniform step equal to ``vddvp``'s mean
step, at their default constraint tolerance. Drawn, per node: ``|g(q_k)|``, the hidden
constraint ``|G H_p|``, and ``|H(z_k) - H(z_0)| / |H(z_0)|``; for ``vddvp`` also the energy it
conserves, the interval energy, as ``|E_k - E_0| / |H(z_0)|`` (the sum of its energy-row
residuals). Each curve is the largest value in each of 160 bins of log-spaced time from
the hundredth node (an envelope; exact zeros drawn at the floor 1e-17). Prints each run's CPU
beside wall and the largest values per tenth of the run (a drift shows as a growing row).
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ddvp_nlp import HamiltonianSystem, march
from ddvp_nlp.io import new_figure, save, styled
from ddvp_nlp.solvers import INTEGRATORS

ROOT = Path(__file__).resolve().parents[2]
FLOOR = 1e-17  # exact zeros on a log axis
BINS = 160


def pendulum():
    return HamiltonianSystem(lambda q, p, t: (p[0] ** 2 + p[1] ** 2) / 2 + q[1], 2,
                             name="cartesian_pendulum",
                             constraints=lambda q, t: q[0] ** 2 + q[1] ** 2 - 1)


def timed(function):
    cpu, wall = time.process_time(), time.perf_counter()
    result = function()
    return result, time.process_time() - cpu, time.perf_counter() - wall


def residuals(t, q, p):
    """``|g|``, the hidden constraint ``|G H_p| = 2 |q . p|`` and ``H`` at every node."""
    g = np.abs(np.sum(q * q, axis=1) - 1.0)
    hidden = np.abs(2.0 * np.sum(q * p, axis=1))
    H = 0.5 * np.sum(p * p, axis=1) + q[:, 1]
    return g, hidden, H


def envelope(t, values, t_first):
    """The largest value in each of `BINS` log-spaced bins of time from ``t_first``."""
    edges = np.geomspace(t_first, t[-1], BINS + 1)
    index = np.searchsorted(edges, t[1:], side="right") - 1
    index = np.clip(index, 0, BINS - 1)
    top = np.full(BINS, -np.inf)
    np.maximum.at(top, index, values[1:])
    keep = np.isfinite(top)
    centres = np.sqrt(edges[:-1] * edges[1:])
    return centres[keep], np.maximum(top[keep], FLOOR)


def trend(values) -> str:
    return " ".join(f"{part.max():.1e}" for part in np.array_split(np.asarray(values), 10))


def run_all(steps: int, tau0: float):
    system = pendulum()
    q0, p0 = [0.0, -1.0], [3.0, 0.0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the start is consistent already
        march(system, q0, p0, (0, 20 * tau0), tau0=tau0, scheme="vddvp", accuracy=None)  # warm
        mean = 1.317 * tau0  # measured mean step of vddvp from this start (bench_constraints)
        span = steps * mean
        vddvp, cpu, wall = timed(lambda: march(system, q0, p0, (0, span), tau0=tau0,
                                               scheme="vddvp", accuracy=None))
    runs = {}
    tau = (vddvp.t[-1] - vddvp.t[0]) / (vddvp.t.size - 1)
    runs["vddvp"] = (vddvp.t, vddvp.q, vddvp.p, cpu, wall)
    # the energy rows from step 1 (step 0 has the fixed length tau0, no energy row): E_k - E_0
    # at nodes k + 1; the first nodes drawn as 0
    rows = np.asarray(vddvp.energy_residual, float)
    interval = np.zeros(vddvp.t.size)
    interval[vddvp.t.size - rows.size:] = np.cumsum(rows)
    for method in ("rattle", "shake"):
        run = next(m for m in INTEGRATORS if m.name == method).run  # compare's method

        def call(t_end, run=run):
            config = SimpleNamespace(q0=q0, p0=p0, t0=0.0, t_end=t_end, params={})
            return run(system, config, tau, compiler=None, cache_dir=None,
                       max_steps=10 * steps)
        call(20 * tau)  # warm
        solution, cpu, wall = timed(lambda call=call: call(float(vddvp.t[-1])))
        runs[method] = (solution.t, solution.q, solution.p, cpu, wall)
        tol = solution.stats["tol"]
    return runs, interval, tau, tol


def report(runs, interval, tau):
    H0 = 3.5
    print(f"mean step of vddvp {tau:.6g}, RATTLE and SHAKE on that step")
    print("| method | steps | t_end | max abs g | max hidden | max rel |H - H0| | CPU s | wall s |")
    print("|---|---|---|---|---|---|---|---|")
    rows = {}
    for name, (t, q, p, cpu, wall) in runs.items():
        g, hidden, H = residuals(t, q, p)
        energy = np.abs(H - H[0]) / H0
        rows[name] = (t, g, hidden, energy)
        print(f"| {name} | {t.size - 1} | {t[-1]:.1f} | {g.max():.2e} | {hidden.max():.2e} | "
              f"{energy.max():.2e} | {cpu:.2f} | {wall:.2f} |")
        print(f"  {name}: max |g| per tenth: {trend(g)}")
        print(f"  {name}: max rel energy error per tenth: {trend(energy)}")
    drift = np.abs(interval) / H0
    print(f"vddvp interval energy |E_k - E_0| / H0: max {drift.max():.2e}; per tenth: "
          f"{trend(drift)}")
    return rows, drift


STYLE = {"vddvp": ("C0", "-", "constrained march, vddvp (energy steps)"),
         "rattle": ("C1", "--", "RATTLE, same mean step (solve stops at $|g| \\leq$ tol)"),
         "shake": ("C2", ":", "SHAKE, same mean step (solve stops at $|g| \\leq$ tol)")}


def plot(rows, drift, tau, tol, path: Path) -> None:
    t_first = 100 * tau
    with styled():
        fig = new_figure(11, 4.4)
        left, right = fig.subplots(1, 2)
        for name, (t, g, _hidden, energy) in rows.items():
            colour, line, label = STYLE[name]
            left.plot(*envelope(t, g, t_first), line, color=colour, lw=1.1, label=label)
            right.plot(*envelope(t, energy, t_first), line, color=colour, lw=1.1, label=label)
        t = rows["vddvp"][0]
        right.plot(*envelope(t, drift, t_first), "-", color="C3", lw=1.1,
                   label="vddvp, interval energy: $|E_k - E_0|\\,/\\,|H(z_0)|$")
        for ax in (left, right):
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("time $t$")
        left.set_ylim(FLOOR / 3, 1e-12)
        left.set_ylabel(r"constraint residual $|g(q_k)| = |x_k^2 + y_k^2 - 1|$")
        mantissa, exponent = f"{tol:.0e}".split("e")
        left.set_title(f"position constraint at the nodes (max per time bin); "
                       f"tol $= {mantissa} \\cdot 10^{{{int(exponent)}}}$")
        right.set_ylabel(r"relative energy error $|H(z_k) - H(z_0)|\,/\,|H(z_0)|$")
        right.set_title("energy at the nodes (max per time bin)")
        right.set_ylim(FLOOR / 3, 1e-1)
        left.legend(loc="upper left", fontsize="small")
        right.legend(loc="center left", fontsize="small")
        fig.suptitle(f"Cartesian pendulum, rotation $E = 3.5$, {rows['vddvp'][0].size - 1:,} "
                     f"steps, mean step {tau:.4f}")
        save(fig, path)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--tau0", type=float, default=0.01)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "constraint_drift.png")
    args = parser.parse_args()
    runs, interval, tau, tol = run_all(args.steps, args.tau0)
    rows, drift = report(runs, interval, tau)
    print(f"RATTLE and SHAKE stop their constraint solves at |g| <= tol = {tol:.3g}")
    plot(rows, drift, tau, tol, args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
