"""T.D. Lee's original discretisation (docs/theory.md section 3), run in compiled chunks
like the march.

For ``H = p.A p/2 + V(q, t)`` with a constant matrix ``A``, the left-point discrete Lagrangian
``L_d = tau_k [v_k.A^{-1} v_k/2 - V(q_k, t_k)]``, ``v_k = (q_{k+1} - q_k)/tau_k``. Each step
solves the discrete Euler-Lagrange equation ``dS_D/dq_k = 0`` and the energy equation
``dS_D/dt_k = 0``, both taken from the two-interval action by automatic differentiation, for
``(v_k, tau_k)``. Order 1; it has no real step once a step overshoots a turning point.

The first step is special: from ``(q_0, p_0)`` it solves ``p_0 = -d(tau_0 L_0)/dq_0`` for
``v_0`` on the given ``tau_0``, so a march starts from two nodes. The scheme is implicit
(``fast_newton``); each step is accepted only if finite, ``tau > 0`` and its own unscaled
residuals are under ``tol``, exactly like a march step.
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from ...cache import cached
from ...discrete.lee_left import LeeLeftPointEquations
from ...physics.hamiltonian import HamiltonianSystem, quadratic_kinetic_matrix
from ...solution import Solution, Status
from ..driver import Advance, Nodes, Outcome, describe_phase_space, drive, message
from ..marching.acceptance import start_scales
from ..marching.step_newton import NEWTON_OPTIONS
from .chunks import CHUNK, Columns, load, solution_of
from .integrator import Integrator


def _layout(n: int) -> tuple[Columns, Columns]:
    """A chunk's state: the last two nodes (in the order of ``LeeLeftPointEquations``'s ``w``, which
    appends ``theta``); its output row: the new node, its residuals and their scales."""
    state = Columns(t_prev=1, t_mid=1, q_prev=n, q_mid=n)
    row = Columns(t=1, z=2 * n, euler_lagrange=1, energy=1, q_scale=1, energy_scale=1)
    return state, row


def _chunk(system: HamiltonianSystem, functions: LeeLeftPointEquations, chunk: int, compiler,
           cache_dir):
    """``chunk`` Newton steps per call: ``(state, theta) -> (states, rows)``."""
    def build():
        n = system.n
        state_layout, row = _layout(n)
        state = ca.SX.sym("state", 2 + 2 * n)
        theta_symbol = ca.SX.sym("theta", system.theta.numel())
        w = ca.vertcat(state, theta_symbol)
        newton = ca.rootfinder("lee_left_newton", "fast_newton", functions.residual,
                               dict(NEWTON_OPTIONS))
        x = newton(functions.predict(w), w)
        v, tau = x[:n], x[n]
        now = state_layout.split(state)
        t_mid, q_mid = now["t_mid"], now["q_mid"]
        q_next = q_mid + tau * v
        residual = functions.residual(x, w)
        energy = functions.node_energy(v, q_mid, t_mid, theta_symbol)
        out = row.pack(t=t_mid + tau, z=ca.vertcat(q_next, functions.momentum(v, theta_symbol)),
                       euler_lagrange=ca.norm_inf(residual[:n]), energy=residual[n],
                       q_scale=ca.norm_inf(q_mid), energy_scale=ca.fabs(energy))
        one = ca.Function("lee_left_step", [state, theta_symbol],
                          [state_layout.pack(t_prev=t_mid, t_mid=t_mid + tau, q_prev=q_mid,
                                             q_mid=q_next), out])
        return load(one.mapaccum("lee_left_chunk", chunk), compiler, cache_dir)
    return cached(system, ("lee_left", chunk, compiler, str(cache_dir)), build)


class _LeeLeftSteps:
    """Stepper (``driver.py``) of Lee's scheme in compiled chunks, from the last two nodes.

    A step is accepted if its row is finite, ``tau > 0``, the Euler-Lagrange residual is under
    ``tol max(|q|_inf, Z)`` and the energy residual under ``tol max(|E|, E_s)``, ``(Z, E_s)``
    the run's scales from its start (``marching/acceptance.py``, `start_scales`: no floor of
    1 in the units of the state); the first step that is not ends the call with the status
    that says why. ``values`` carries each accepted step's two residuals."""

    describe = staticmethod(describe_phase_space)

    def __init__(self, function, chunk: int, theta, n: int, tol: float,
                 scales: tuple[float, float]):
        self.function, self.chunk, self.n, self.tol = function, chunk, n, tol
        self.z_scale, self.H_scale = scales
        self.thetas = np.tile(np.asarray(theta, float)[:, None], (1, chunk))
        self.state, self.row = _layout(n)

    def advance(self, nodes: Nodes, budget: int) -> Advance:
        n, last = self.n, nodes.count - 1
        state = self.state.join(t_prev=nodes.t[last - 1], t_mid=nodes.t[last],
                                q_prev=nodes.z[last - 1, :n], q_mid=nodes.z[last, :n])
        _, rows = self.function(state, self.thetas)
        rows = np.asarray(rows).T[:min(self.chunk, budget)]
        row = self.row.unpack(rows)
        t_mid = np.concatenate([[nodes.t[last]], row["t"][:-1]])
        el, en = row["euler_lagrange"], row["energy"]
        with np.errstate(invalid="ignore"):
            good = (np.all(np.isfinite(rows), axis=1) & (row["t"] > t_mid)
                    & (el <= self.tol * np.maximum(self.z_scale, row["q_scale"]))
                    & (np.abs(en) <= self.tol * np.maximum(self.H_scale, row["energy_scale"])))
        bad = np.flatnonzero(~good)
        kept = int(bad[0]) if bad.size else rows.shape[0]
        status, detail = self._why(rows, row, t_mid, int(bad[0])) if bad.size else \
            (Status.SUCCESS, "")
        return Advance(row["t"][:kept], row["z"][:kept], status, detail,
                       {"euler_lagrange": el[:kept], "energy": en[:kept]})

    @staticmethod
    def _why(rows, row, t_mid, i: int) -> tuple[Status, str]:
        """The status and detail of the rejected step ``i``."""
        if not np.all(np.isfinite(rows[i])):
            return Status.NON_FINITE, ""
        if row["t"][i] <= t_mid[i]:
            return Status.NO_ADMISSIBLE_STEP, (
                f"Newton from the previous step found tau = {row['t'][i] - t_mid[i]:.6g}")
        return Status.NEWTON_FAILED, (f"Euler-Lagrange residual {row['euler_lagrange'][i]:.3e}, "
                                      f"energy residual {row['energy'][i]:.3e}")


class _Record:
    """Monitor (``driver.py``, rule 5) that keeps the named ``values`` of every kept node."""

    def __init__(self, *keys: str):
        self.kept = {key: [] for key in keys}

    def watch(self, nodes: Nodes, first: int, advance: Advance):
        for key, parts in self.kept.items():
            parts.append(advance.values[key])

    def array(self, key: str, before=()) -> np.ndarray:
        return np.concatenate([np.asarray(before, float), *self.kept[key]])


def _first_step(functions: LeeLeftPointEquations, q0, p0, tau0: float, t0: float, theta):
    """The two start nodes ``(t, z)`` from ``(q0, p0)`` and the first step's residual."""
    start = np.concatenate([[t0, tau0], q0, p0, theta])
    v0 = np.asarray(functions.first_velocity(start)).ravel()
    q1 = q0 + tau0 * v0
    p1 = np.asarray(functions.momentum(v0, theta)).ravel()
    residual = float(np.max(np.abs(np.asarray(functions.first_residual(v0, start)))))
    z = np.array([np.concatenate([q0, p0]), np.concatenate([q1, p1])])
    return np.array([t0, t0 + tau0]), z, residual


def lee_left_march(system: HamiltonianSystem, q0, p0, *, tau0: float, t_end: float, t0: float,
                   theta, tol: float = 1e-10, max_steps: int = 10_000_000, compiler=None,
                   cache_dir=None, time_limit: float | None = None) -> Solution:
    """March T.D. Lee's original left-point scheme until the first node at or past ``t_end``."""
    started = time.perf_counter()
    n = system.n
    functions = cached(system, "lee_left", lambda: LeeLeftPointEquations(system))
    chunk = CHUNK
    function, compile_s = _chunk(system, functions, chunk, compiler, cache_dir)
    built = time.perf_counter()
    t, z, first_residual = _first_step(functions, q0, p0, tau0, t0, theta)
    record = _Record("euler_lagrange", "energy")
    if np.all(np.isfinite(z)):
        scales = start_scales(system, q0, p0, t0, tau0, theta, tol)
        outcome = drive(_LeeLeftSteps(function, chunk, theta, n, tol, scales), Nodes(t, z),
                        t_end=t_end, max_steps=max_steps, time_limit=time_limit,
                        monitors=[record])
    else:  # the first step is not a driven step: the run ends before the driver starts
        outcome = Outcome(t, z, Status.NON_FINITE,
                          message(Status.NON_FINITE, steps=1, t_end=t_end, t=t[-1],
                                  state=describe_phase_space(z[-1])))
    return solution_of(outcome.t, outcome.z, n, outcome.status, outcome.message, "lee_left",
                       {"build_s": built - started, "solve_s": time.perf_counter() - built,
                        "compile_s": compile_s},
                       energy_residual=record.array("energy"),
                       canonical_residual=record.array("euler_lagrange", [first_residual]),
                       stats={"path": "vm" if compiler is None else "compiled"})


def _lee_left(system, config, value, *, compiler, cache_dir, max_steps, time_limit=None):
    return lee_left_march(system, config.q0, config.p0, tau0=value, t_end=config.t_end,
                          t0=config.t0, theta=system.parameter_vector(config.params),
                          max_steps=max_steps, compiler=compiler, cache_dir=cache_dir,
                          time_limit=time_limit)


def _needs_quadratic_kinetic(system) -> str | None:
    A = quadratic_kinetic_matrix(system)
    return A if isinstance(A, str) else None


# Why it stops on every oscillation, measured (harmonic, pendulum, Morse: each at five tau0):
# the step equations fix tau_k through the change of speed over the force at q_k, and both
# vanish together at the bottom of a well and at a turning point.
LIMITATION = ("its step equations fix each step by the change of speed over the force at the "
              "node; where the force vanishes (the bottom of a well, which every oscillation "
              "passes) or the speed does (a turning point) no positive step remains near the "
              "previous one, so on a bound orbit it stops within the first swing at any tau0 "
              "(a property of the scheme, docs/theory.md section 3, not of the knob)")

LEE_LEFT = Integrator("lee_left", "T.D. Lee's original left-point scheme with the node-time "
                      "variation", order=1, symplectic=True, energy_conserving=True, knob="tau0",
                      run=_lee_left, applies=_needs_quadratic_kinetic, limitation=LIMITATION)
