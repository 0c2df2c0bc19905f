"""Rebuild the generated documentation: every page builder of this folder in order, each as a
process of its own; says what each rebuilt and how long it took.

    python scripts/pages/build_docs.py [--quick] [--only NAME,...] [--skip NAME,...]
        [--out DIR] [--list]

``--out`` is the docs folder written into (default: the repository's ``docs/``; with
``--quick``, ``/tmp/ddvp-docs-quick``, so that quick numbers never replace a page). ``--quick``
runs every builder in its quick mode (smaller grids, one timed call): minutes in all, to check
that the builders run, not to publish. A full build takes hours, most of them the long horizons
(``--skip horizons`` leaves them out); run it with nothing else busy on the machine, because the
pages' timings are measured. Every page that shows a timing says the machine and the date
(``ddvp_nlp.io.machine``). The site itself is built afterwards by ``mkdocs build --strict``.

Exit code: 0 when every builder that ran succeeded, else 1 (the others still run).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAGES = Path(__file__).resolve().parent
BENCHMARKS = ROOT / "scripts" / "benchmarks"


@dataclass(frozen=True)
class Builder:
    name: str
    script: Path
    target: str            # what it writes, relative to the docs folder
    arguments: tuple       # given after --out (the full build)
    quick: tuple           # given after --out with --quick
    duration: str          # of a full build, as measured
    out_is_docs: bool = False  # --out is the docs folder itself, not the target
    by_default: bool = True


BUILDERS = [
    Builder("comparison", PAGES / "comparison_page.py", "comparison", (), ("--quick",),
            "about 8 minutes (the horizons' runs)"),
    Builder("reproduce", PAGES / "reproduce_page.py", "reproduce", (), ("--quick",),
            "a few minutes"),
    Builder("accuracy", PAGES / "accuracy_study.py", "accuracy", (), ("--quick",),
            "about 5 minutes"),
    Builder("periodic", PAGES / "periodic_page.py", "periodic", (), ("--quick",),
            "a few minutes"),
    Builder("stability", PAGES / "stability_study.py",
            "periodic (stability.md, bifurcations.md) and transfers", (), ("--quick",),
            "about 10 minutes", out_is_docs=True),
    Builder("poincare", PAGES / "poincare_page.py", "poincare", (), ("--quick",),
            "a few minutes"),
    Builder("stress", PAGES / "stress.py", "stress", (), ("--quick",), "about a minute"),
    Builder("work_precision", PAGES / "work_precision.py", "work_precision", (),
            ("--quick",), "about 5 minutes"),
    Builder("horizons", PAGES / "work_precision.py", "work_precision/horizons",
            ("--horizons",), ("--horizons", "--quick"), "hours", out_is_docs=True),
    Builder("faults", PAGES / "faults.py", "reliability/faults.md", (), ("--quick",),
            "about 10 minutes; as root, on real tmpfs disks"),
    Builder("bench_accuracy", BENCHMARKS / "bench_accuracy.py", "benchmarks/bench_accuracy.md",
            (), ("--repeats", "1"), "about a minute"),
    # the comparison figures redrawn from their rows: after a change of the figure code only
    Builder("figures", PAGES / "redraw_figures.py", "work_precision", (), (), "seconds",
            by_default=False),
]


def command(builder: Builder, docs: Path, quick: bool) -> list[str]:
    """The builder's command line writing into the docs folder ``docs``."""
    if builder.name == "horizons":  # work_precision.py --horizons writes into OUT/horizons
        out = docs / "work_precision"
    elif builder.out_is_docs:
        out = docs
    else:
        out = docs / builder.target
    flag = "--root" if builder.name == "figures" else "--out"
    return [sys.executable, str(builder.script), flag, str(out),
            *(builder.quick if quick else builder.arguments)]


def chosen(only: str | None, skip: str | None) -> list[Builder]:
    names = {b.name for b in BUILDERS}
    asked = [n for n in (only or "").split(",") if n] + [n for n in (skip or "").split(",") if n]
    unknown = sorted(set(asked) - names)
    if unknown:
        raise SystemExit(f"unknown builder {', '.join(unknown)} (known: "
                         f"{', '.join(b.name for b in BUILDERS)})")
    if only:
        wanted = set(only.split(","))
        return [b for b in BUILDERS if b.name in wanted]
    skipped = set((skip or "").split(","))
    return [b for b in BUILDERS if b.by_default and b.name not in skipped]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="every builder's quick mode, into /tmp/ddvp-docs-quick by default")
    parser.add_argument("--only", default=None, help="builders to run, comma-separated")
    parser.add_argument("--skip", default=None, help="builders to leave out, comma-separated")
    parser.add_argument("--out", default=None, help="the docs folder to write into")
    parser.add_argument("--list", action="store_true", help="list the builders and stop")
    args = parser.parse_args()
    if args.list:
        for b in BUILDERS:
            print(f"{b.name:15s} {b.script.relative_to(ROOT)} -> docs/{b.target} "
                  f"({b.duration}{'' if b.by_default else '; only with --only'})")
        return 0
    docs = Path(args.out or ("/tmp/ddvp-docs-quick" if args.quick else ROOT / "docs"))
    docs.mkdir(parents=True, exist_ok=True)
    done = []
    for builder in chosen(args.only, args.skip):
        argv = command(builder, docs, args.quick)
        print(f"== {builder.name}: {' '.join(argv[1:])}", flush=True)
        started = time.perf_counter()
        code = subprocess.run(argv, cwd=ROOT).returncode
        seconds = time.perf_counter() - started
        done.append((builder, code, seconds))
        print(f"== {builder.name}: exit {code} after {seconds:.0f} s", flush=True)
    print(f"\nRebuilt into {docs}{' (quick)' if args.quick else ''}:")
    for builder, code, seconds in done:
        print(f"  {builder.name:15s} {'ok    ' if code == 0 else f'exit {code}'} "
              f"{seconds:7.0f} s  {builder.target}")
    return 0 if all(code == 0 for _, code, _ in done) else 1


if __name__ == "__main__":
    sys.exit(main())
