"""Constrained marches (issue 48): the Cartesian pendulum and the spherical pendulum over many
steps (constraint, hidden constraint, energy row, angular momentum), and chains of N rigid
links (Newton updates per step, CPU per step at N = 128 against N = 10).

    python scripts/benchmarks/bench_constraints.py               # 1e6 steps, N = 10, 50, 128
    python scripts/benchmarks/bench_constraints.py --steps 20000 --links 10,50   # quick
    python scripts/benchmarks/bench_constraints.py --only chains --gravity 0     # free space
    python scripts/benchmarks/bench_constraints.py --only methods --methods multipliers,null_space
    python scripts/benchmarks/bench_constraints.py --only chains --chain-schemes vddvp \
        --methods multipliers,null_space --links 10,50                      # side by side

Each march's CPU and wall time are printed side by side, warm (the compiled chunk is built
first by a short march of the same system, and its build time is printed apart).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
import warnings
from functools import partial

import casadi as ca
import numpy as np

from ddvp_nlp import Compilation, HamiltonianSystem, StepControl, march


def timed(function):
    cpu, wall = time.process_time(), time.perf_counter()
    result = function()
    return result, time.process_time() - cpu, time.perf_counter() - wall


def pendulum_system():
    return HamiltonianSystem(lambda q, p, t: (p[0] ** 2 + p[1] ** 2) / 2 + q[1], 2,
                             name="cartesian_pendulum",
                             constraints=lambda q, t: q[0] ** 2 + q[1] ** 2 - 1)


def trend(values) -> str:
    """The largest value of each tenth of the run: a drift shows as a growing row."""
    parts = np.array_split(np.asarray(values), 10)
    return " ".join(f"{part.max():.1e}" for part in parts)


def pendulum(steps: int):
    system = pendulum_system()
    print(f"## Cartesian pendulum, {steps} steps (g = x^2 + y^2 - 1, H = |p|^2/2 + y)")
    print("| scheme | start | steps | max abs g | max hidden | max energy row | updates "
          "max/mean | CPU s | wall s | us per step (CPU) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    cases = [("fixed", "libration th0 = 1", [np.sin(1.0), -np.cos(1.0)], [0.0, 0.0], 0.01),
             ("vddvp", "rotation E = 3.5", [0.0, -1.0], [3.0, 0.0], 0.01)]
    records = {}
    for scheme, label, q0, p0, tau0 in cases:
        march(system, q0, p0, (0, 1), tau0=tau0, scheme=scheme, accuracy=None)  # warm
        span = steps * tau0 * (1.0 if scheme == "fixed" else 1.317)  # mean step 0.01317
        solution, cpu, wall = timed(lambda q0=q0, p0=p0, span=span, tau0=tau0, scheme=scheme:
                                    march(system, q0, p0, (0, span), tau0=tau0, scheme=scheme,
                                          accuracy=None))
        record = solution.constraints
        marched = solution.t.size - 1
        print(f"| {scheme} | {label} | {marched} | {record.constraint_residual.max():.2e} | "
              f"{record.hidden_residual.max():.2e} | "
              f"{np.abs(solution.energy_residual).max():.2e} | "
              f"{record.newton_updates.max()}/{record.newton_updates.mean():.2f} | "
              f"{cpu:.2f} | {wall:.2f} | {1e6 * cpu / max(marched, 1):.2f} |")
        records[scheme] = record
    for scheme, record in records.items():
        print(f"\n{scheme}: max |g| per tenth of the run: {trend(record.constraint_residual)}")
        print(f"{scheme}: max hidden per tenth: {trend(record.hidden_residual)}")


def order():
    """The error against the exact pendulum (the angle by DOP853 at rtol = atol = 1e-13,
    put on the circle) at every node up to t = 6 (fixed) or 3 (vddvp), and the order
    fitted to it."""
    from scipy.integrate import solve_ivp

    system = pendulum_system()
    print("\n## Convergence to the exact pendulum (largest |q - q_exact| over the nodes)")
    print("| scheme | start | mean step | error | fitted order |")
    print("|---|---|---|---|---|")
    cases = [("fixed", "libration th0 = 1", [np.sin(1.0), -np.cos(1.0)], [0.0, 0.0], 1.0, 0.0,
              6.0), ("vddvp", "rotation E = 3.5", [0.0, -1.0], [3.0, 0.0], 0.0, 3.0, 3.0)]
    for scheme, label, q0, p0, angle0, omega0, span in cases:
        exact = solve_ivp(lambda t, y: [y[1], -np.sin(y[0])], (0, span + 0.1),
                          [angle0, omega0], method="DOP853", rtol=1e-13, atol=1e-13,
                          dense_output=True)
        steps, errors = [], []
        for tau0 in (0.02, 0.01, 0.005, 0.0025):
            solution = march(system, q0, p0, (0, span), tau0=tau0, scheme=scheme,
                             accuracy=None)
            angle = exact.sol(solution.t)[0]
            errors.append(np.abs(solution.q - np.column_stack([np.sin(angle),
                                                               -np.cos(angle)])).max())
            steps.append(np.diff(solution.t).mean())
        fitted = np.polyfit(np.log(steps), np.log(errors), 1)[0]
        for step, error in zip(steps, errors, strict=True):
            print(f"| {scheme} | {label} | {step:.5f} | {error:.3e} | {fitted:.3f} |")


def spherical(steps: int):
    system = HamiltonianSystem(lambda q, p, t: ca.dot(p, p) / 2 + q[2], 3, name="spherical",
                               constraints=lambda q, t: ca.dot(q, q) - 1)
    q0, p0 = [0.0, np.sin(0.1), -np.cos(0.1)], [0.06, 0.0, 0.0]
    print(f"\n## Spherical pendulum, {steps} steps, q0 = (0, sin 0.1, -cos 0.1), "
          "p0 = (0.06, 0, 0), fixed steps 0.05")
    march(system, q0, p0, (0, 1), tau0=0.05, scheme="fixed", accuracy=None)
    solution, cpu, wall = timed(lambda: march(system, q0, p0, (0, steps * 0.05), tau0=0.05,
                                              scheme="fixed", accuracy=None))
    L = solution.q[:, 0] * solution.p[:, 1] - solution.q[:, 1] * solution.p[:, 0]
    relative = np.abs(L - L[0]) / abs(L[0])
    print(f"steps {solution.t.size - 1}: max |L_z - L_z(0)| / |L_z(0)| = {relative.max():.2e} "
          f"(per tenth: {trend(relative)}); max |g| "
          f"{solution.constraints.constraint_residual.max():.2e}, max hidden "
          f"{solution.constraints.hidden_residual.max():.2e}; CPU {cpu:.2f} s, wall "
          f"{wall:.2f} s")


def double_pendulum_system():
    """Two unit masses on unit rods from a pivot, coordinates ``(x1, y1, x2, y2)``."""
    return HamiltonianSystem(
        lambda q, p, t: ca.dot(p, p) / 2 + q[1] + q[3], 4, name="double_pendulum",
        constraints=lambda q, t: ca.vertcat(q[0] ** 2 + q[1] ** 2 - 1,
                                            (q[2] - q[0]) ** 2 + (q[3] - q[1]) ** 2 - 1))


def methods_table(methods, steps: int, repeats: int):
    """The constraint methods side by side on the small systems: CPU per step
    (`per_step_cpu`), Newton updates, and how far apart their nodes are."""
    print(f"\n## Constraint methods side by side, {steps} steps (stepping and after-check), "
          f"median of {repeats}")
    print("| system | scheme | method | unknowns per step | updates max/mean | us per step "
          "(CPU) | us per step (wall) | max abs g | max energy row | max node difference "
          "from the first method (first 500 steps / all) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    cases = [("pendulum", pendulum_system(), "fixed", [np.sin(1.0), -np.cos(1.0)], [0.0, 0.0]),
             ("pendulum", pendulum_system(), "vddvp", [0.0, -1.0], [3.0, 0.0]),
             ("double pendulum E = 10", double_pendulum_system(), "fixed",
              [0.0, -1.0, 0.0, -2.0], [5.0, 0.0, 1.0, 0.0]),
             ("double pendulum E = 10", double_pendulum_system(), "vddvp",
              [0.0, -1.0, 0.0, -2.0], [5.0, 0.0, 1.0, 0.0])]
    for label, system, scheme, q0, p0 in cases:
        first, ratios = None, []
        for method in methods:
            def run(count, method=method, system=system, scheme=scheme, q0=q0, p0=p0):
                return march(system, q0, p0, (0, 1e6), tau0=0.005, scheme=scheme,
                             accuracy=None, steps=StepControl(max_steps=count,
                                                              constraint_method=method))
            run(2)  # build and compile
            cpu, wall, solution = per_step_cpu(run, steps, repeats)
            first = first or (solution, cpu)
            ratios.append(cpu / first[1])
            k = min(first[0].t.size, solution.t.size)
            gaps = np.abs(np.hstack([first[0].q[:k], first[0].p[:k]])
                          - np.hstack([solution.q[:k], solution.p[:k]])).max(axis=1)
            m = system.n_constraints
            record = solution.constraints
            print(f"| {label} | {scheme} | {method} | "
                  f"{2 * system.n + (0 if method == 'null_space' else 2 * m) + (scheme != 'fixed')}"
                  f" | {record.newton_updates.max()}/{record.newton_updates.mean():.2f} | "
                  f"{1e6 * cpu:.2f} | {1e6 * wall:.2f} | {record.constraint_residual.max():.1e} | "
                  f"{np.abs(solution.energy_residual).max(initial=0.0):.1e} | "
                  f"{gaps[:501].max():.1e} / {gaps.max():.1e} |")
        print(f"<!-- {label} {scheme}: CPU per step over {methods[0]}: "
              f"{' '.join(f'{r:.2f}' for r in ratios)} -->")


def chain_system(links: int):
    """N unit masses on unit rods from a pivot at the origin, in the vertical plane, under
    gravity ``grav`` (a parameter: one compiled chunk for every gravity)."""
    def hamiltonian(q, p, t, grav):
        return ca.dot(p, p) / 2 + grav * ca.sum1(q[1::2])

    def rods(q, t, grav):
        rows = [q[0] ** 2 + q[1] ** 2 - 1]
        rows += [(q[2 * i] - q[2 * i - 2]) ** 2 + (q[2 * i + 1] - q[2 * i - 1]) ** 2 - 1
                 for i in range(1, links)]
        return ca.vertcat(*rows)
    return HamiltonianSystem(hamiltonian, 2 * links, {"grav": 1.0}, name=f"chain{links}",
                             constraints=rods)


def chain_start(links: int):
    """Links hanging at 0.3 rad from the vertical, each joint pushed sideways: the start is
    projected onto the hidden constraint by the march (a warning, silenced here). A hanging
    chain librates: the energy row's c changes sign, so only ``fixed`` steps march it."""
    angle = 0.3
    q = np.zeros(2 * links)
    for i in range(links):
        q[2 * i] = (i + 1) * np.sin(angle)
        q[2 * i + 1] = -(i + 1) * np.cos(angle)
    return q, np.tile([0.2, 0.0], links)


def whirl_start(links: int, omega: float = 2.0, bend: float = 0.3):
    """A bent chain (link ``i`` at ``0.3 + bend sin i`` rad from the downward vertical) turning
    as a rigid body about the pivot at ``omega`` rad/s: consistent as it stands (each rod's
    relative velocity is normal to it), and not a relative equilibrium (it flails). Its
    tensions keep c = (nu' G H_pp G' nu - f' H_zz f) / 8 > 0 (measured below), so the energy
    rules march it."""
    angles = 0.3 + bend * np.sin(np.arange(links))
    q = np.zeros(2 * links)
    q[0::2] = np.cumsum(np.sin(angles))
    q[1::2] = -np.cumsum(np.cos(angles))
    p = np.zeros(2 * links)
    p[0::2], p[1::2] = -omega * q[1::2], omega * q[0::2]
    return q, p


def children_cpu() -> float:
    """CPU seconds of the finished child processes (the C compiler)."""
    times = os.times()
    return times.children_user + times.children_system


def sign_changes(system, solution, theta) -> float:
    """The fraction of nodes where the energy row's c <= 0 (no positive root of the step)."""
    from ddvp_nlp.discrete.constrained import solvability_function  # internal: measured

    z = np.hstack([solution.q, solution.p])
    c = np.asarray(solvability_function(system).map(z.shape[0])(
        z.T, solution.t[None, :], np.tile(theta[:, None], (1, z.shape[0])))).ravel()
    return float(np.mean(c <= 0))


class PhaseClock:
    """CPU and wall seconds of a constrained march's stepping (the driver's loop over the
    compiled chunks) and of its after-check (every equation recomputed on the kept nodes),
    read by wrapping the two internal functions (internal: measured); building the march's
    functions, which a warm march in a new process pays once, is left out."""

    def __init__(self):
        from ddvp_nlp.solvers.marching.constrained_march import (  # internal: measured
            march_constrained,
        )

        constrained_march = sys.modules[march_constrained.__module__]
        self.module, self.last = constrained_march, {}
        for name in ("drive", "recheck"):
            setattr(constrained_march, name, self._wrapped(name, getattr(constrained_march,
                                                                          name)))

    def _wrapped(self, name, function):
        def timed_phase(*args, **kwargs):
            result, cpu, wall = timed(partial(function, *args, **kwargs))
            self.last[name] = (cpu, wall)
            return result
        return timed_phase


CLOCK = None


def per_step_cpu(run, steps: int, repeats: int):
    """CPU and wall seconds per step of a march of ``steps`` steps: its stepping and its
    after-check (`PhaseClock`) over its steps, medians of ``repeats`` marches; the march's
    whole CPU per step beside (its start, its functions where not cached, its result). A
    compiled chunk computes ``Compilation.chunk`` (1024) steps per call whatever the march
    keeps, so a ``steps`` below it, or not about a multiple of it, counts steps computed and
    dropped: use 1024 (the first step is made apart, then one call of 1024)."""
    global CLOCK
    CLOCK = CLOCK or PhaseClock()
    cpu, wall, whole, solution = [], [], [], None
    for _ in range(repeats):
        solution, whole_cpu, _ = timed(partial(run, steps))
        count = max(solution.t.size - 1, 1)
        cpu.append(sum(CLOCK.last[k][0] for k in ("drive", "recheck")) / count)
        wall.append(sum(CLOCK.last[k][1] for k in ("drive", "recheck")) / count)
        whole.append(whole_cpu / count)
    solution.whole_cpu_per_step = float(np.median(whole))
    solution.recheck_share = CLOCK.last["recheck"][0] / max(
        CLOCK.last["recheck"][0] + CLOCK.last["drive"][0], 1e-300)
    return float(np.median(cpu)), float(np.median(wall)), solution


def chains(sizes, steps: int, scheme: str, gravity: float = 1.0,
           methods=("multipliers",), repeats: int = 3, cache_dir=None, vm: bool = False):
    """CPU per step (`per_step_cpu`: the stepping and the after-check of ``steps`` steps, the
    same count at every size, medians of ``repeats``) of each constraint method side by
    side. ``fixed`` steps march the hanging chain; the energy rules a whirling one
    (`whirl_start`). The first march of each size and method builds and compiles its chunks
    in a fresh cache folder (or ``cache_dir``, where compiled chunks are reused): its CPU
    (this process) and the compiler's (child processes) are printed apart. ``vm``: on
    CasADi's virtual machine, nothing compiled (its cost follows the operations a step
    evaluates, where the compiled chunk of the null-space form takes long to compile)."""
    start = chain_start if scheme == "fixed" else whirl_start
    print(f"\n## Chains of N links (n = 2N, m = N), {scheme} steps from tau0 = 0.01, gravity "
          f"{gravity}, {start.__name__}: {steps} steps, median of {repeats}"
          + (", on the virtual machine" if vm else ""))
    print("| N | method | unknowns per step | build CPU s | compiler CPU s | build wall s | "
          "updates max/mean | retries | c <= 0 | us per step (CPU) | us per step (wall) | "
          "after-check share | whole march CPU us per step | max g | "
          "max hidden | max energy residual / max abs H (fixed: lee's balance, not solved) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    per_step = {}
    for links in sizes:
        system = chain_system(links)
        theta = system.parameter_vector({"grav": gravity})
        q0, p0 = start(links)
        with warnings.catch_warnings(), tempfile.TemporaryDirectory() as fresh:
            cache = cache_dir or fresh
            warnings.simplefilter("ignore", RuntimeWarning)
            runs = {}
            for method in methods:
                runs[method] = partial(_chain_march, system, q0, p0, scheme, gravity,
                                       Compilation(cache_dir=cache, fast=not vm), method)
                gcc = children_cpu()
                _, build_cpu, build_wall = timed(partial(runs[method], 2))
                runs[method].build = (build_cpu, children_cpu() - gcc, build_wall)
            for method in methods:  # after every build: the same machine state for each
                cpu, wall, solution = per_step_cpu(runs[method], steps, repeats)
                per_step[links, method] = cpu
                _chain_row(links, method, scheme, runs[method].build, cpu, wall, solution,
                           system, theta)
    for method in methods:
        sizes_run = [n for n in sizes if (n, method) in per_step]
        if len(sizes_run) > 1:
            small, large = min(sizes_run), max(sizes_run)
            print(f"\n{method}: CPU per step at N = {large} / at N = {small}: "
                  f"{per_step[large, method] / per_step[small, method]:.1f}x")
    if len(methods) > 1:
        print("\nCPU per step, " + " / ".join(methods[1:]) + f" over {methods[0]}: " + ", ".join(
            f"N = {n}: " + " ".join(f"{per_step[n, m] / per_step[n, methods[0]]:.2f}"
                                    for m in methods[1:]) for n in sizes))


def _chain_march(system, q0, p0, scheme, gravity, compilation, method, steps):
    return march(system, q0, p0, (0, 1e6), tau0=0.01, scheme=scheme, accuracy=None,
                 params={"grav": gravity}, compilation=compilation,
                 steps=StepControl(max_steps=steps, constraint_method=method))


def _chain_row(links, method, scheme, build, cpu, wall, solution, system, theta):
    record = solution.constraints
    marched = solution.t.size - 1
    H = np.abs(system.energy(solution.q, solution.p, solution.t, theta)).max()
    energy = np.abs(solution.energy_residual).max(initial=0.0) / H
    m = system.n_constraints
    unknowns = 2 * system.n + (0 if method == "null_space" else 2 * m) + (scheme != "fixed")
    ok = solution.status.name == "MAX_STEPS"  # marched every step asked for
    print(f"| {links} | {method} | {unknowns} | {build[0]:.1f} | {build[1]:.1f} | "
          f"{build[2]:.1f} | {record.newton_updates.max()}/{record.newton_updates.mean():.2f} | "
          f"{record.retries} of {marched} | {sign_changes(system, solution, theta):.3f} | "
          f"{1e6 * cpu:.1f} | {1e6 * wall:.1f} | {solution.recheck_share:.2f} | "
          f"{1e6 * solution.whole_cpu_per_step:.0f} | {record.constraint_residual.max():.1e} | "
          f"{record.hidden_residual.max():.1e} | {energy:.1e} |"
          + ("" if ok else f" {solution.message[:80]}"))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--chain-steps", type=int, default=1024)
    parser.add_argument("--links", default="10,50,128")
    parser.add_argument("--chain-schemes", default="fixed,vddvp")
    parser.add_argument("--methods", default="multipliers",
                        help="constraint methods of the chains and --only methods, side by "
                             "side: multipliers,null_space")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--vm", action="store_true",
                        help="the chains on CasADi's virtual machine (nothing compiled)")
    parser.add_argument("--cache-dir", default=None,
                        help="the chains' compile cache (default: a fresh folder per size)")
    parser.add_argument("--method-steps", type=int, default=20000,
                        help="steps of each march of --only methods")
    parser.add_argument("--gravity", type=float, default=1.0,
                        help="gravity of the chains (0: a chain in free space)")
    parser.add_argument("--only", choices=["pendulum", "spherical", "chains", "methods"])
    args = parser.parse_args()
    if args.only in (None, "pendulum"):
        pendulum(args.steps)
        order()
    if args.only in (None, "spherical"):
        spherical(args.steps)
    if args.only in (None, "methods"):
        methods_table(tuple(args.methods.split(",")), args.method_steps, args.repeats)
    if args.only in (None, "chains"):
        for scheme in args.chain_schemes.split(","):
            chains([int(v) for v in args.links.split(",")], args.chain_steps, scheme,
                   args.gravity, tuple(args.methods.split(",")), args.repeats, args.cache_dir,
                   args.vm)
    from ddvp_nlp.io import machine
    print("\n" + machine())


if __name__ == "__main__":
    main()
