"""The figure of docs/gradients.md: a march's derivative error against its first step, for the
derivative of the discrete solution, the frozen-step derivative and the exact flow's.

    python scripts/pages/gradients_page.py [--out docs/gradients] [--quick]

The pendulum ``H = p^2/2 + w^2 (1 - cos q)`` at ``w = 1.3`` from ``(q0, p0) = (1, 0)`` marched
by ``vddvp`` to ``t = 8`` at each ``tau0``; the derivatives of ``(q, p)`` at ``t = 2, 5, 7.5`` in
``(q0, p0, w)``, three ways:

- the march's own (``march(..., derivatives=...)``: the discrete solution's, step lengths
  included);
- the frozen-step derivative (the same chain with every ``dtau_k = 0``: what integrators with
  step control report);
- the exact flow's (the variational equations integrated by DOP853 at rtol 1e-12, written
  here by hand for the pendulum).

Left: each against central differences of the discrete march itself (the function an
optimiser of the discrete model sees; step 1e-6 of each input). Right: each against the exact
flow's. The largest relative error over the times, components and inputs.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import casadi as ca
import numpy as np
from scipy.integrate import solve_ivp

from ddvp_nlp import HamiltonianSystem, Output, march
from ddvp_nlp.io import machine, new_figure, save, styled

# internal, named explicitly: the frozen-step derivative is what the figure shows is not it
from ddvp_nlp.solvers.marching.derivatives import march_derivatives

ROOT = Path(__file__).resolve().parents[2]
W, Q0, P0, T_END = 1.3, 1.0, 0.0, 8.0
TIMES = np.array([2.0, 5.0, 7.5])
NAMES = ("q0", "p0", "params")
FD_STEP = 1e-6


def pendulum():
    def H(q, p, t, w):
        return p[0] ** 2 / 2 + w ** 2 * (1 - ca.cos(q[0]))
    return HamiltonianSystem(H, 1, {"w": W}, name="pendulum_w")


def stacked(derivatives: dict) -> np.ndarray:
    """``(M, 2, 3)``: columns q0, p0, w."""
    return np.concatenate([derivatives[name] for name in NAMES], axis=2)


def exact_flow() -> np.ndarray:
    """``d(q, p)(TIMES) / d(q0, p0, w)`` of the exact flow: the pendulum's variational
    equations, ``S' = A S + b``, ``A = [[0, 1], [-w^2 cos q, 0]]``, ``b = (0, -2 w sin q)`` in the
    ``w`` column."""
    def field(t, y):
        q, p = y[0], y[1]
        S = y[2:].reshape(2, 3)
        A = np.array([[0.0, 1.0], [-W ** 2 * np.cos(q), 0.0]])
        dS = A @ S
        dS[1, 2] += -2 * W * np.sin(q)
        return np.concatenate([[p, -W ** 2 * np.sin(q)], dS.ravel()])
    start = np.concatenate([[Q0, P0], np.eye(2, 3).ravel()])
    done = solve_ivp(field, (0.0, T_END), start, method="DOP853", rtol=1e-12, atol=1e-14,
                     t_eval=TIMES)
    return done.y[2:].T.reshape(TIMES.size, 2, 3)


def errors(system, tau0: float, exact: np.ndarray) -> dict:
    """Relative errors of the three derivatives against the discrete map's differences and
    against the exact flow's."""
    def run(q0=Q0, p0=P0, w=W, derivatives=None):
        return march(system, [q0], [p0], (0.0, T_END), tau0=tau0, params={"w": w},
                     output=Output(t_eval=TIMES), derivatives=derivatives)
    solution = run(derivatives=NAMES)
    discrete = stacked(solution.derivatives)
    frozen = stacked(march_derivatives(system, solution.scheme, np.array([W]), solution.t,
                                       np.hstack([solution.q, solution.p]), solution.t_eval,
                                       NAMES, frozen_steps=True))
    columns = []
    for key, value in (("q0", Q0), ("p0", P0), ("w", W)):
        h = FD_STEP * max(abs(value), abs(Q0))
        plus, minus = run(**{key: value + h}).z_eval, run(**{key: value - h}).z_eval
        columns.append((plus - minus) / (2 * h))
    differenced = np.stack(columns, axis=2)

    def relative(a, b):
        return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))
    return {"discrete": (relative(discrete, differenced), relative(discrete, exact)),
            "frozen": (relative(frozen, differenced), relative(frozen, exact)),
            "exact": (relative(exact, differenced), 0.0)}


def draw(steps, table, path: Path) -> None:
    styles = {"discrete": ("o-", "tab:blue", "derivative of the discrete solution (this library)",
                           dict(ms=8, mfc="none", mew=1.4)),
              "frozen": ("s--", "tab:red", "frozen steps ($d\\tau_k = 0$)", dict(ms=4)),
              "exact": ("^:", "tab:green", "exact flow's sensitivity", dict(ms=5))}
    with styled():
        fig = new_figure(10, 4.2)
        left, right = fig.subplots(1, 2, sharex=True)
        for name, (marker, colour, label, look) in styles.items():
            left.loglog(steps, [row[name][0] for row in table], marker, color=colour,
                        label=label, **look)
            if name != "exact":
                right.loglog(steps, [row[name][1] for row in table], marker, color=colour,
                             label=label, **look)
        guide = np.array([steps[0], steps[-1]])
        anchor = table[-1]["frozen"][1]
        right.loglog(guide, anchor * (guide / steps[-1]) ** 2, "-", color="0.6", lw=0.8,
                     label="slope 2")
        left.set_title("against finite differences of the discrete march")
        right.set_title("against the exact flow's sensitivity (both converge)")
        for ax in (left, right):
            ax.set_xlabel("first step $\\tau_0$")
            ax.grid(True, which="major", lw=0.4, alpha=0.5)
        left.set_ylabel("relative error of $\\partial(q, p)(t_i) / \\partial(q_0, p_0, w)$")
        left.legend(loc="center right", fontsize="small")
        right.legend(loc="lower right", fontsize="small")
        save(fig, path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "docs" / "gradients"))
    parser.add_argument("--quick", action="store_true", help="three steps (not for docs/)")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    system = pendulum()
    steps = np.geomspace(0.01, 0.3, 3 if args.quick else 8)
    exact = exact_flow()
    table = [errors(system, float(tau0), exact) for tau0 in steps]
    print("| tau0 | discrete vs FD | frozen vs FD | exact vs FD | discrete vs exact | "
          "frozen vs exact |")
    print("|---|---|---|---|---|---|")
    for tau0, row in zip(steps, table, strict=True):
        print(f"| {tau0:.4g} | {row['discrete'][0]:.2e} | {row['frozen'][0]:.2e} | "
              f"{row['exact'][0]:.2e} | {row['discrete'][1]:.2e} | {row['frozen'][1]:.2e} |")
    draw(steps, table, out / "derivative_error.png")
    print(f"wrote {out / 'derivative_error.png'}")
    print(machine())


if __name__ == "__main__":
    main()
