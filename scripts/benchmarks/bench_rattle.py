"""The constrained exact flow and RATTLE/SHAKE, measured (issue 48), side by side in one run:

1. the constrained reference (``solvers/exact/constrained.py``) against the Cartesian pendulum's
   elliptic solution and the spherical pendulum in angles (scipy DOP853 at rtol 1e-13): its
   true error, its claimed bound, their ratio, the constraints at its nodes, per tolerance;
2. RATTLE over ``--steps`` steps of the Cartesian pendulum: ``|g|`` and the hidden constraint
   at every node (largest, and first against last tenth for a trend); the spherical pendulum's
   angular momentum about the vertical;
3. the energy error against the constraint tolerance 1e-8 ... 1e-14 for SHAKE and RATTLE at the
   same step, each against the same method at tol 1e-15 (what the tolerance alone costs), and
   its growth (last tenth over first tenth of the run).

CPU of this process (``time.process_time``) beside wall. The constrained systems are made by
attaching ``constraints``, ``n_constraints`` and ``G`` to a ``HamiltonianSystem`` (the
interface of ``HamiltonianSystem(..., constraints=g)``, a stand-in until it lands).

    python scripts/benchmarks/bench_rattle.py [--steps 1000000] [--tau 0.01]
"""

from __future__ import annotations

import argparse
import time

import casadi as ca
import numpy as np
from scipy.integrate import solve_ivp
from scipy.special import ellipj, ellipk

from ddvp_nlp import HamiltonianSystem
from ddvp_nlp.io import machine
from ddvp_nlp.solvers import find_compiler

# internals measured here (tests/architecture lists them): the steppers and the reference
from ddvp_nlp.solvers.baselines.rattle import rattle_run  # internal: measured
from ddvp_nlp.solvers.exact.constrained import constraint_residuals  # internal: measured
from ddvp_nlp.solvers.exact.constrained_reference import constrained_reference  # internal

TOLERANCES = (1e-8, 1e-10, 1e-12, 1e-14)


def constrained(system, g):
    G = ca.vec(ca.SX(g(system.q, system.t)))
    system.constraints, system.n_constraints, system.G = g, int(G.numel()), G
    return system


def planar():
    return constrained(HamiltonianSystem(lambda q, p, t: (p[0] ** 2 + p[1] ** 2) / 2 + q[1], 2,
                                         name="cartesian_pendulum"),
                       lambda q, t: q[0] ** 2 + q[1] ** 2 - 1)


def spherical():
    return constrained(HamiltonianSystem(
        lambda q, p, t: (p[0] ** 2 + p[1] ** 2 + p[2] ** 2) / 2 + q[2], 3,
        name="spherical_pendulum"), lambda q, t: q[0] ** 2 + q[1] ** 2 + q[2] ** 2 - 1)


ANGLE = 1.0
PLANAR_Z0 = np.array([np.sin(ANGLE), -np.cos(ANGLE), 0.0, 0.0])
SPHERICAL_Z0 = np.array([0.0, np.sin(0.1), -np.cos(0.1), 0.06, 0.0, 0.0])


def elliptic(t):
    k = np.sin(ANGLE / 2)
    sn, cn, _, _ = ellipj(ellipk(k * k) - t, k * k)
    theta, omega = 2 * np.arcsin(k * sn), -2 * k * cn
    return np.column_stack([np.sin(theta), -np.cos(theta), omega * np.cos(theta),
                            omega * np.sin(theta)])


def in_angles(t):
    q, v = SPHERICAL_Z0[:3], SPHERICAL_Z0[3:]
    th0, ph0 = np.arccos(-q[2]), np.arctan2(q[1], q[0])
    e_th = np.array([np.cos(th0) * np.cos(ph0), np.cos(th0) * np.sin(ph0), np.sin(th0)])
    e_ph = np.array([-np.sin(ph0), np.cos(ph0), 0.0])

    def rhs(_, u):
        th, _, a, b = u
        return [a, b, np.sin(th) * np.cos(th) * b ** 2 - np.sin(th),
                -2 * np.cos(th) / np.sin(th) * a * b]
    th, ph, a, b = solve_ivp(rhs, (t[0], t[-1]), [th0, ph0, e_th @ v, e_ph @ v / np.sin(th0)],
                             method="DOP853", rtol=1e-13, atol=1e-13, t_eval=t).y
    s, c = np.sin(th), np.cos(th)
    qs = np.column_stack([s * np.cos(ph), s * np.sin(ph), -c])
    vs = a[:, None] * np.column_stack([c * np.cos(ph), c * np.sin(ph), s]) + \
        (b * s)[:, None] * np.column_stack([-np.sin(ph), np.cos(ph), 0 * ph])
    return np.hstack([qs, vs])


def timed(function, *args, **options):
    cpu, wall = time.process_time(), time.perf_counter()
    result = function(*args, **options)
    return time.process_time() - cpu, time.perf_counter() - wall, result


def reference_table():
    print("\n1. the constrained reference against the exact motion (t in [0, 100])")
    print("| system | rtol | steps | true error | claimed bound | true / claim | "
          "nodes max |g| | max |h| | CPU s | wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    t = np.linspace(0, 100, 4001)
    for name, system, z0, theta, exact in (
            ("planar", planar(), PLANAR_Z0, [], elliptic(t)),
            ("spherical", spherical(), SPHERICAL_Z0, [], in_angles(t))):
        scale = exact.max(axis=0) - exact.min(axis=0)
        for rtol in (1e-6, 1e-8, 1e-10, 1e-12):
            cpu, wall, ref = timed(constrained_reference, system, z0, 0.0, 100.0, theta,
                                   rtol=rtol)
            error = np.max(np.abs(ref.states(t) - exact) / scale, axis=1)
            claim = ref.error(t, scale)
            g, h = constraint_residuals(system, *ref.fine.nodes(), theta)
            print(f"| {name} | {rtol:.0e} | {ref.fine.steps} | {error.max():.2e} | "
                  f"{claim.max():.2e} | {np.max(error / claim):.2f} | {g.max():.1e} | "
                  f"{h.max():.1e} | {cpu:.2f} | {wall:.2f} |")


def trend(values):
    tenth = max(values.size // 10, 1)
    return values[-tenth:].max(), values[:tenth].max()


def rattle_long(steps: int, tau: float, compiler):
    print(f"\n2. RATTLE, {steps} steps of {tau} (default tolerance)")
    for name, system, z0 in (("planar", planar(), PLANAR_Z0),
                             ("spherical", spherical(), SPHERICAL_Z0)):
        n = system.n
        cpu, wall, solution = timed(rattle_run, system, z0[:n], z0[n:], tau=tau,
                                    t_end=steps * tau, compiler=compiler)
        z = np.hstack([solution.q, solution.p])
        g, h = constraint_residuals(system, solution.t, z, [])
        line = (f"{name}: {solution.status.value}; max |g| {g.max():.1e} (last tenth "
                f"{trend(g)[0]:.1e}, first {trend(g)[1]:.1e}), max |h| {h.max():.1e}; Newton "
                f"iterations per step {solution.stats['newton'].mean():.2f} (max "
                f"{solution.stats['newton'].max():.0f}); CPU {cpu:.2f} s, wall {wall:.2f} s")
        if n == 3:
            Lz = z[:, 0] * z[:, 4] - z[:, 1] * z[:, 3]
            line += f"; L_z relative error {np.max(np.abs(Lz / Lz[0] - 1)):.1e}"
        print(line)


def energy_against_tolerance(steps: int, tau: float, compiler):
    print(f"\n3. energy error against the constraint tolerance, planar, {steps} steps of {tau}:"
          " max |H - H(tol 1e-15)| (same method and step), and last tenth / first tenth")
    print("| tol | SHAKE | SHAKE growth | SHAKE CPU s | wall s | RATTLE | RATTLE growth | "
          "RATTLE CPU s | wall s |")
    print("|---|---|---|---|---|---|---|---|---|")
    system = planar()

    def energies(method, tol):
        cpu, wall, s = timed(rattle_run, system, PLANAR_Z0[:2], PLANAR_Z0[2:], tau=tau,
                              t_end=steps * tau, method=method, tol=tol, compiler=compiler)
        return system.energy(s.q, s.p, s.t, []), cpu, wall
    tight = {m: energies(m, 1e-15)[0] for m in ("shake", "rattle")}
    for tol in TOLERANCES:
        cells = [f"{tol:.0e}"]
        for method in ("shake", "rattle"):
            H, cpu, wall = energies(method, tol)
            gap = np.abs(H - tight[method])
            last, first = trend(gap)
            growth = last / first if first > 0 else float("nan")
            cells += [f"{gap.max():.1e}", f"{growth:.1f}", f"{cpu:.2f}", f"{wall:.2f}"]
        print("| " + " | ".join(cells) + " |")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--tau", type=float, default=0.01)
    args = parser.parse_args(argv)
    print(machine())
    compiler = find_compiler()
    reference_table()
    rattle_long(args.steps, args.tau, compiler)
    energy_against_tolerance(args.steps, args.tau, compiler)


if __name__ == "__main__":
    main()
