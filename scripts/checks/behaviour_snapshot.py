"""Behaviour snapshot: the same command-line runs before and after a change, compared bit for bit.

A change that must not change behaviour (a layout change, a refactor) is checked by running
this script once on the old tree (``take``), once on the new one (``take`` into another folder)
and comparing the two (``compare``). Only the ``ddvp`` command is used, so the script runs
unchanged on both trees.

    python scripts/checks/behaviour_snapshot.py take /tmp/before
    ... change the code ...
    python scripts/checks/behaviour_snapshot.py take /tmp/after
    python scripts/checks/behaviour_snapshot.py compare /tmp/before /tmp/after

What is compared, run by run: the exit code; every array of every ``.npz`` file (bit for bit,
NaN equal to NaN); in every ``meta.json`` the status, message, steps and the accuracy verdict
with its figures; in every ``.csv`` file every column but the timing ones. Timings, dates and
paths are left out: they differ between any two runs.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

# Each run: (name, arguments after `ddvp`), in the command line of the tree being snapshotted
# (a run keeps its name when its arguments change spelling: before the layout change of issue
# 36 periodic --nodes counted intervals (100 became 101) and compared methods ran with
# --scheme NAME, now --method NAME). --out and
# --no-progress are added. The set covers
# every command, every built-in scene, every compared method, both grid solvers and the
# options that change a path through the code (events, output times, guesses, families).
RUNS: list[tuple[str, str]] = [
    *[(f"march-{scene}", f"march {scene} --no-plot") for scene in (
        "cr3bp", "figure_eight", "fpu", "harmonic", "henon_heiles", "kepler",
        "pais_uhlenbeck", "paper_pendulum", "pendulum", "pendulum_lagrangian", "spline")],
    *[(f"march-pendulum-{rule}", f"march pendulum --scheme {rule} --no-plot")
      for rule in ("lee", "fixed")],
    *[(f"march-pendulum-{method}", f"march pendulum --method {method} --no-plot")
      for method in ("midpoint", "stormer_verlet", "leapfrog", "verlet_adaptive", "avf", "rk4",
                     "dop853", "lee_left")],
    ("march-kepler-e06", "march kepler --set e=0.6 --no-plot"),
    ("march-kepler-dop853-coarse", "march kepler --method dop853 --tol 1e-2 --set e=0.9 "
     "--no-plot"),
    ("march-pais-coarse", "march pais_uhlenbeck --set g=0.01 --set tau0=0.3 --no-plot"),
    ("march-pendulum-careful", "march pendulum --careful --set t_end=20 --no-plot"),
    ("march-pendulum-teval-event", "march pendulum --t-eval 0:50:11 "
     "--event 'q1;up' --event 'p1;down;terminal=3' --no-plot"),
    ("march-pendulum-left-alpha", "march pendulum --alpha 0.3 --clock left --set t_end=20 "
     "--no-plot"),
    ("march-pendulum-energy-guard", "march pendulum --energy-guard 1e-12 --no-plot"),
    ("march-pendulum-rotation", "march pendulum --set p0=2.2 --no-plot"),
    ("march-pendulum-least-squares", "march pendulum --set p0=2.2 --least-squares --no-plot"),
    ("march-paper-pendulum-plot", "march paper_pendulum --set t_end=50"),
    ("march-henon-require", "march henon_heiles --require-accurate --no-plot"),
    ("march-kepler-tols", "march kepler --rtol 1e-3 --global-tol 1e-3 --energy-tol 1e-2 "
     "--no-plot"),
    ("march-cr3bp-max-steps", "march cr3bp --max-steps 50 --no-plot"),
    *[(f"bvp-{scene}", f"bvp {scene} --no-plot") for scene in (
        "pendulum", "paper_pendulum", "pendulum_lagrangian", "pais_uhlenbeck", "spline")],
    ("bvp-pendulum-newton", "bvp pendulum --solver newton --nodes 401 --no-plot"),
    ("bvp-pendulum-ipopt", "bvp pendulum --solver ipopt --nodes 401 --no-plot"),
    ("bvp-pendulum-guess-march", "bvp pendulum --guess march --no-plot"),
    ("bvp-pendulum-lee", "bvp pendulum --scheme lee --no-plot"),
    ("bvp-pendulum-fixed", "bvp pendulum --scheme fixed --no-plot"),
    ("bvp-pendulum-energy", "bvp pendulum --energy 0.3 --no-plot"),
    ("bvp-harmonic-conjugate", "bvp harmonic --set q_start=1 --set q_end=0.5 --set t0=0 "
     "--set t_end=3.141592653589793 --no-plot"),
    ("bvp-spline-ipopt", "bvp spline --solver ipopt --no-plot"),
    ("bvp-pais-plot", "bvp pais_uhlenbeck"),
    ("periodic-pendulum", "periodic pendulum --energy 0.5 --nodes 101"),
    ("periodic-pendulum-ipopt", "periodic pendulum --energy 0.5 --nodes 101 --solver ipopt "
     "--no-plot"),
    ("periodic-pendulum-coarse", "periodic pendulum --energy 1e-4 --nodes 5 --no-plot"),
    ("periodic-henon-stability", "periodic henon_heiles --energy 0.1 --nodes 101 --stability "
     "--no-plot"),
    ("periodic-pendulum-family", "periodic pendulum --energy 0.3 --nodes 61 "
     "--family 0.3:1.2:4 --stability"),
    ("periodic-pendulum-follow", "periodic pendulum --energy 0.3 --nodes 61 --follow 1.5 "
     "--max-orbits 6 --no-plot"),
    ("poincare-henon", "poincare henon_heiles --energy 0.125 --orbits 4 --t-end 200 "
     "--workers 1"),
    ("compare-pendulum", "compare pendulum --methods vddvp,midpoint,rk4,dop853 --halvings 2 "
     "--repeats 1 --set t_end=10"),
    ("stress-quick", "stress --quick --workers 1"),
    ("sweep-pendulum", "sweep pendulum --grid tau0=0.05,0.1 --methods vddvp,rk4 "
     "--set t_end=10 --workers 1"),
    ("reproduce-quick", "reproduce --quick"),
]

# CSV columns that hold times of the machine, not results.
TIMING_WORDS = ("time", "cpu", "wall", "seconds", "elapsed", "date", "_s")
# CSV columns of the journal's bookkeeping: the fingerprint hashes the task's function by its
# module path (a moved module changes it by design: an old journal's rows are then run again),
# and the checksum covers the fingerprint.
BOOKKEEPING = ("fingerprint", "row_sha256")


def take(folder: Path, only: list[str]) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    environment = dict(os.environ, DDVP_NLP_CACHE=str(folder / "cache"))
    total = time.perf_counter()
    for name, arguments in RUNS:
        if only and name not in only:
            continue
        out = folder / name
        command = ["ddvp", *shlex.split(arguments), "--out", str(out), "--no-progress"]
        start = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True, env=environment,
                              timeout=1800)
        record = {"command": shlex.join(command[1:]), "exit": done.returncode,
                  "stderr_tail": done.stderr[-2000:], "stdout_tail": done.stdout[-2000:]}
        out.mkdir(parents=True, exist_ok=True)
        (out / "snapshot.json").write_text(json.dumps(record, indent=1))
        print(f"{name:36s} exit {done.returncode}  {time.perf_counter() - start:7.1f} s",
              flush=True)
    print(f"all runs: {time.perf_counter() - total:.1f} s")


def _meta_fields(meta: dict) -> dict:
    """What a meta.json says about the result (not when or where or how fast)."""
    keep = {}
    for key in ("status", "message", "steps", "scheme", "scene", "verdict", "nodes",
                "energy_error", "energy", "period"):
        if key in meta:
            keep[key] = meta[key]
    accuracy = meta.get("accuracy")
    if isinstance(accuracy, dict):
        keep["accuracy"] = {k: v for k, v in accuracy.items() if "time" not in k}
    return keep


def _csv_rows(path: Path) -> list[dict]:
    with open(path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    return [{k: v for k, v in row.items()
             if k is not None and k not in BOOKKEEPING
             and not any(word in k.lower() for word in TIMING_WORDS)}
            for row in rows]


def _same_json(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same_json(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same_json(x, y) for x, y in zip(a, b, strict=True))
    return a == b


def compare_runs(before: Path, after: Path) -> list[str]:
    differences = []
    for name, _ in RUNS:
        a_dir, b_dir = before / name, after / name
        if not (a_dir / "snapshot.json").exists():
            continue
        if not (b_dir / "snapshot.json").exists():
            differences.append(f"{name}: not run after")
            continue
        a_rec = json.loads((a_dir / "snapshot.json").read_text())
        b_rec = json.loads((b_dir / "snapshot.json").read_text())
        if a_rec["exit"] != b_rec["exit"]:
            differences.append(f"{name}: exit {a_rec['exit']} -> {b_rec['exit']}")
        files_a = {p.relative_to(a_dir) for p in a_dir.rglob("*") if p.is_file()}
        files_b = {p.relative_to(b_dir) for p in b_dir.rglob("*") if p.is_file()}
        for rel in sorted(files_a):
            if rel.suffix not in (".npz", ".csv") and rel.name != "meta.json":
                continue
            if rel not in files_b:
                differences.append(f"{name}: {rel} missing after")
                continue
            differences += [f"{name}: {rel}: {d}" for d in _compare_file(a_dir / rel,
                                                                          b_dir / rel)]
    return differences


def _compare_file(a: Path, b: Path) -> list[str]:
    if a.suffix == ".npz":
        with np.load(a, allow_pickle=False) as x, np.load(b, allow_pickle=False) as y:
            if set(x.files) != set(y.files):
                return [f"arrays {sorted(x.files)} -> {sorted(y.files)}"]
            out = []
            for key in x.files:
                u, v = x[key], y[key]
                same = u.shape == v.shape and u.dtype == v.dtype and (
                    np.array_equal(u, v, equal_nan=u.dtype.kind == "f"))
                if not same:
                    out.append(f"array {key} differs")
            return out
    if a.suffix == ".csv":
        return [] if _csv_rows(a) == _csv_rows(b) else ["rows differ"]
    meta_a = _meta_fields(json.loads(a.read_text()))
    meta_b = _meta_fields(json.loads(b.read_text()))
    if _same_json(meta_a, meta_b):
        return []
    keys = sorted(set(meta_a) | set(meta_b))
    return [f"meta {k}: {meta_a.get(k)!r:.200} -> {meta_b.get(k)!r:.200}" for k in keys
            if not _same_json(meta_a.get(k), meta_b.get(k))]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="action", required=True)
    taking = sub.add_parser("take", help="run every command into FOLDER")
    taking.add_argument("folder", type=Path)
    taking.add_argument("--only", nargs="*", default=[], help="run only these names")
    comparing = sub.add_parser("compare", help="compare two snapshots")
    comparing.add_argument("before", type=Path)
    comparing.add_argument("after", type=Path)
    args = parser.parse_args(argv)
    if args.action == "take":
        take(args.folder, args.only)
        return 0
    differences = compare_runs(args.before, args.after)
    runs = sum(1 for name, _ in RUNS if (args.before / name / "snapshot.json").exists())
    for line in differences:
        print(line)
    print(f"{runs} runs compared: {len(differences)} differences")
    return 1 if differences else 0


if __name__ == "__main__":
    sys.exit(main())
