"""Fixed-endpoint solver at growing N: build and solve time (wall and CPU), iterations, residuals,
peak memory, for each solver path, measured side by side in one run.

Cases (issue 16's targets):

- ``pendulum``: the autonomous pendulum over about 2.7 periods (t in [0, 18], q(0) = 0.5,
  q(18) from a fixed-step march with p(0) = 0.5), vddvp, default start;
- ``kepler``: e = 0.5 over 3 periods from the pericentre, q(6 pi) from a fixed-step march
  (20000 steps), vddvp, default start (the straight line: it leads to the radial branch, on which
  the energy rule has no solution; the row shows how fast that is reported);
- ``kepler-shoot``: the same problem, ``guess=Shooting(p_start)`` with the orbit's momentum
  (0, sqrt 3): shooting picks the three revolutions;
- ``kepler-nodes``: the same problem, the march that made the endpoints as the guess (resampled
  onto N nodes).

Over whole periods this problem is degenerate: every direction of p_0 with |p_0| = sqrt 3 comes
back to the start, so only the discretisation singles out a solution (the exact flow's shooting
Jacobian has singular values 170 and 7e-9 at 3 periods, 77 and 1.0 at 2.75; measured).

Each run is its own process (so that its peak memory, ``ru_maxrss``, is its own) with a time
limit. Every (case, solver, N) runs ``--repeat`` times (default 3) to show that the iteration
counts repeat; the table gives the best wall time.

    python scripts/benchmarks/bench_bvp.py                  (the full table: about 10 minutes)
    python scripts/benchmarks/bench_bvp.py --quick          (N = 1e3, 1e4 only)
    python scripts/benchmarks/bench_bvp.py --only pendulum:ipopt,pendulum:newton
    python scripts/benchmarks/bench_bvp.py \
        --only pendulum:newton,pendulum:newton-vm,pendulum:newton-lapack

Solver ``newton-vm`` is Newton with nothing compiled: the assembly's blocks on CasADi's virtual
machine and the band LU by LAPACK through scipy (``Compilation(compiler=None,
band_lu="lapack")``), the path of a machine without a C compiler; ``newton-lapack`` compiles
the blocks but factorises with LAPACK (``Compilation(band_lu="lapack")``). Both run in the same
way for the ratio to ``newton`` (everything compiled by ``compiler.py``, cached in
``$DDVP_NLP_CACHE`` or ``~/.cache/ddvp_nlp``, so only the first run ever compiles).

Solver ``ipopt`` is IPOPT on the banded assembly's callbacks (``solvers/bvp/ends_nlp.py`` through
the grid's one IPOPT build).
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import time

import numpy as np

PLAN = {  # (case, solver): sizes
    ("pendulum", "newton"): [1_000, 10_000, 100_000, 1_000_000],
    ("pendulum", "newton-vm"): [1_000, 10_000, 100_000, 1_000_000],
    ("pendulum", "newton-lapack"): [1_000, 10_000, 100_000, 1_000_000],
    ("pendulum", "ipopt"): [1_000, 10_000, 100_000],
    ("kepler", "auto"): [1_000, 10_000],
    ("kepler-shoot", "auto"): [1_000, 10_000, 100_000],
    ("kepler-nodes", "auto"): [1_000, 10_000, 100_000],
}
TARGETS = {("pendulum", "newton"): {10_000: 0.2, 100_000: 1.5, 1_000_000: 20.0},
           ("pendulum", "ipopt"): {10_000: 2.0, 100_000: 20.0},
           ("kepler", "auto"): {10_000: 0.5, 100_000: 5.0},
           ("kepler-shoot", "auto"): {10_000: 0.5, 100_000: 5.0},
           ("kepler-nodes", "auto"): {10_000: 0.5, 100_000: 5.0}}
TIME_LIMIT = 150.0
# Runs per (case, solver, N): 3 where a run takes seconds, to show the iteration counts repeat.
REPEATS = {("pendulum", "newton"): 3, ("pendulum", "newton-vm"): 3,
           ("pendulum", "newton-lapack"): 3, ("pendulum", "ipopt"): 3,
           ("kepler", "auto"): 1, ("kepler-shoot", "auto"): 3, ("kepler-nodes", "auto"): 3}


def endpoints(case: str):
    from ddvp_nlp import Shooting, load_scene, march

    system = load_scene(case.split("-")[0]).system
    if case == "pendulum":
        reference = march(system, [0.5], [0.5], (0.0, 18.0), tau0=0.01, scheme="fixed")
        return system, [0.5], reference.q[-1], (0.0, 18.0), {}, {}
    e, T = 0.5, 6 * np.pi
    q0, p0 = [1 - e, 0.0], [0.0, np.sqrt((1 + e) / (1 - e))]
    reference = march(system, q0, p0, (0.0, T), tau0=T / 20000, scheme="fixed", params={"e": e})
    start = {"kepler": {}, "kepler-shoot": {"guess": Shooting(p0)},
             "kepler-nodes": {"guess": reference}}[case]
    return system, q0, reference.q[-1], (0.0, T), {"e": e}, start


def one(case: str, nodes: int, solver: str) -> dict:
    from ddvp_nlp import Compilation, GridOptions, solve_bvp

    label = solver
    compilation = Compilation(compiler=None if solver == "newton-vm" else "auto",
                              band_lu="lapack" if solver in ("newton-vm", "newton-lapack")
                              else "compiled")
    solver = solver.split("-")[0]

    system, q_start, q_end, span, params, start = endpoints(case)
    cpu = time.process_time()
    solution = solve_bvp(
        system,
        q_start,
        q_end,
        (span[0], span[1]),
        nodes=nodes,
        params=params,
        options=GridOptions(solver=solver, time_limit=TIME_LIMIT),
        compilation=compilation,
        **start,
    )
    phases, ends = solution.ends.stages, solution.ends
    return {"case": case, "N": nodes, "solver": label, "status": solution.status.code,
            "path": _path(system, solution.stats["solver"], compilation),
            "build_s": solution.timing["build_s"], "solve_s": solution.timing["solve_s"],
            "cpu_s": time.process_time() - cpu,
            "iterations": [ph.iterations for ph in phases],
            "canonical": ends.canonical_residual_max if ends.tau_min is not None else np.nan,
            "energy": ends.energy_residual_max if ends.tau_min is not None else np.nan,
            "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def _path(system, solver: str, compilation) -> str:
    """The solver that returned the point; for Newton, how its blocks were evaluated (compiled
    or on CasADi's virtual machine, read from the built assembly)."""
    from ddvp_nlp.cache import PROBLEMS

    if solver != "newton":
        return solver
    # an internal, named explicitly: which LU the grid Newton uses (not a workbench name)
    from ddvp_nlp.solvers.grid.linear import band_kernel

    paths = {PROBLEMS.get(system, key, lambda: None).path for key in PROBLEMS.keys(system)
             if key[0] == "bvp_assembly"}
    lu = "C LU" if band_kernel(compilation) is not None else "LAPACK"
    return f"newton, {'/'.join(sorted(paths))}, {lu}"


def run(case, nodes, solver, repeat) -> dict:
    runs = []
    for _ in range(repeat):
        try:
            out = subprocess.run([sys.executable, __file__, "--one", case, str(nodes), solver],
                                 check=True, capture_output=True, text=True,
                                 timeout=TIME_LIMIT + 120).stdout
            runs.append(json.loads(out.strip().splitlines()[-1]))
        except subprocess.TimeoutExpired:
            runs.append({"case": case, "N": nodes, "solver": solver, "status": "timeout",
                         "path": solver, "build_s": np.nan, "solve_s": np.nan, "cpu_s": np.nan,
                         "iterations": [], "canonical": np.nan, "energy": np.nan,
                         "peak_mb": np.nan})
        print(f"{case} {solver} N={nodes}: {runs[-1]['status']} "
              f"{runs[-1]['build_s'] + runs[-1]['solve_s']:.2f} s", file=sys.stderr, flush=True)
    best = min(runs, key=lambda r: r["build_s"] + r["solve_s"]
               if np.isfinite(r["build_s"]) else np.inf)
    best["repeat_iterations"] = [r["iterations"] for r in runs]
    return best


def table(rows) -> None:
    print("| case | solver (path) | N | status | build s | solve s | total s | CPU s | "
          "iterations per phase | same in every run | s / iteration | canonical | energy | "
          "peak MB | target |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        total = r["build_s"] + r["solve_s"]
        r["per_iteration"] = r["solve_s"] / max(1, sum(r["iterations"]))
        target = TARGETS.get((r["case"], r["solver"]), {}).get(r["N"])
        met = r["status"] == "success" and total <= (target or 0)
        verdict = "" if target is None else f"<= {target:g} s: {'met' if met else 'MISSED'}"
        same = len({tuple(i) for i in r["repeat_iterations"]}) == 1
        print(f"| {r['case']} | {r['solver']} ({r['path']}) | {r['N']:.0e} | {r['status']} | "
              f"{r['build_s']:.3f} | {r['solve_s']:.3f} | {total:.3f} | {r['cpu_s']:.3f} | "
              f"{' + '.join(map(str, r['iterations']))} | {'yes' if same else 'NO'} | "
              f"{r['per_iteration']:.2e} | {r['canonical']:.1e} | {r['energy']:.1e} | "
              f"{r['peak_mb']:.0f} | {verdict} |")


def summary(rows) -> None:
    print()
    for (case, solver) in PLAN:
        mine = [r for r in rows if r["case"] == case and r["solver"] == solver
                and r["status"] == "success" and r["N"] >= 10_000]
        if len(mine) >= 2:
            slope = np.polyfit(np.log([r["N"] for r in mine]),
                               np.log([r["per_iteration"] for r in mine]), 1)[0]
            # the same fit on CPU time (build + solve per iteration): wall time on a shared
            # machine measures the other processes too
            cpu = np.polyfit(np.log([r["N"] for r in mine]),
                             np.log([r["cpu_s"] / max(1, sum(r["iterations"])) for r in mine]),
                             1)[0]
            print(f"{case} {solver}: time per iteration grows like N^{slope:.2f} "
                  f"(N = {mine[0]['N']:.0e} .. {mine[-1]['N']:.0e}; target: at most N^1.1); "
                  f"CPU time per iteration like N^{cpu:.2f}")
    for nodes in sorted({r["N"] for r in rows}):
        pair = {r["solver"]: r for r in rows if r["N"] == nodes and r["case"] == "pendulum"}
        for a, b in (("ipopt", "newton"), ("ipopt-mx", "ipopt"), ("newton-vm", "newton"),
                     ("newton-lapack", "newton")):
            if {a, b} <= set(pair):
                wall = ((pair[a]["build_s"] + pair[a]["solve_s"])
                        / (pair[b]["build_s"] + pair[b]["solve_s"]))
                cpu = pair[a]["cpu_s"] / pair[b]["cpu_s"]
                print(f"pendulum N = {nodes:.0e}: build + solve, {a} / {b} = {wall:.1f} wall, "
                      f"{cpu:.1f} CPU")
    from ddvp_nlp.io import machine

    print(f"\nmachine: {machine()}")


def main(argv: list[str]) -> None:
    if argv and argv[0] == "--one":
        print(json.dumps(one(argv[1], int(argv[2]), argv[3])))
        return
    quick = "--quick" in argv
    repeat = 1 if quick else 3
    only = None
    if "--only" in argv:
        only = {tuple(pair.split(":")) for pair in argv[argv.index("--only") + 1].split(",")}
    rows = []
    for (case, solver), sizes in PLAN.items():
        if only is not None and (case, solver) not in only:
            continue
        for nodes in sizes:
            if quick and nodes > 10_000:
                continue
            count = min(repeat, REPEATS[case, solver]) \
                if nodes <= 10_000 or solver.startswith("newton") \
                else 1
            rows.append(run(case, nodes, solver, count if nodes < 1_000_000 else 1))
    table(rows)
    summary(rows)


if __name__ == "__main__":
    main(sys.argv[1:])
