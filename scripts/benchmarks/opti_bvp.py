"""Reference for ``bench_ipopt.py``: the pendulum's fixed-endpoint problem under the vddvp rule,
written by hand with CasADi's Opti and solved by IPOPT, as a user without ddvp_nlp would.

Not part of the package: it imports nothing from ddvp_nlp. The problem is the one
``bench_bvp.py`` solves (``H = p^2/2 + 1 - cos q``, ``q(0) = 0.5``, ``q(18)`` the end of a
fixed-step march from ``p(0) = 0.5`` with step 0.01, ``N`` nodes, every node time free but the
two ends), with its rows as the package scales them:

    q_{k+1} - q_k - tau_k P_k = 0,   p_{k+1} - p_k + tau_k sin Q_k = 0       (k = 0 .. N-2)
    (H(Q_k, P_k) - H(Q_{k-1}, P_{k-1})) / h = 0                             (k = 1 .. N-2)
    Q_k = (q_k + q_{k+1})/2,  P_k = (p_k + p_{k+1})/2,

``h = 18/(N-1)`` the mean step (the energy rows divided by it are O(1) in the node times), and
no bound on the steps: a user starting this close would not write one (ddvp_nlp keeps
``t_{k+1} - t_k >= 1e-3 h`` as bounded rows; with them and IPOPT's default barrier parameter the
script took over a minute of CPU at N = 1e5 from the start below, IPOPT pushing the iterate off
its start first). The
start is what such a user has at hand: the exact motion (scipy's DOP853 at rtol 1e-12 from
``(0.5, 0.5)``) on node times with the vddvp rule's site density ``tau ~ (f' H_zz f)^(-1/3)``
(the paper's section 4: ``V'' p^2 + V'^2``), ten lines below, or (``--start FILE``) given
nodes: ``bench_ipopt.py`` hands it the point ddvp_nlp's own released phase starts from, so that
both IPOPTs solve the same rows from the same point (from the exact motion IPOPT's defaults took
28 iterations at N = 1e4 and 23 at 1e5, 132 s CPU there: no reference at 1e6). IPOPT with its
defaults but the tolerances the package's verification asks for (``--tol``, default 1e-10).

    python scripts/benchmarks/opti_bvp.py 100000 [--tol 1e-10] [--q-end Q] [--start FILE.npz]

Prints one JSON line: IPOPT's status and iterations, build and solve seconds (wall and CPU), the
largest rows, the peak memory of the process.
"""

from __future__ import annotations

import argparse
import json
import resource
import time

import casadi as ca
import numpy as np
from scipy.integrate import solve_ivp

T_END = 18.0


def end_position() -> float:
    """``q(18)`` of the fixed-step march the benchmark takes its endpoints from: the implicit
    midpoint rule with step 0.01 from ``(0.5, 0.5)`` (the ``fixed`` scheme of the pendulum)."""
    q, p, tau = 0.5, 0.5, 0.01
    for _ in range(int(round(T_END / tau))):
        q_next, p_next = q, p
        for _ in range(50):  # fixed point: contraction factor ~ tau
            Q, P = (q + q_next) / 2, (p + p_next) / 2
            q_next, p_next = q + tau * P, p - tau * np.sin(Q)
        q, p = q_next, p_next
    return q


def start(nodes: int, path: str | None = None):
    """The nodes in ``path`` (an ``.npz`` with ``t``, ``q``, ``p``), else the exact motion on
    node times of density ``w^(1/3)``, ``w = cos(q) p^2 + sin(q)^2``."""
    if path is not None:
        data = np.load(path)
        return data["t"], data["q"].ravel(), data["p"].ravel()
    fine = np.linspace(0.0, T_END, 20001)
    motion = solve_ivp(lambda t, z: [z[1], -np.sin(z[0])], (0.0, T_END), [0.5, 0.5],
                       method="DOP853", rtol=1e-12, atol=1e-12, dense_output=True)
    q, p = motion.sol(fine)
    density = np.maximum(np.cos(q) * p ** 2 + np.sin(q) ** 2, 1e-12) ** (1 / 3)
    mass = np.concatenate([[0.0], np.cumsum((density[:-1] + density[1:]) / 2 * np.diff(fine))])
    t = np.interp(np.linspace(0.0, mass[-1], nodes), mass, fine)
    q, p = motion.sol(t)
    return t, q, p


def solve(nodes: int, tol: float, q_end: float, start_path: str | None = None) -> dict:
    wall, cpu = time.perf_counter(), time.process_time()
    h = T_END / (nodes - 1)
    opti = ca.Opti()
    t, q, p = opti.variable(nodes), opti.variable(nodes), opti.variable(nodes)
    tau = t[1:] - t[:-1]
    Q, P = (q[:-1] + q[1:]) / 2, (p[:-1] + p[1:]) / 2
    E = P ** 2 / 2 + 1 - ca.cos(Q)
    opti.subject_to(q[1:] - q[:-1] - tau * P == 0)
    opti.subject_to(p[1:] - p[:-1] + tau * ca.sin(Q) == 0)
    opti.subject_to((E[1:] - E[:-1]) / h == 0)
    opti.subject_to(t[0] == 0.0)
    opti.subject_to(t[-1] == T_END)
    opti.subject_to(q[0] == 0.5)
    opti.subject_to(q[-1] == q_end)
    opti.minimize(0)
    t0, q0, p0 = start(nodes, start_path)
    opti.set_initial(t, t0)
    opti.set_initial(q, q0)
    opti.set_initial(p, p0)
    opti.solver("ipopt", {"print_time": False},
                {"tol": tol, "constr_viol_tol": tol, "print_level": 0, "sb": "yes"})
    built = time.perf_counter()
    try:
        solution = opti.solve()
        stats = solution.stats()
        tv, qv, pv = (solution.value(v) for v in (t, q, p))
    except RuntimeError:  # IPOPT did not succeed: report where it stopped
        stats = opti.stats()
        tv, qv, pv = (opti.debug.value(v) for v in (t, q, p))
    solved = time.perf_counter()
    taus = np.diff(tv)
    Qv, Pv = (qv[:-1] + qv[1:]) / 2, (pv[:-1] + pv[1:]) / 2
    canonical = max(np.max(np.abs(np.diff(qv) - taus * Pv)),
                    np.max(np.abs(np.diff(pv) + taus * np.sin(Qv))))
    Ev = Pv ** 2 / 2 + 1 - np.cos(Qv)
    return {"N": nodes, "status": stats["return_status"], "iterations": stats["iter_count"],
            "build_s": built - wall, "solve_s": solved - built,
            "wall_s": time.perf_counter() - wall, "cpu_s": time.process_time() - cpu,
            "canonical": float(canonical), "energy": float(np.max(np.abs(np.diff(Ev)))),
            "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("nodes", type=int)
    parser.add_argument("--tol", type=float, default=1e-10)
    parser.add_argument("--q-end", type=float, default=None,
                        help="q(18) (default: end_position(), the march done here)")
    parser.add_argument("--start", default=None,
                        help="an .npz with the start's t, q, p (default: the exact motion)")
    args = parser.parse_args()
    q_end = end_position() if args.q_end is None else args.q_end
    print(json.dumps(solve(args.nodes, args.tol, q_end, args.start)))


if __name__ == "__main__":
    main()
