"""docs/chaos/README.md: the chaos maps of ``ddvp chaos`` against the exact flow, and the
validation of the indicators (issue 41).

    python scripts/pages/chaos_page.py [--work DIR]
        [--stage maps|exact|cost|validate|second|page|all]

Stages keep their results in the work folder (default /tmp/chaos-page) and are skipped when
their file is there, so the page can be redrawn without running anything again:

- ``maps``: ``ddvp chaos henon_heiles --energy 0.125 --grid 'q2=-0.45:0.7:100,p2=-0.52:0.52:100'
  --t-end 500 --workers 2`` (10 000 cells, the indicators also at t = 250);
- ``exact``: the same cells' indicators on the exact flow (``exact_indicators``, rtol 1e-12),
  two processes;
- ``cost``: every 200th cell marched by ``march`` (compiled, no accuracy check) and by
  ``chaos_indicators``, one after the other in this process: CPU and wall per cell;
- ``validate``: regular tori to t = 1e4, spectra (level map and exact) to t = 1e4, convergence
  of <Y> and ln|w| in tau0 with fitted orders;
- ``second``: Henon-Heiles at E = 1/10 on a 40 x 40 grid of other bounds, run as three shards
  (docs/chaos/chaos_array.sbatch run here as array tasks 1-3) and merged, against the exact
  flow;
- ``page``: the figures and README.md.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ddvp_nlp import load_scene, march
from ddvp_nlp.solvers import chaos_indicators, lyapunov_spectrum

# internals, named explicitly: the indicators' exact-flow reference (not workbench names)
from ddvp_nlp.solvers.chaos.exact_indicators import exact_indicators, exact_spectrum

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs" / "chaos"
E_MAP = 0.125
GRID = "q2=-0.45:0.7:100,p2=-0.52:0.52:100"
T_MAP = 500.0
THRESHOLD = 2.5  # <Y> above: chaotic (tori tend to 2, chaotic orbits grow like lambda t / 2)


def ddvp(*words) -> tuple[float, float, str]:
    """Run ``ddvp`` in a child process: (wall s, CPU s of it and its workers, stdout)."""
    before = os.times()
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "ddvp_nlp.cli", *words], capture_output=True,
                          text=True)
    wall = time.perf_counter() - started
    after = os.times()
    cpu = (after.children_user - before.children_user) + \
        (after.children_system - before.children_system)
    if done.returncode not in (0, 1):
        raise SystemExit(f"ddvp {' '.join(words)} ended {done.returncode}: {done.stderr}")
    return wall, cpu, done.stdout


def stage_maps(work: Path) -> None:
    out = work / "hh-map"
    if (out / "chaos.npz").exists():
        return
    load = os.getloadavg()
    wall, cpu, text = ddvp("chaos", "henon_heiles", "--energy", str(E_MAP), "--grid", GRID,
                           "--t-end", str(T_MAP), "--out", str(out), "--workers", "2",
                           "--no-progress")
    (work / "hh-map.json").write_text(json.dumps(
        {"wall_s": wall, "cpu_s": cpu, "stdout": text, "load_before": load,
         "load_after": os.getloadavg()}, indent=1))


def _exact_cells(args):
    z, t_end, energy = args
    system = load_scene("henon_heiles").system
    rows = []
    for start in z:
        r = exact_indicators(system, start[:2], start[2:], t_end, snapshots=(t_end / 2,))
        rows.append((r.megno, r.lyapunov, r.snapshots["megno"][0], r.seconds))
    return rows


def exact_map(chaos_npz: Path, target: Path) -> None:
    """The exact flow's indicators of every runnable cell of a map, two processes."""
    if target.exists():
        return
    data = np.load(chaos_npz)
    z = np.hstack([data["q0"], data["p0"]])
    cells = np.flatnonzero(data["status"] != "not_run")
    exact_indicators(load_scene("henon_heiles").system, z[cells[0], :2], z[cells[0], 2:], 1.0)
    blocks = [(z[cells[s:s + 50]], float(data["t_end"]), float(data["energy"]))
              for s in range(0, cells.size, 50)]
    started, load = time.perf_counter(), os.getloadavg()
    with multiprocessing.get_context("fork").Pool(2) as pool:
        rows = [row for block in pool.map(_exact_cells, blocks) for row in block]
    values = np.full((z.shape[0], 4), np.nan)
    values[cells] = rows
    np.savez(target, megno=values[:, 0], lyapunov=values[:, 1], megno_half=values[:, 2],
             cpu_s=values[:, 3], wall_s=time.perf_counter() - started, load=load)


def stage_cost(work: Path) -> None:
    target = work / "cost.json"
    if target.exists():
        return
    data = np.load(work / "hh-map" / "chaos.npz")
    system = load_scene("henon_heiles").system
    z = np.hstack([data["q0"], data["p0"]])
    cells = np.flatnonzero(data["status"] == "success")[::200]
    march(system, z[cells[0], :2], z[cells[0], 2:], (0, 1), tau0=0.02, accuracy=None)
    chaos_indicators(system, z[cells[0], :2], z[cells[0], 2:], (0, 1), tau0=0.02)
    rows, load = [], os.getloadavg()
    for c in cells:
        q, p = z[c, :2], z[c, 2:]
        t0, w0 = time.process_time(), time.perf_counter()
        solution = march(system, q, p, (0, T_MAP), tau0=0.02, accuracy=None)
        t1, w1 = time.process_time(), time.perf_counter()
        r = chaos_indicators(system, q, p, (0, T_MAP), tau0=0.02, snapshots=(T_MAP / 2,))
        t2, w2 = time.process_time(), time.perf_counter()
        rows.append({"cell": int(c), "steps": int(solution.steps), "chaos_steps": r.steps,
                     "march_cpu": t1 - t0, "chaos_cpu": t2 - t1, "march_wall": w1 - w0,
                     "chaos_wall": w2 - w1})
    target.write_text(json.dumps({"rows": rows, "load_before": load,
                                  "load_after": os.getloadavg()}, indent=1))


def stage_validate(work: Path) -> None:
    target = work / "validate.json"
    if target.exists():
        return
    system = load_scene("henon_heiles").system
    result = {"tori": [], "spectra": [], "convergence": {}}
    for q2, p2 in [(0.0, 0.27), (0.1, 0.1), (0.3, 0.0), (-0.2, 0.1), (0.0, -0.3), (0.2, -0.2),
                   (0.45, 0.1), (-0.3, -0.1)]:
        q, p = start(q2, p2, E_MAP)
        d = chaos_indicators(system, q, p, (0, 1e4), tau0=0.02, snapshots=(2000,))
        x = exact_indicators(system, q, p, 1e4, snapshots=(2000,))
        result["tori"].append({"q2": q2, "p2": p2, "discrete": d.megno, "exact": x.megno,
                               "discrete_2000": d.snapshots["megno"][0],
                               "exact_2000": x.snapshots["megno"][0]})
    for name, (q2, p2) in {"regular": (0.0, 0.27), "chaotic": (-0.1, 0.0)}.items():
        q, p = start(q2, p2, E_MAP)
        for tau0 in (0.02, 0.005):
            s = lyapunov_spectrum(system, q, p, (0, 1e4), tau0=tau0)
            result["spectra"].append({"orbit": name, "tau0": tau0, "kind": "level map",
                                      "exponents": s.exponents.tolist(),
                                      "pair_sums": s.pair_sums.tolist(), "cpu_s": s.seconds})
        x = exact_spectrum(system, q, p, 1e4)
        result["spectra"].append({"orbit": name, "kind": "exact", "exponents":
                                  x.exponents.tolist(), "pair_sums": x.pair_sums.tolist(),
                                  "cpu_s": x.seconds})
    for name, (q2, p2), t in (("regular", (0.0, 0.27), 100.0), ("chaotic", (-0.1, 0.0), 50.0)):
        q, p = start(q2, p2, E_MAP)
        x = exact_indicators(system, q, p, t)
        rows = []
        for tau0 in (0.08, 0.04, 0.02, 0.01, 0.005):
            d = chaos_indicators(system, q, p, (0, t), tau0=tau0, snapshots=(t,))
            # at t exactly: the snapshot's node is the first at or past t; compare at its time
            xs = exact_indicators(system, q, p, float(d.snapshots["t"][0]))
            rows.append({"tau0": tau0, "megno_error": d.snapshots["megno"][0] - xs.megno,
                         "log_norm_error": (d.snapshots["lyapunov"][0] - xs.lyapunov)
                         * d.snapshots["t"][0]})
        result["convergence"][name] = {"t": t, "exact_megno": x.megno, "rows": rows}
    target.write_text(json.dumps(result, indent=1))


def start(q2: float, p2: float, energy: float):
    r = 2 * energy - p2 ** 2 - (q2 ** 2 - 2 * q2 ** 3 / 3)
    return np.array([0.0, q2]), np.array([math.sqrt(r), p2])


def stage_second(work: Path) -> None:
    """docs/chaos/chaos_array.sbatch run here as its array tasks 1-3 would run on a cluster
    (one after the other, SLURM_ARRAY_TASK_ID set by hand), then the merge."""
    out = work / "maps" / "hh-E0.1"
    if (out / "chaos.npz").exists():
        return
    log = []
    for k in (1, 2, 3):
        started, before = time.perf_counter(), os.times()
        done = subprocess.run(["bash", str(DOCS / "chaos_array.sbatch")], cwd=work,
                              env={**os.environ, "SLURM_ARRAY_TASK_ID": str(k)},
                              capture_output=True, text=True)
        after = os.times()
        if done.returncode not in (0, 1):
            raise SystemExit(f"shard {k} ended {done.returncode}: {done.stderr}")
        log.append({"shard": k, "wall_s": time.perf_counter() - started,
                    "cpu_s": after.children_user - before.children_user,
                    "stdout": done.stdout})
    wall, cpu, text = ddvp("chaos", "--merge", str(out))
    log.append({"merge": True, "wall_s": wall, "stdout": text})
    (work / "second.json").write_text(json.dumps(log, indent=1))


def agreement(chaos: dict, exact: dict) -> dict:
    """Classes at T/2 and T in both maps; the share alike among the cells whose class is the
    same at T/2 and T in both (stable in time), and among all."""
    run = chaos["status"] == "success"
    cd, cd2 = chaos["megno"] > THRESHOLD, chaos["megno_half"] > THRESHOLD
    ce, ce2 = exact["megno"] > THRESHOLD, exact["megno_half"] > THRESHOLD
    stable = run & (cd == cd2) & (ce == ce2)
    alike = cd == ce
    return {"run": int(run.sum()), "stable": int(stable.sum()),
            "alike_stable": int((alike & stable).sum()),
            "share_stable": float((alike & stable).sum() / max(stable.sum(), 1)),
            "alike_all": int((alike & run).sum()),
            "share_all": float((alike & run).sum() / max(run.sum(), 1)),
            "chaotic_discrete": int((cd & run).sum()), "chaotic_exact": int((ce & run).sum()),
            "thresholds": {str(t): float(((chaos["megno"] > t) == (exact["megno"] > t))[run]
                                         .mean()) for t in (2.1, 2.5, 3.0, 4.0)}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", default="/tmp/chaos-page")
    parser.add_argument("--stage", default="all")
    args = parser.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    stages = {"maps": lambda: stage_maps(work),
              "exact": lambda: exact_map(work / "hh-map" / "chaos.npz", work / "hh-exact.npz"),
              "cost": lambda: stage_cost(work), "validate": lambda: stage_validate(work),
              "second": lambda: (stage_second(work),
                                 exact_map(work / "maps" / "hh-E0.1" / "chaos.npz",
                                           work / "second-exact.npz")),
              "page": lambda: write_page(work)}
    for name, run in stages.items():
        if args.stage in (name, "all"):
            started = time.perf_counter()
            run()
            print(f"{name}: {time.perf_counter() - started:.1f} s", flush=True)


def write_page(work: Path) -> None:
    from chaos_page_text import write  # the page's figures and text, beside this script

    write(work, DOCS, agreement)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    main()
