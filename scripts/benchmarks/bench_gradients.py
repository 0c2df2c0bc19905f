"""What a march's derivatives cost (issue 47), each against the march itself, side by side in one
run: CPU time of this process (``time.process_time``) beside wall time, the medians of
``--repeats`` interleaved warm runs (the compiled chunk and the Jacobians built by a first run
that is not counted), and the ratios of the medians.

1. Reverse mode: the gradient of a scalar (a random cotangent on the states at 8 output times)
   in the 64 parameters and the initial state of a pendulum whose potential is a 64-term Fourier
   series, ``gradient(sol, c)``: the sweep alone (``check=False``) and with its own check (two
   marches more), against the march (target: at most 5 marches).
2. Forward mode in the ``2n`` initial values: ``march(..., derivatives=DerivativeOptions(("q0",
   "p0"), "forward"))``, its check included, against the plain march (target: at most ``2n +
   2``), on the Fourier pendulum (2n = 2) and on Kepler (2n = 4).
3. Memory: a march of ``--memory-steps`` steps (default 1e6) and the reverse sweep over it, on
   the plain pendulum (one parameter) and on the Fourier pendulum, each in its own child
   process (peak resident memory, ``VmHWM``, above the child's after a warm first march of a
   few steps): the peak while the sweep runs (the solution's nodes held, and one chunk of
   Jacobians) against the march's own (target: at most 2x), and the sweep's peak above the
   process it started in (the allocator may reuse what the march freed).

Every march runs without the accuracy check (``accuracy=None``, as the derivative's check runs
its marches), so that the ratios compare like with like.

    python scripts/benchmarks/bench_gradients.py [--repeats 5] [--memory-steps 1000000]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

import casadi as ca
import numpy as np

from ddvp_nlp import DerivativeOptions, HamiltonianSystem, Output, gradient, march

TERMS = 64


def fourier_pendulum() -> HamiltonianSystem:
    """``H = p^2 / 2 + sum_j a_j (1 - cos(j q)) / j^2``, ``j = 1..64``, ``a_1 = 1``, ``a_j =
    0.3 / j`` (a pendulum whose potential has 64 parameters)."""
    names = [f"a{j}" for j in range(1, TERMS + 1)]

    def H(q, p, t, **a):
        return p[0] ** 2 / 2 + sum(a[f"a{j}"] * (1 - ca.cos(j * q[0])) / j ** 2
                                   for j in range(1, TERMS + 1))
    values = {name: (1.0 if j == 1 else 0.3 / j) for j, name in enumerate(names, 1)}
    return HamiltonianSystem(H, 1, values, name="fourier_pendulum_64")


def kepler() -> HamiltonianSystem:
    def H(q, p, t, mu):
        return ca.sumsqr(p) / 2 - mu / ca.norm_2(q)
    return HamiltonianSystem(H, 2, {"mu": 1.0}, name="kepler_mu")


def runs():
    """(label, system, q0, p0, t_end, tau0) of the cost rows."""
    return [("fourier pendulum (n = 1, m = 64)", fourier_pendulum(), [0.8], [0.0], 100.0, 0.01),
            ("kepler e = 0.5 (n = 2, m = 1)", kepler(), [1.5, 0.0], [0.0, np.sqrt(1 / 3)],
             60.0, 0.01)]


def timed(function):
    cpu, wall = time.process_time(), time.perf_counter()
    result = function()
    return time.process_time() - cpu, time.perf_counter() - wall, result


def medians(samples):
    return {key: (statistics.median(s[0] for s in values),
                  statistics.median(s[1] for s in values)) for key, values in samples.items()}


def cost_rows(repeats: int):
    rows = []
    for label, system, q0, p0, t_end, tau0 in runs():
        times = np.linspace(0.1 * t_end, t_end, 8)
        cotangent = np.random.default_rng(0).normal(size=(8, 2 * system.n))

        def plain(derivatives=None, system=system, q0=q0, p0=p0, t_end=t_end, tau0=tau0,
                  times=times):
            return march(system, q0, p0, (0.0, t_end), tau0=tau0, accuracy=None,
                         output=Output(t_eval=times), derivatives=derivatives)
        base = plain()
        variants = {
            "march": plain,
            "reverse sweep": lambda base=base, c=cotangent: gradient(base, c, check=False),
            "reverse + check": lambda base=base, c=cotangent: gradient(base, c),
            "forward 2n": lambda plain=plain: plain(DerivativeOptions(("q0", "p0"), "forward")),
        }
        samples = {key: [] for key in variants}
        for function in variants.values():  # warm: builds and loads every function once
            function()
        for _ in range(repeats):
            for key, function in variants.items():
                cpu, wall, _ = timed(function)
                samples[key].append((cpu, wall))
        found = medians(samples)
        checked = gradient(base, cotangent)
        forward = plain(DerivativeOptions(("q0", "p0"), "forward"))
        rows.append((label, base.t.size - 1, system.n, found, checked.check,
                     forward.derivatives.check))
    return rows


CHILD = r"""
import json, sys, time, numpy as np
sys.path.insert(0, {root!r})
from scripts.benchmarks.bench_gradients import fourier_pendulum, pendulum
from ddvp_nlp import Output, march, gradient

def status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1]) * 1024
def reset_peak():
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
system = {system}()
steps, sweep = {steps}, {sweep}
tau0 = 0.01
march(system, [0.8], [0.0], (0.0, 5 * tau0), tau0=tau0, accuracy=None,
      output=Output(t_eval=[2 * tau0]))
gradient(march(system, [0.8], [0.0], (0.0, 5 * tau0), tau0=tau0, accuracy=None,
               output=Output(t_eval=[2 * tau0])), np.ones((1, 2)), check=False)
base = status("VmRSS")
reset_peak()
t_end = steps * tau0 * 0.999
sol = march(system, [0.8], [0.0], (0.0, t_end), tau0=tau0, accuracy=None,
            output=Output(t_eval=np.linspace(0.1 * t_end, t_end, 8)))
march_peak = status("VmHWM")
before = status("VmRSS")
reset_peak()
cpu = time.process_time()
if sweep:
    gradient(sol, np.ones((8, 2)), check=False)
cpu = time.process_time() - cpu
print(json.dumps(dict(steps=int(sol.t.size - 1), base=base, march_peak=march_peak,
                      before=before, sweep_peak=status("VmHWM"), sweep_cpu=cpu)))
"""


def pendulum() -> HamiltonianSystem:
    def H(q, p, t, w):
        return p[0] ** 2 / 2 + w ** 2 * (1 - ca.cos(q[0]))
    return HamiltonianSystem(H, 1, {"w": 1.0}, name="pendulum_w")


def memory_row(steps: int, system: str):
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    code = CHILD.format(root=root, steps=steps, sweep=True, system=system)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--memory-steps", type=int, default=1_000_000)
    parser.add_argument("--memory-only", action="store_true", help="skip the cost rows")
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}; medians of {args.repeats} warm runs; "
          "CPU s | wall s; ratio to the march CPU | wall")
    for label, steps, n, found, checked, forward_check in \
            ([] if args.memory_only else cost_rows(args.repeats)):
        cpu0, wall0 = found["march"]
        print(f"\n{label}, {steps} steps")
        for key, (cpu, wall) in found.items():
            target = {"reverse + check": "<= 5", "forward 2n": f"<= {2 * n + 2}"}.get(key, "")
            print(f"  {key:16s} {cpu:8.3f} | {wall:8.3f}   x {cpu / cpu0:5.2f} | "
                  f"{wall / wall0:5.2f}   {target}")
        print(f"  checks: reverse {checked.verdict} ({checked.error:.1e}), forward "
              f"{forward_check.verdict} ({forward_check.error:.1e})")
    for system in ("pendulum", "fourier_pendulum"):
        row = memory_row(args.memory_steps, system)
        mib = 2 ** 20
        march_mem = (row["march_peak"] - row["base"]) / mib
        sweep_mem = (row["sweep_peak"] - row["base"]) / mib
        added = (row["sweep_peak"] - row["before"]) / mib
        print(f"\nmemory, {system}, {row['steps']} steps, peaks above the warm process: march "
              f"+{march_mem:.0f} MiB, reverse sweep (the solution held) +{sweep_mem:.0f} MiB: "
              f"ratio {sweep_mem / march_mem:.2f} (target <= 2); the sweep's peak above the "
              f"process it started in {added:+.0f} MiB; sweep CPU {row['sweep_cpu']:.1f} s")


if __name__ == "__main__":
    main()
