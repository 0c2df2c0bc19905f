"""The double pendulum in Cartesian coordinates (4 coordinates, 2 rods; issue 48): a long vddvp
march at a chaotic energy, and the energy error against the Newton tolerance beside SHAKE's.

    python scripts/benchmarks/bench_double_pendulum.py                  # 1e6 steps; 1e5 a run
    python scripts/benchmarks/bench_double_pendulum.py --steps 100000 --tol-steps 20000

Unit masses, rods and gravity, ``H = |p|^2 / 2 + y1 + y2``. The start: both rods hanging, rates
5 and -4 (E = 10, the potential's range is [-3, 3]). It is chaotic (in the angle equations by
DOP853 at rtol 1e-11, a change of 1e-8 in the first angle grows to 35 by t = 150) and the energy
row's c = (nu' G H_pp G' nu - f' H_zz f) / 8 stays positive along it (at least 0.76 over t =
6000 in that reference; printed below along the march), so vddvp's energy-determined steps
apply. The slower starts of the double pendulum where c changes sign (rates 4 and -4, E = 5:
c < 0 at 0.5 % of the times) need fixed steps.

1. vddvp, ``--steps`` steps from tau0 = 0.005: the energy row and the interval energies'
   drift relative to E, the rods and their hidden constraints at every node, per tenth of the
   run, the Newton updates, the retries (the careful path of a failed chunk step) and the
   fraction of nodes with c <= 0.
2. The energy error against the Newton tolerance, ``--tol-steps`` steps a run at two steps.
   The march's Newton stops where its residual is at most ``tol_N max(1, |x|)`` or its update
   at most ``100 tol_N max(1, |x|)``, with ``tol_N = StepControl.tol / 1e4`` (the acceptance
   tolerance of a step's residuals, default 1e-10: tol_N = 1e-14; ``RESIDUAL_SHARE`` and
   ``UPDATE_SHARE`` of ``solvers/marching/constrained_steps.py``). The study sets the user's
   option ``StepControl(tol=1e4 tol_N)`` for tol_N = 1e-8 ... 1e-14.
   vddvp's error: the largest ``|E_k - E_1| / E`` of the interval energies (the sum of the
   energy rows, recomputed unscaled on the nodes). SHAKE at its constraint tolerance ``tol``
   (the same numbers, in the units of g): the largest ``|H(z_k) - H(z_0)| / E`` at the nodes
   and the ratio of its last tenth to its first (growth along the run). On this chaotic
   orbit SHAKE's node energy error is its step's at every tolerance: the tolerance's share
   is measured on a regular orbit by ``bench_shake_tolerance.py`` (against the same run at
   tolerance 1e-15, beside vddvp's interval energy against its Newton tolerance).
"""

from __future__ import annotations

import argparse
import time
import warnings

import casadi as ca
import numpy as np

from ddvp_nlp import HamiltonianSystem, StepControl, march
from ddvp_nlp.discrete.constrained import solvability_function  # internal: measured
from ddvp_nlp.io import machine
from ddvp_nlp.solvers import find_compiler
from ddvp_nlp.solvers.baselines.rattle import rattle_run  # internal: measured

TOLERANCES = (1e-8, 1e-10, 1e-12, 1e-14)
NEWTON_SHARE = 1e4  # StepControl.tol over the Newton's residual test (constrained_steps.py)
ANGLES = (0.0, 0.0, 5.0, -4.0)


def hamiltonian(q, p, t):
    return (p[0] ** 2 + p[1] ** 2 + p[2] ** 2 + p[3] ** 2) / 2 + q[1] + q[3]


def rods(q, t):
    return ca.vertcat(q[0] ** 2 + q[1] ** 2 - 1, (q[2] - q[0]) ** 2 + (q[3] - q[1]) ** 2 - 1)


SYSTEM = HamiltonianSystem(hamiltonian, 4, name="double_pendulum", constraints=rods)


def start():
    """Both bobs' positions and momenta from the angles (from the downward vertical, each
    rod's own) and their rates."""
    a, b, wa, wb = ANGLES
    q = np.array([np.sin(a), -np.cos(a), np.sin(a) + np.sin(b), -np.cos(a) - np.cos(b)])
    u1, v1 = wa * np.cos(a), wa * np.sin(a)
    p = np.array([u1, v1, u1 + wb * np.cos(b), v1 + wb * np.sin(b)])
    return q, p


def timed(function, *args, **kwargs):
    cpu, wall = time.process_time(), time.perf_counter()
    result = function(*args, **kwargs)
    return result, time.process_time() - cpu, time.perf_counter() - wall


def tenths(values) -> str:
    return " ".join(f"{part.max():.1e}" for part in np.array_split(np.asarray(values), 10))


def energy_of(q, p):
    return 0.5 * np.sum(p ** 2, axis=1) + q[:, 1] + q[:, 3]


def vddvp_march(steps: int, tau0: float, *, tol: float | None = None):
    """vddvp to ``steps`` steps from `start` (``max_steps``: the span is long enough), with
    the Newton tolerance ``tol`` (module docstring; ``None``: the march's own)."""
    q0, p0 = start()
    control = StepControl(max_steps=steps) if tol is None else \
        StepControl(max_steps=steps, tol=NEWTON_SHARE * tol)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # a consistent start: no move
        return march(SYSTEM, q0, p0, (0, 10 * steps * tau0), tau0=tau0, scheme="vddvp",
                     steps=control, accuracy=None)


def long_march(steps: int, tau0: float):
    vddvp_march(100, tau0)  # builds and compiles the chunks (not measured)
    solution, cpu, wall = timed(vddvp_march, steps, tau0)
    record = solution.constraints
    E = abs(energy_of(solution.q[:1], solution.p[:1])[0])
    row = np.abs(solution.energy_residual) / E
    drift = np.abs(np.cumsum(solution.energy_residual)) / E
    z = np.hstack([solution.q, solution.p])
    c = np.asarray(solvability_function(SYSTEM).map(z.shape[0])(
        z.T, solution.t[None, :], np.zeros((0, z.shape[0])))).ravel()
    node = np.abs(energy_of(solution.q, solution.p) - energy_of(solution.q[:1],
                                                                  solution.p[:1])) / E
    marched = solution.t.size - 1
    print(f"## 1. vddvp, {marched} steps from angles {ANGLES} (E = {E:g}), tau0 = {tau0}: "
          f"{solution.status.value}, to t = {solution.t[-1]:.1f} (mean step "
          f"{solution.t[-1] / marched:.5f}, min {np.diff(solution.t).min():.2e}, max "
          f"{np.diff(solution.t).max():.2e})")
    print("| quantity | max | per tenth of the run |")
    print("|---|---|---|")
    for name, values in (("energy row / E", row), ("interval energy drift |E_k - E_1| / E",
                                                    drift),
                         ("abs g", record.constraint_residual),
                         ("hidden constraint", record.hidden_residual),
                         ("node |H - H_0| / E (not the conserved quantity)", node)):
        print(f"| {name} | {values.max():.2e} | {tenths(values)} |")
    print(f"\nNewton updates a step: max {record.newton_updates.max()}, mean "
          f"{record.newton_updates.mean():.2f}; retries {record.retries} of {marched} steps; "
          f"c <= 0 at {np.mean(c <= 0):.4f} of the nodes (c min {c.min():.3g}); "
          f"CPU {cpu:.2f} s, wall {wall:.2f} s ({1e6 * cpu / marched:.2f} us a step CPU)")


def against_tolerance(steps: int, taus, compiler):
    print(f"\n## 2. Energy error against the Newton / constraint tolerance, {steps} steps a run")
    print("| tol (Newton's; SHAKE's) | tau | vddvp max abs(E_k - E_1) / E | vddvp max row | "
          "vddvp updates mean | CPU s | wall s | SHAKE max abs(H - H_0) / E | "
          "SHAKE last / first tenth | CPU s | wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    q0, p0 = start()
    E = abs(energy_of(q0[None], p0[None])[0])
    for tol in TOLERANCES:
        for tau in taus:
            solution, cpu, wall = timed(vddvp_march, steps, tau, tol=tol)
            drift = np.abs(np.cumsum(solution.energy_residual)).max() / E
            row = np.abs(solution.energy_residual).max() / E
            shake, s_cpu, s_wall = timed(rattle_run, SYSTEM, q0, p0, tau=tau, t_end=steps * tau,
                                         method="shake", tol=tol, compiler=compiler)
            gap = np.abs(energy_of(shake.q, shake.p) - E_start(q0, p0)) / E
            tenth = max(gap.size // 10, 1)
            growth = gap[-tenth:].max() / max(gap[:tenth].max(), np.finfo(float).tiny)
            status = "" if solution.status.name in ("SUCCESS", "MAX_STEPS") else \
                f" (vddvp: {solution.status.value})"
            print(f"| {tol:.0e} | {tau} | {drift:.2e} | {row:.2e} | "
                  f"{solution.constraints.newton_updates.mean():.2f} | {cpu:.2f} | {wall:.2f} "
                  f"| {gap.max():.2e} | {growth:.1f} | {s_cpu:.2f} | {s_wall:.2f} |{status}")


def E_start(q0, p0) -> float:
    return float(energy_of(q0[None], p0[None])[0])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--tol-steps", type=int, default=100_000)
    parser.add_argument("--tau0", type=float, default=0.005)
    parser.add_argument("--only", choices=["long", "tolerance"])
    args = parser.parse_args(argv)
    print(machine() + "\n")
    if args.only in (None, "long"):
        long_march(args.steps, args.tau0)
    if args.only in (None, "tolerance"):
        against_tolerance(args.tol_steps, (2 * args.tau0, args.tau0), find_compiler())


if __name__ == "__main__":
    main()
