"""March speed: careful per-step path, fast path on CasADi's virtual machine, fast path compiled,
and scipy's DOP853, measured side by side in one run (the machine is shared: compare ratios).

paper_pendulum (the paper's example, about 20150 steps to t = 10000) and fpu (omega = 50, six
degrees of freedom, 20000 steps) show how the cost grows with the dimension. Each timing is the
best of several repeats after one warm-up. "stepping" is the march's own solve time
(``timing["solve_s"]``); the recomputation of every equation on the returned grid
(``timing["verify_s"]``) and build/compile times are reported apart. DOP853 gets a hand-written
numpy right-hand side, as a user would write it.

    python scripts/benchmarks/bench_march.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import ctypes
import math
import resource
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from ddvp_nlp import Compilation, load_scene, march
from ddvp_nlp.io import machine


def best_of(repeats, run):
    run()  # warm-up
    times, result = [], None
    for _ in range(repeats):
        started = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - started)
    return min(times), result


def paper_pendulum_field(eps, omega):
    def f(t, y):
        return [y[1], -np.sin(y[0]) * (1 - eps * np.sin(omega * t))]
    return f


def fpu_field(omega):
    def f(t, y):
        q, p = y[:6], y[6:]
        x = np.concatenate([[0.0], q, [0.0]])
        force = np.zeros(8)
        stiff = omega**2 / 2 * (x[2:8:2] - x[1:7:2])  # springs (2i-1, 2i), i = 1..3
        force[2:8:2] -= stiff
        force[1:7:2] += stiff
        soft = 4 * (x[1:8:2] - x[0:8:2]) ** 3  # springs (2i, 2i+1), i = 0..3
        force[1:8:2] -= soft
        force[0:8:2] += soft
        return np.concatenate([p, force[1:7]])
    return f


FIELDS = {"paper_pendulum": lambda params: paper_pendulum_field(**params),
          "fpu": lambda params: fpu_field(**params)}


def vector_field_check(system, theta, config):
    """A state and its Hamiltonian vector field by CasADi, to check the hand-written one."""
    import casadi as ca
    z = ca.vertcat(system.q, system.p)
    field = ca.Function("f", [system.t, z, system.theta],
                        [ca.vertcat(ca.gradient(system.H, system.p),
                                    -ca.gradient(system.H, system.q))])
    state = np.concatenate([config.q0, config.p0]) + 0.1
    return state, np.asarray(field(config.t0 + 0.3, state, theta)).ravel()


def _largest_difference(a, b) -> float:
    """Largest difference of t, q, p between two marches of the same number of steps."""
    if a.steps != b.steps:
        return float("nan")
    return float(max(np.max(np.abs(a.t - b.t)), np.max(np.abs(a.q - b.q)),
                     np.max(np.abs(a.p - b.p))))


def bench(name, overrides, repeats):
    scene = load_scene(name)
    config = scene.resolve(overrides)
    system = scene.system
    theta = system.parameter_vector(config.params)
    rows = {}
    with tempfile.TemporaryDirectory() as cache:
        def run(**options):
            return march(system, config.q0, config.p0, (0.0, config.t_end), tau0=config.tau0,
                         params=config.params,
                         compilation=Compilation(cache_dir=cache, **options))

        first = run()  # builds and compiles into the empty cache: the build/compile figures
        build = {"build_s": first.timing["build_s"], "compile_s": first.timing["compile_s"]}
        for label, options in (("careful path", {"fast": False}),
                               ("fast path, virtual machine", {"compiler": None}),
                               ("fast path, compiled", {})):
            best = None
            for _ in range(1 + (repeats if options.get("fast", True) else max(1, repeats // 2))):
                solution = run(**options)  # the first is the warm-up
                if best is not None and solution.timing["solve_s"] < best.timing["solve_s"]:
                    best = solution
                best = best or solution
            rows[label] = (best.timing["solve_s"], best)
    careful = rows["careful path"][1]
    compiled = rows["fast path, compiled"][1]
    agreement = _largest_difference(compiled, careful)
    nudged = _largest_difference(
        march(
            system,
            config.q0 + 1e-15,
            config.p0,
            (0.0, config.t_end),
            tau0=config.tau0,
            params=config.params,
            compilation=Compilation(fast=False),
        ),
        careful,
    )

    f = FIELDS[name](config.params)
    check = np.asarray(vector_field_check(system, theta, config))
    assert np.allclose(f(config.t0 + 0.3, check[0]), check[1]), "hand-written field is wrong"
    y0 = np.concatenate([config.q0, config.p0])
    span = (config.t0, compiled.t[-1])
    reference = solve_ivp(f, span, y0, method="DOP853", rtol=1e-13, atol=1e-13,
                          dense_output=True)
    seconds, dop = best_of(max(1, repeats // 2), lambda: solve_ivp(
        f, span, y0, method="DOP853", rtol=1e-10, atol=1e-10))
    n = system.n
    H = system.energy(dop.y[:n].T, dop.y[n:].T, dop.t, theta)
    ref = reference.sol(dop.t)
    H_ref = system.energy(ref[:n].T, ref[n:].T, dop.t, theta)
    dop_energy = float(np.max(np.abs(H - H_ref)))
    dop_error = float(np.max(np.abs(dop.y - ref)))
    ours_ref = reference.sol(compiled.t)
    ours_error = float(max(np.max(np.abs(compiled.q - ours_ref[:n].T)),
                           np.max(np.abs(compiled.p - ours_ref[n:].T))))

    steps = compiled.steps
    params = ", ".join(f"{k}={v:g}" for k, v in config.params.items())
    print(f"\n## {name} ({params}; n = {n}; {steps} steps of vddvp to t = "
          f"{compiled.t[-1]:.6g})\n")
    print("| method | stepping s | us / step | ratio to compiled fast path |")
    print("|---|---|---|---|")
    fastest = rows["fast path, compiled"][0]
    for label, (sec, _) in rows.items():
        print(f"| {label} | {sec:.4f} | {sec / steps * 1e6:.2f} | {sec / fastest:.1f} |")
    print(f"| scipy DOP853, rtol = atol = 1e-10 ({dop.t.size - 1} steps) | {seconds:.4f} | "
          f"{seconds / (dop.t.size - 1) * 1e6:.2f} per DOP853 step | {seconds / fastest:.1f} |")
    print(f"\n- build {build['build_s']:.3f} s, of which C compile {build['compile_s']:.3f} s "
          f"(once per system, scheme and options; cached afterwards)")
    verify = compiled.timing["verify_s"]
    print(f"- recomputing every equation on the returned grid: {verify:.4f} s "
          f"({verify / steps * 1e6:.2f} us per node, "
          f"{'compiled' if compiled.stats['path'] == 'compiled' else 'virtual machine'})")
    print(f"- compiled fast path vs careful path: largest difference of t, q, p over {steps} "
          f"steps {agreement:.2e} (the careful path itself moves by {nudged:.2e} when q0 is "
          f"nudged by 1e-15: round-off grown over the run); speed-up "
          f"{rows['careful path'][0] / fastest:.1f}x")
    worst = np.max(np.abs(compiled.energy_residual))
    print(f"- vddvp largest energy residual per step {worst:.2e}; state error against DOP853 at "
          f"rtol 1e-13 {ours_error:.2e}")
    print(f"- DOP853 at 1e-10: energy error |H(z,t) - H(z_ref,t)| {dop_energy:.2e}, "
          f"state error {dop_error:.2e}")


C_SOURCE = Path(__file__).with_name("c_march.c")
C_KINDS = {"paper_pendulum": 0, "fpu": 1, "henon_heiles": 2}


# The flags the library compiles its chunks with (ddvp_nlp/solvers/compiler.py), so that the C
# march gets what the compiled chunk gets: no FMA contraction, sincos merged, sin and cos called
# without the PLT.
C_FLAGS = ("-O2", "-fPIC", "-shared", "-ffp-contract=off", "-fno-math-errno", "-fno-plt",
           "-fno-semantic-interposition")


def c_march_library(folder):
    """``c_march.c`` (beside this script) compiled with the library's own flags
    (``C_FLAGS``)."""
    library = Path(folder) / "c_march.so"
    subprocess.run(["gcc", *C_FLAGS, str(C_SOURCE), "-o", str(library), "-lm"], check=True)
    lib = ctypes.CDLL(str(library))
    pointer = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
    lib.c_march.argtypes = [ctypes.c_int, ctypes.c_int, pointer, pointer, ctypes.c_double,
                            ctypes.c_double, ctypes.c_double, ctypes.c_int, ctypes.c_double,
                            pointer, pointer, pointer]
    lib.c_march.restype = ctypes.c_int
    lib.c_march_fast.argtypes = [*lib.c_march.argtypes[:9], ctypes.c_int, pointer, pointer,
                                 pointer, ctypes.POINTER(ctypes.c_long)]
    lib.c_march_fast.restype = ctypes.c_int
    lib.c_march_checks.argtypes = [ctypes.c_int, ctypes.c_int, pointer, ctypes.c_int, pointer,
                                   pointer, *[pointer] * 6]
    lib.c_march_checks.restype = None
    lib.c_march_sphere.argtypes = [pointer, *[ctypes.c_double] * 3, ctypes.c_int,
                                   ctypes.c_double, ctypes.c_int, pointer, pointer, pointer,
                                   ctypes.POINTER(ctypes.c_long)]
    lib.c_march_sphere.restype = ctypes.c_int
    return lib


# c_march_fast's predictors (scripts/benchmarks/c_march.c)
C_PREDICTORS = {0: "RK4", 1: "Stormer-Verlet", 2: "extrapolation from three nodes"}


def cpu_seconds():
    """CPU seconds of this process and of its children that have ended (worker processes)."""
    own, ended = (resource.getrusage(who) for who in (resource.RUSAGE_SELF,
                                                      resource.RUSAGE_CHILDREN))
    return own.ru_utime + own.ru_stime + ended.ru_utime + ended.ru_stime


def timed(repeats, run, *, warm_up=True):
    """Best CPU (this process and its ended children) and best wall time of ``repeats`` runs
    after one warm-up, and the last result."""
    if warm_up:
        run()
    cpu, wall, result = [], [], None
    for _ in range(repeats):
        c0, w0 = cpu_seconds(), time.perf_counter()
        result = run()
        cpu.append(cpu_seconds() - c0)
        wall.append(time.perf_counter() - w0)
    return min(cpu), min(wall), result


def bench_against_c(name, overrides, repeats, folder):
    """march() (the whole call, with and without the accuracy check) against the C march."""
    scene = load_scene(name)
    config = scene.resolve(overrides)
    system = scene.system
    theta = np.zeros(4)
    values = system.parameter_vector(config.params)
    theta[:values.size] = values
    n = system.n
    lib = c_march_library(folder)
    capacity = 400_000
    t, z, H = np.empty(capacity + 1), np.empty((capacity + 1, 2 * n)), np.empty(capacity + 1)
    z0 = np.concatenate([config.q0, config.p0])

    def c_run():
        return lib.c_march(C_KINDS[name], n, theta, z0, config.t0, config.tau0, config.t_end,
                           capacity, 1e-10, t, z, H)

    def c_fast(predictor, iterations):
        return lambda: lib.c_march_fast(C_KINDS[name], n, theta, z0, config.t0, config.tau0,
                                        config.t_end, capacity, 1e-10, predictor, t, z, H,
                                        ctypes.byref(iterations))

    def run(**options):
        return march(system, config.q0, config.p0, (0.0, config.t_end), tau0=config.tau0,
                     params=config.params, compilation=Compilation(cache_dir=folder), **options)

    checks = [np.empty((capacity, 2 * n)), np.zeros(capacity), *(np.empty(capacity + 1)
                                                                   for _ in range(4))]

    def c_checked(predictor, iterations):
        """The fast C march, then the march()'s own extra work in C on its nodes."""
        march_fast = c_fast(predictor, iterations)

        def run():
            steps = march_fast()
            lib.c_march_checks(C_KINDS[name], n, theta, steps, t, z, *checks)
            return steps
        return run

    # one round: every C march and every march() once, interleaved, `repeats` rounds (best of
    # each): the machine's load hits every row alike
    c_rows = {"C march, first reference (scripts/benchmarks/c_march.c: c_march)": c_run}
    counts = {}
    for predictor, label in C_PREDICTORS.items():
        counts[predictor] = ctypes.c_long(0)
        c_rows[f"C march, fast (c_march_fast, {label} predictor)"] = c_fast(predictor,
                                                                           counts[predictor])
    for predictor, label in C_PREDICTORS.items():
        c_rows[f"C march, fast ({label}) + march()'s checks in C (c_march_checks)"] = \
            c_checked(predictor, ctypes.c_long(0))
    march_rows = {"march(), accuracy check on (default)": lambda: run(),
                  "march(), accuracy=None": lambda: run(accuracy=None)}
    found = {label: [math.inf, math.inf, None] for label in [*c_rows, *march_rows]}
    for run_all in (False, True):  # a warm-up round, then the measured ones
        for _ in range(repeats if run_all else 1):
            for label, call in [*c_rows.items(), *march_rows.items()]:
                # a C march takes ~10 ms: four calls per round for a steadier minimum
                for _ in range(4 if label in c_rows else 1):
                    cpu, wall, result = timed(1, call, warm_up=False)
                    if run_all:
                        best = found[label]
                        best[0], best[1], best[2] = min(best[0], cpu), min(best[1], wall), result
    iterations = {p: counts[p].value for p in C_PREDICTORS}
    c_steps = found[next(iter(c_rows))][2]
    fast_labels = [label for label in c_rows if "fast (c_march_fast" in label]
    checked_labels = [label for label in c_rows if "c_march_checks" in label]
    checked = min(checked_labels, key=lambda label: found[label][0])
    reference = min(fast_labels, key=lambda label: found[label][0])
    c_cpu, c_wall = found[reference][:2]
    rows = [(label, cpu, wall, result if label in c_rows else result.steps)
            for label, (cpu, wall, result) in found.items()]
    solution = found["march(), accuracy=None"][2]
    rows.insert(1, rows.pop(rows.index(next(r for r in rows if r[0] == reference))))
    steps = solution.steps
    same = c_steps == steps
    difference = float(np.max(np.abs(t[:c_steps + 1] - solution.t))) if same else float("nan")
    print(f"\n## {name} against the C march (n = {n}, {steps} steps, whole call)\n")
    print("| method | CPU s | wall s | CPU us / step | CPU ratio to fast C "
          "| wall ratio to fast C |")
    print("|---|---|---|---|---|---|")
    for label, cpu, wall, count in rows:
        mark = " **(reference)**" if label == reference else ""
        print(f"| {label}{mark} | {cpu:.4f} | {wall:.4f} | {cpu / count * 1e6:.3f} | "
              f"{cpu / c_cpu:.2f} | {wall / c_wall:.2f} |")
    print(f"\n- C marches: {c_steps} steps; largest |t_C - t_march| over the nodes (last C "
          f"march run) {difference:.2e}")
    like = found["march(), accuracy check on (default)"][0] / found[checked][0]
    print(f"- like for like: march() (accuracy check on) against the fastest C march that also "
          f"does march()'s checks (the recheck of every residual, the accuracy check's RK4 "
          f"estimates and propagated global error, w at every node; {checked}): CPU ratio "
          f"{like:.2f}")
    per_step = ", ".join(f"{C_PREDICTORS[p]} {iterations[p] / c_steps:.2f}"
                         for p in C_PREDICTORS)
    print(f"- c_march_fast's Newton iterations per step by predictor: {per_step}")
    off = found["march(), accuracy=None"]
    rk4 = found[f"C march, fast (c_march_fast, {C_PREDICTORS[0]} predictor)"]
    print(f"- issue 49's target, march() with the check off <= 1.3x the C march: CPU "
          f"{off[0] / c_cpu:.2f}x the fastest C march (wall {off[1] / c_wall:.2f}x), "
          f"{off[0] / rk4[0]:.2f}x the C march from the library's own predictor, RK4 "
          f"(wall {off[1] / rk4[1]:.2f}x)")

def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--c-only", action="store_true",
                        help="only the comparison with the C march")
    args = parser.parse_args()
    print(f"machine: {machine()}")
    with tempfile.TemporaryDirectory() as folder:
        bench_against_c("paper_pendulum", {}, args.repeats, folder)
        bench_against_c("fpu", {"t_end": 200.0, "tau0": 0.01}, args.repeats, folder)
    if args.c_only:
        print(f"\nmachine: {machine()}")
        return
    bench("paper_pendulum", {}, args.repeats)
    bench("fpu", {"t_end": 200.0, "tau0": 0.01}, args.repeats)
    print(f"\nmachine: {machine()}")


if __name__ == "__main__":
    main()
