"""Many degrees of freedom and first runs: issue 38's targets for chains and new scenes.

- An alpha-FPU chain (n unit masses between fixed walls, nearest-neighbour springs d^2/2 +
  d^3/12), written as a user's scene file: the warm march's CPU per step at each n (check off,
  the march alone, ``--repeats`` runs, median), the ratio n = 64 : n = 8 (target <= 10), and
  the first run at each n from an empty compile cache, the whole ``ddvp march FILE`` process
  (target <= 30 s CPU at n = 64).
- A new one-degree-of-freedom scene (a quartic oscillator) from an empty cache, the whole
  process (target <= 3 s CPU).

Whole processes are timed by ``wait4`` (user + sys of the process and its compilers); the
machine's load is printed beside.

    python scripts/benchmarks/bench_chain.py [--sizes 8,64] [--repeats 3] [--t-end 100]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

CHAIN = '''
"""alpha-FPU chain: {n} unit masses between fixed walls, nearest-neighbour springs."""
import casadi as ca
import numpy as np

from ddvp_nlp import Scene

N = {n}


def hamiltonian(q, p, t, alpha):
    x = ca.vertcat(0, q, 0)
    d = x[1:] - x[:-1]
    return ca.sumsqr(p) / 2 + ca.sum1(d ** 2 / 2 + alpha * d ** 3 / 3)


i = np.arange(1, N + 1)
omega = 2 * np.sin(np.pi / (2 * (N + 1)))
scene = Scene(hamiltonian, n=N, params={{"alpha": 0.25}},
              q0=2 / (omega * np.sqrt(N + 1)) * np.sin(np.pi * i / (N + 1)), p0=np.zeros(N),
              tau0=0.05, t_end={t_end})
'''

QUARTIC = '''
"""A quartic oscillator nobody compiled before: H = p^2/2 + q^4/4 + {salt} q^2."""
import casadi as ca

from ddvp_nlp import Scene


def hamiltonian(q, p, t):
    return ca.sumsqr(p) / 2 + q[0] ** 4 / 4 + {salt} * q[0] ** 2


scene = Scene(hamiltonian, n=1, q0=[1.0], p0=[0.0], tau0=0.05, t_end=50.0)
'''

TARGET_RATIO, TARGET_FIRST_64, TARGET_FIRST_1DOF = 10.0, 30.0, 3.0


def project_root() -> Path:
    for folder in Path(__file__).resolve().parents:
        if (folder / "ddvp_nlp").is_dir():
            return folder
    raise SystemExit("bench_chain.py: no ddvp_nlp/ in a folder above this script")


def whole_process(argv, cache: Path) -> tuple[float, float, float, int]:
    """CPU (user + sys, children included), wall, peak MB and exit code of one process."""
    env = {**os.environ, "DDVP_NLP_CACHE": str(cache)}
    started = time.perf_counter()
    child = subprocess.Popen(argv, cwd=project_root(), env=env, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE)
    _, status, usage = os.wait4(child.pid, 0)
    child.stderr.close()
    return (usage.ru_utime + usage.ru_stime, time.perf_counter() - started,
            usage.ru_maxrss / 1024, os.waitstatus_to_exitcode(status))


PER_STEP = textwrap.dedent('''
    import sys, time, warnings
    warnings.simplefilter("ignore")
    from ddvp_nlp import load_scene, march
    scene = load_scene(sys.argv[1]); config = scene.resolve({})
    run = lambda: march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                        tau0=config.tau0, params=config.params, accuracy=None)
    run()
    cpu = []
    for _ in range(int(sys.argv[2])):
        started = time.process_time(); solution = run()
        cpu.append((time.process_time() - started) / solution.steps)
    print(sorted(cpu)[len(cpu) // 2], solution.steps, solution.stats["path"],
          solution.stats["fast_steps"])
''')


def per_step(scene_file: Path, repeats: int, cache: Path) -> tuple[float, int, str]:
    """The warm march's median CPU per step (check off), in a process of its own."""
    env = {**os.environ, "DDVP_NLP_CACHE": str(cache)}
    out = subprocess.run([sys.executable, "-c", PER_STEP, str(scene_file), str(repeats)],
                         cwd=project_root(), env=env, capture_output=True, text=True,
                         check=True).stdout.split()
    return float(out[0]), int(out[1]), f"{out[2]}, {out[3]} fast steps"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="8,64")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--t-end", type=float, default=100.0)
    args = parser.parse_args()
    sys.path.insert(0, str(project_root()))
    from ddvp_nlp.io import machine

    print(machine())
    sizes = [int(v) for v in args.sizes.split(",")]
    rows, steps_cpu = [], {}
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        for n in sizes:
            scene_file = scratch / f"alpha_fpu_{n}.py"
            scene_file.write_text(CHAIN.format(n=n, t_end=args.t_end))
            cache = scratch / f"cache_{n}"
            cpu, wall, peak, code = whole_process(
                [sys.executable, "-m", "ddvp_nlp.cli", "march", str(scene_file), "--no-plot",
                 "--no-progress", "--out", str(scratch / f"run_{n}")], cache)
            step, count, path = per_step(scene_file, args.repeats, cache)
            steps_cpu[n] = step
            rows.append(f"| alpha-FPU n = {n} | {code} | {cpu:.2f} | {wall:.2f} | {peak:.0f} | "
                        f"{step * 1e6:.2f} ({count} steps; {path}) |")
        quartic = (scratch / "quartic").with_suffix(".py")  # a scratch file, not ours
        quartic.write_text(QUARTIC.format(salt=repr(time.time() % 1)))  # never cached before
        cpu1, wall1, peak1, code1 = whole_process(
            [sys.executable, "-m", "ddvp_nlp.cli", "march", str(quartic), "--no-plot",
             "--no-progress", "--out", str(scratch / "run_quartic")], scratch / "cache_1")
    print("\n| scene | exit | first run CPU s (whole process, empty cache) | wall s | peak MB "
          "| warm march CPU us / step (check off) |")
    print("|---|---|---|---|---|---|")
    print("\n".join(rows))
    print(f"| quartic oscillator (1 dof) | {code1} | {cpu1:.2f} | {wall1:.2f} | {peak1:.0f} | |")
    if 8 in steps_cpu and 64 in steps_cpu:
        ratio = steps_cpu[64] / steps_cpu[8]
        print(f"\n- per step, n = 64 against n = 8: {ratio:.2f} (target <= {TARGET_RATIO:g}: "
              f"{'met' if ratio <= TARGET_RATIO else 'MISSED'})")
    print(f"- first run of a new 1-dof scene: {cpu1:.2f} s CPU (target <= {TARGET_FIRST_1DOF:g}:"
          f" {'met' if cpu1 <= TARGET_FIRST_1DOF else 'MISSED'})")
    print(machine())


if __name__ == "__main__":
    main()
