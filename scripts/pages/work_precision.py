"""Regenerate docs/work_precision/: work-precision reports of six scenes, and over long horizons.

Default horizons (``docs/work_precision/SCENE/``): each scene runs every method that applies
(``ddvp compare`` with its defaults) on its default horizon, Kepler at e = 0.6 and FPU at
omega = 50; from seconds (harmonic) to about three minutes (paper_pendulum, to t = 10000).

Long horizons (``--horizons``, ``docs/work_precision/horizons/CASE/``): Kepler at e = 0.6 and
0.9, the pendulum, Henon-Heiles and FPU at 10, 10^3 and 10^5 periods (FPU: of its stiff
springs), each
a ``ddvp compare --horizons`` run with its error-growth figure, then
``docs/work_precision/horizons/README.md``, the summary in words computed from the rows
(``--summary-only`` rewrites it from the runs already on disk). Tens of minutes per case.

Run it with nothing else busy on the machine: the run times are what is compared; every report
ends with the machine and the date (``ddvp_nlp.io.machine``). Each run's folder is written to a
scratch folder and only what the pages show or read back (the reports, the figures, the rows of
``work_precision.csv``, from which ``redraw_figures.py`` and ``--summary-only`` work) is copied
into ``--out``.

    python scripts/pages/work_precision.py [--scenes paper_pendulum,harmonic]
        [--out docs/work_precision] [--quick]
    python scripts/pages/work_precision.py --horizons [--cases kepler_e0.6,fpu] [--summary-only]
        [--quick]

``--quick`` (not for docs/): the harmonic oscillator alone, two halvings, one timed call; with
``--horizons``, the pendulum at 10 and 30 periods.
"""

from __future__ import annotations

import argparse
import math
import shutil
import tempfile
import time
from pathlib import Path

from scipy.special import ellipk

from ddvp_nlp import load_scene
from ddvp_nlp.cli import main as ddvp
from ddvp_nlp.studies import (
    ERROR_KINDS,
    CompareOptions,
    cheapest,
    in_words,
    methods_in,
    read_rows,
    winner_spans,
    work_precision_horizons,
)

ROOT = Path(__file__).resolve().parents[2]
# what a page shows or reads back: the rest of a run's folder (its manifest) stays in scratch
SHOWN = ("*.md", "*.png", "work_precision.csv")

SCENES = {
    "paper_pendulum": {},
    "harmonic": {},
    "pendulum": {},
    "kepler": {"e": 0.6},
    "henon_heiles": {},
    "fpu": {"omega": 50.0},
}


def _pendulum_period() -> float:
    """The period of the pendulum scene's default libration, 4 K(k), k^2 = H/2."""
    config = load_scene("pendulum").resolve({})
    energy = config.p0[0] ** 2 / 2 + 1 - math.cos(config.q0[0])
    return 4 * float(ellipk(energy / 2))


TWO_PI = 2 * math.pi
HORIZONS = "10,1000,100000"
# case: (scene, overrides, time unit and its name)
HORIZON_CASES = {
    "kepler_e0.6": ("kepler", {"e": 0.6}, TWO_PI, "periods"),
    "kepler_e0.9": ("kepler", {"e": 0.9}, TWO_PI, "periods"),
    "pendulum": ("pendulum", {}, None, "periods"),
    "henon_heiles": ("henon_heiles", {}, TWO_PI, "linear periods (2 pi)"),
    # FPU's periods: those of its stiff springs, 2 pi / omega (the slow exchange of their
    # energies takes about omega of them)
    "fpu": ("fpu", {"omega": 50.0}, TWO_PI / 50.0, "stiff periods (2 pi / omega)"),
}


def copy_shown(source: Path, target: Path) -> None:
    """The files of ``SHOWN`` below ``source``, copied to the same places below ``target``; a
    long-horizon case's figure per horizon stays behind (``horizons.png`` has a panel each)."""
    for pattern in SHOWN:
        for path in source.rglob(pattern):
            if path.name == "work_precision.png" and path.parent.name.startswith("horizon_"):
                continue
            place = target / path.relative_to(source)
            place.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, place)


def run_horizons(cases, out: Path, args) -> None:
    for case in cases:
        name, overrides, unit, _ = HORIZON_CASES[case]
        unit = unit or _pendulum_period()
        started = time.perf_counter()
        with tempfile.TemporaryDirectory(prefix="horizons-") as scratch:
            work_precision_horizons(load_scene(name), args.horizon_list, out=scratch,
                                    unit=unit, overrides=overrides,
                                    options=CompareOptions(halvings=args.halvings,
                                                           repeats=args.repeats,
                                                           max_steps=args.max_steps),
                                    run_budget_s=args.run_budget, progress=True)
            copy_shown(Path(scratch), out / case)
        print(f"{case}: {time.perf_counter() - started:.0f} s -> {out / case}/horizons.md",
              flush=True)


def _wins(rows, method) -> list[str]:
    """Where ``method`` is the cheapest, as ``kind from A down to B`` phrases."""
    found = []
    for kind, label in ERROR_KINDS.items():
        for winner, high, low in winner_spans(rows, kind):
            if winner == method:
                found.append(f"{label.split(' max')[0]} {high:.0e}"
                             + (f" to {low:.0e}" if low != high else ""))
    return found


def _verdicts(rows) -> list[str]:
    """The cheapest method per error range, per error kind, and where the paper's schemes
    win, as indented list items (computed from the rows)."""
    methods, lines = methods_in(rows), []
    for kind, label in ERROR_KINDS.items():
        text = in_words(rows, kind, methods).removeprefix("In words: ")
        lines.append(f"  - {label.split(' max')[0]}: {text}")
    for method in ("vddvp", "lee"):
        if method in methods:
            wins = _wins(rows, method)
            lines.append(f"  - `{method}` is the cheapest " + (
                "at: " + "; ".join(wins) if wins else "nowhere on these runs") + ".")
    return lines


def default_summary(out: Path) -> str:
    """``docs/work_precision/README.md``: every scene's verdicts on its default horizon."""
    lines = ["# Work-precision on each scene's default horizon", "",
             "Regenerate: `python scripts/pages/work_precision.py` (the runs and this page); "
             "the long horizons are in [horizons/](horizons/README.md). Each scene's full "
             "report is `SCENE/summary.md`.", ""]
    for name, overrides in SCENES.items():
        path = out / name / "work_precision.csv"
        if not path.exists():
            continue
        settings = ", ".join(f"{k} = {v:g}" for k, v in overrides.items())
        lines.append(f"- **`{name}`**" + (f" ({settings})" if settings else "")
                     + f", [report]({name}/summary.md):")
        lines += _verdicts(read_rows(path))
    lines += [""] + [f"![{name}]({name}/work_precision.png)" for name in SCENES
                     if (out / name / "work_precision.png").exists()] + [""]
    return "\n".join(lines)


def horizons_summary(out: Path) -> str:
    """The summary in words of every case on disk, computed from its rows."""
    lines = ["# Long horizons: which method, at which error level", "",
             "Regenerate: `python scripts/pages/work_precision.py --horizons` (the runs), or "
             "`--horizons --summary-only` (this page from the runs on disk). Each case's own "
             "page (`CASE/horizons.md`) has the error-growth table at equal cost and the runs "
             "left out; each horizon's full report is in `CASE/horizon_T/summary.md`.", ""]
    for case, (name, overrides, _, unit_name) in HORIZON_CASES.items():
        folder = out / case
        horizons = sorted((float(p.name.removeprefix("horizon_")), p)
                          for p in folder.glob("horizon_*") if (p / "work_precision.csv").exists())
        if not horizons:
            continue
        settings = ", ".join(f"{k} = {v:g}" for k, v in overrides.items())
        lines += [f"## {case}: `{name}`" + (f" ({settings})" if settings else ""), ""]
        for horizon, path in horizons:
            lines.append(f"- **{horizon:g} {unit_name}.**")
            lines += _verdicts(read_rows(path / "work_precision.csv"))
        lines += ["", f"![{case}]({case}/horizons.png)", f"![{case} growth]({case}/growth.png)",
                  ""]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default=",".join(SCENES))
    parser.add_argument("--out", default=str(ROOT / "docs" / "work_precision"))
    parser.add_argument("--repeats", type=int, default=None,
                        help="timed calls per run (default: 3; 1 with --horizons)")
    parser.add_argument("--horizons", action="store_true",
                        help="the long-horizon cases instead of the default horizons")
    parser.add_argument("--cases", default=",".join(HORIZON_CASES))
    parser.add_argument("--horizon-list", default=HORIZONS)
    parser.add_argument("--summary-only", action="store_true",
                        help="rewrite the summary page from the runs on disk")
    parser.add_argument("--halvings", type=int, default=2)
    parser.add_argument("--max-steps", type=int, default=10_000_000)
    parser.add_argument("--run-budget", type=float, default=60.0)
    parser.add_argument("--quick", action="store_true",
                        help="harmonic alone (with --horizons: the pendulum at 10 and 30 "
                             "periods), two halvings, one timed call; not for docs/")
    args = parser.parse_args()
    if args.quick:
        args.scenes, args.cases, args.horizon_list = "harmonic", "pendulum", "10,30"
        args.repeats, args.halvings, args.run_budget = 1, 2, 5.0
    if args.repeats is None:
        args.repeats = 1 if args.horizons else 3
    if args.horizons:
        out = Path(args.out) / "horizons"
        if not args.summary_only:
            run_horizons([c for c in args.cases.split(",") if c], out, args)
        out.mkdir(parents=True, exist_ok=True)
        (out / "README.md").write_text(horizons_summary(out))
        print(f"summary -> {out}/README.md")
        return
    for name in [] if args.summary_only else args.scenes.split(","):
        started = time.perf_counter()
        folder = Path(args.out) / name
        # `ddvp compare` with the scene's settings: the command a reader reruns
        argv = ["compare", name, "--repeats", str(args.repeats), "--progress",
                *(f"--set={key}={value!r}" for key, value in SCENES[name].items()),
                *(["--halvings", str(args.halvings)] if args.quick else [])]
        with tempfile.TemporaryDirectory(prefix="work-precision-") as scratch:
            code = ddvp([*argv, "--out", scratch])
            if code != 0:
                raise SystemExit(f"ddvp {' '.join(argv)}: exit {code}")
            rows = read_rows(Path(scratch) / "work_precision.csv")
            copy_shown(Path(scratch), folder)
        failed = sum(r["status"] != "success" for r in rows)
        print(f"{name}: {len(rows)} runs ({failed} did not reach t_end) in "
              f"{time.perf_counter() - started:.0f} s -> {folder}/summary.md")
        for kind, label in ERROR_KINDS.items():
            winners = []
            for level in (1e-2, 1e-4, 1e-6, 1e-8):
                ranking = cheapest(rows, kind, level)
                if ranking:
                    winners.append(f"{level:.0e}: {ranking[0][0]}")
            print(f"  {label.split(' max')[0]}: " + ", ".join(winners))
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "README.md").write_text(default_summary(Path(args.out)))
    print(f"summary -> {args.out}/README.md")


if __name__ == "__main__":
    main()
