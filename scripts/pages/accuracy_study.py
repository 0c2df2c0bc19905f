"""Regenerate docs/accuracy/README.md: the accuracy check's verdicts on systems nobody chose, set
beside their true error, with the named cases and the built-in scenes.

1. **Random systems** (``ddvp_nlp.studies.verdict_study``): ``--cases`` Hamiltonians drawn with a
   fixed seed (polynomial and trigonometric potentials in 1-3 degrees of freedom, couplings,
   non-separable terms, forcing and gauge terms, units from 1e-4 to 1e4 with offsets and
   translations, first steps across the breakdown range, vddvp, lee and fixed steps), each
   marched and judged, its true error measured against scipy's DOP853 at rtol 1e-12 with dense
   output (checked against a run at 1e-10). Counted: false successes and false refusals (the
   definitions of ``studies.verdicts.classify``), and the ratio of the verdict's error to the
   true error. Every row goes to random.csv.
2. **Named cases**: the issue's examples and the Kepler grid of the first version of this page
   (e = 0.5 .. 0.99, tau0 = 0.001 .. 1), each with its verdict and its true error against the
   exact solution.
3. **The built-in scenes at their defaults**: verdict, t_drift, largest error.

    python scripts/pages/accuracy_study.py [--cases 1200] [--seed 27] [--out docs/accuracy]
        [--quick]

About 20 minutes of CPU (1200 cases: 1192 s CPU, 1911 s wall at load 2, after the check
moved to the one exact flow; 164 s before it); ``--quick`` (12 cases, a 2 x 2 Kepler grid, not for
docs/) seconds. The page's seconds stand beside the machine and the date
(``ddvp_nlp.io.machine``).
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import time
import warnings
from collections import Counter
from pathlib import Path

import numpy as np

from ddvp_nlp import Tolerance, list_scenes, load_scene, march
from ddvp_nlp.io import machine
from ddvp_nlp.scenes import HigherOrderScene
from ddvp_nlp.solvers import march_higher, motion_scales
from ddvp_nlp.studies import MARGIN, draw_case, judge_case

ROOT = Path(__file__).resolve().parents[2]
ECCENTRICITIES = (0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 0.99)
TAU0 = (0.001, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0)
QUICK_KEPLER = ((0.5, 0.9), (0.01, 0.1))
COLUMNS = ("case", "n", "potential", "scheme", "time_dependent", "status", "steps", "verdict",
           "failure", "t_drift", "estimate", "true", "true_all", "truth_error", "class")


def random_rows(count: int, seed: int, progress: bool):
    rng = np.random.default_rng(seed)
    rows = []
    started = time.perf_counter()
    for k in range(count):
        case = draw_case(rng)
        try:
            row = judge_case(case)
        except Exception as exc:  # a case the tools cannot run is reported, never dropped
            row = {"verdict": "", "status": f"error: {type(exc).__name__}: {exc}",
                   "class": "error", "n": case.system.n, "potential": case.system.potential,
                   "scheme": case.scheme, "time_dependent": case.system.time_dependent}
        row["case"] = k
        rows.append(row)
        if progress and (k + 1) % 50 == 0:
            print(f"  {k + 1} cases, {time.perf_counter() - started:.0f} s", flush=True)
    return rows


def kepler_rows(eccentricities=ECCENTRICITIES, steps=TAU0):
    """The Kepler grid: every verdict beside the true error against the exact solution."""
    scene = load_scene("kepler")
    rows = []
    for e in eccentricities:
        for tau0 in steps:
            config = scene.resolve({"e": e, "tau0": tau0})
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                solution = march(scene.system, config.q0, config.p0, (0.0, config.t_end),
                                 tau0=tau0, params=config.params,
                                 accuracy=Tolerance(stop=False))
            z = np.hstack([solution.q, solution.p])
            q, p = scene.exact(solution.t, config.q0, config.p0, 0.0, **config.params)
            truth = np.hstack([q, p])
            both = np.vstack([z, truth])
            scale = motion_scales(both.min(axis=0), both.max(axis=0), np.abs(both).max(axis=0),
                                  2)
            true = float(np.max(np.abs(z - truth) / scale))
            report = solution.verdict.as_dict()
            rows.append({"e": e, "tau0": tau0, "status": solution.status.code,
                         "steps": solution.steps, "verdict": report["verdict"],
                         "t_drift": report["t_drift"], "true": true,
                         "failure": (report["first_failure"] or {}).get("test", "")})
    return rows


def scene_rows():
    rows = []
    for name in list_scenes():
        scene = load_scene(name)
        config = scene.resolve({})
        started = time.perf_counter()
        if isinstance(scene, HigherOrderScene):
            t_init, q_init = scene.start(config)
            solution = march_higher(scene.system, t_init, q_init, t_end=config.t_end,
                                    scheme=scene.scheme, params=config.params)
        else:
            solution = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                             v0=config.v0, tau0=config.tau0, params=config.params)
        report = solution.verdict.as_dict()
        rows.append({"scene": name, "status": solution.status.code, "steps": solution.steps,
                     "tau0": config.tau0, "t_end": config.t_end, "verdict": report["verdict"],
                     "t_drift": report["t_drift"], "error_max": report["error_max"],
                     "estimate": report["estimate"].split(" (")[0],
                     "seconds": time.perf_counter() - started})
    return rows


def _ratio_lines(rows) -> list[str]:
    """The verdict's error against the true error over the same nodes."""
    pairs = np.array([(r["estimate"], r["true"]) for r in rows
                      if r["class"] not in ("untrusted", "error") and r["true"] > 1e-9])
    if not pairs.size:
        return ["(no case with a measurable error)"]
    ratio = pairs[:, 0] / pairs[:, 1]
    quantiles = np.quantile(ratio, [0.0, 0.01, 0.5, 0.99, 1.0])
    far = ratio[np.abs(ratio - 1) > 1e-3]
    return [f"Over the {ratio.size} trusted cases with a true error above 1e-9 of the motion's "
            "size (the verdict's error is over the nodes its scan covered, up to `t_drift` "
            "for a drifted run; the true error over the same nodes, with the scales of the "
            "nodes and of the true states up to there, as the verdict's): ratio estimate / true "
            f"min {quantiles[0]:.6f}, 1% {quantiles[1]:.6f}, median {quantiles[2]:.6f}, 99% "
            f"{quantiles[3]:.6f}, max {quantiles[4]:.6f}; {far.size} cases off by more than "
            "0.1%."]


def random_section(rows, seed: int, seconds: float) -> list[str]:
    classes = Counter(r["class"] for r in rows)
    verdicts = Counter(r["verdict"] for r in rows if r["class"] != "error")
    false = [r for r in rows if r["class"] in ("false success", "false refusal")]
    lines = ["## Random systems", "",
             f"`python scripts/pages/accuracy_study.py --cases {len(rows)} --seed {seed}`: "
             f"{len(rows)} cases in {seconds:.0f} s (every row in [random.csv](random.csv)); "
             f"{machine()}", "",
             "| | count |", "|---|---|"]
    for name in ("false success", "false refusal", "consistent", "band", "untrusted", "error"):
        lines.append(f"| {name} | {classes.get(name, 0)} |")
    lines += ["", "Verdicts: " + ", ".join(f"{v or '(none)'} {c}" for v, c in
                                          sorted(verdicts.items())) + ".", ""]
    by = Counter((r["scheme"], r["verdict"]) for r in rows if r["class"] != "error")
    lines += ["By scheme: " + "; ".join(f"{s} {v} {c}" for (s, v), c in sorted(by.items()))
              + ".", ""]
    statuses = Counter(r["status"] for r in rows)
    lines += ["March statuses (a failed march is judged on the nodes it kept): "
              + ", ".join(f"{s} {c}" for s, c in sorted(statuses.items())) + ".", ""]
    lines += _ratio_lines(rows) + [""]
    if false:
        lines += ["The false verdicts:", "", "| case | verdict | true | estimate | failure |",
                  "|---|---|---|---|---|"]
        lines += [f"| {r['case']} | {r['verdict']} | {r['true_all']:.3e} | "
                  f"{r['estimate']:.3e} | {r['failure']} |" for r in false]
        lines.append("")
    return lines


def named_section(kepler, scenes) -> list[str]:
    lines = ["## The built-in scenes at their defaults", "",
             "| scene | tau0 | t_end | status | steps | verdict | t_drift | largest error | "
             "measured against | s |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in scenes:
        drift = "" if r["t_drift"] is None else f"{r['t_drift']:.4g}"
        lines.append(f"| {r['scene']} | {r['tau0']:g} | {r['t_end']:.6g} | {r['status']} | "
                     f"{r['steps']} | {r['verdict']} | {drift} | {r['error_max']:.2e} | "
                     f"{r['estimate']} | {r['seconds']:.2f} |")
    lines += ["", "The largest error of a drifted run is over the nodes up to `t_drift` (the "
              "scan stops there).", "", "## Kepler orbits", "",
              "vddvp over ten periods; the true error against the exact solution, relative to "
              "the motion's size, over the whole run.", "",
              "| e | tau0 | status | steps | verdict | t_drift | true error | failed test |",
              "|---|---|---|---|---|---|---|---|"]
    for r in kepler:
        drift = "" if r["t_drift"] is None else f"{r['t_drift']:.4g}"
        lines.append(f"| {r['e']} | {r['tau0']} | {r['status']} | {r['steps']} | "
                     f"{r['verdict']} | {drift} | {r['true']:.2e} | {r['failure']} |")
    wrong = [r for r in kepler if (r["verdict"] == "accurate" and r["true"] > MARGIN * 1e-2)
             or (r["verdict"] != "accurate" and r["true"] < 1e-2 / MARGIN)]
    lines += ["", f"False verdicts among these {len(kepler)} runs: {len(wrong)}.", ""]
    return lines


def page(rows, kepler, scenes, seed, seconds) -> str:
    intro = [
        "# The accuracy check on systems nobody chose", "",
        "Every run ends with one of three verdicts (`ddvp_nlp/solvers/accuracy/judgement.py`): "
        "`accurate` (the trajectory error stays within `global_tol` of the motion's size "
        "over the whole run), `drifted` (every step follows the flow and the energy is right, "
        "but the trajectory error passes `global_tol` from `t_drift` on) or `inaccurate` (a "
        "step does not follow the flow, or the energy level is wrong). Defaults: `global_tol "
        "= rtol = 1e-2`, `energy_tol = 0.1`; every figure is relative to the motion's own "
        "scales.", "",
        "**How a verdict is judged** (`ddvp_nlp.studies.verdict_study.classify`). The true error "
        "of a run is `max_k max_i |z_k,i - z_i(t_k)| / S_i` over its nodes, `z(t)` scipy's "
        "DOP853 at `rtol = 1e-12` with dense output from the run's own start, `S_i` the range "
        "of component `i` over the run's nodes and the true states (at least a tenth of the "
        "largest range of its block). A **false success** is a verdict `accurate` with a true "
        f"error above `{MARGIN:g} global_tol`; a **false refusal** a verdict `drifted` or "
        f"`inaccurate` with a true error below `global_tol / {MARGIN:g}`; between the two "
        "(`band`) either verdict is consistent. A case whose truth is not trusted (DOP853 at "
        "1e-10 differs from it by more than `global_tol / 20` of the motion's size at some "
        "node: a chaotic orbit past its horizon) is counted apart (`untrusted`).", ""]
    return "\n".join(intro + random_section(rows, seed, seconds)
                     + named_section(kepler, scenes)) + "\n"


def write_csv(rows, path: Path):
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: (f"{v:.6e}" if isinstance(v, float) and math.isfinite(v)
                                 else v) for k, v in row.items()})


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=1200)
    parser.add_argument("--seed", type=int, default=27)
    parser.add_argument("--out", default=str(ROOT / "docs" / "accuracy"))
    parser.add_argument("--quick", action="store_true",
                        help="12 cases and a 2 x 2 Kepler grid (not for docs/)")
    args = parser.parse_args()
    if args.quick:
        args.cases = 12
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    rows = random_rows(args.cases, args.seed, progress=True)
    seconds = time.perf_counter() - started
    kepler = kepler_rows(*QUICK_KEPLER) if args.quick else kepler_rows()
    scenes = scene_rows()
    write_csv(rows, out / "random.csv")
    (out / "README.md").write_text(page(rows, kepler, scenes, args.seed, seconds))
    classes = Counter(r["class"] for r in rows)
    print(f"{len(rows)} cases in {seconds:.0f} s (load average {os.getloadavg()[0]:.2f}): "
          + ", ".join(f"{k} {v}" for k, v in sorted(classes.items())))
    print(f"written to {out}/README.md and {out}/random.csv")


if __name__ == "__main__":
    main()
