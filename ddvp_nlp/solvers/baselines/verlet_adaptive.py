"""Reversible adaptive Stormer-Verlet (``discrete/adaptive_verlet.py``) as a compiled baseline.

The knob is the first step ``tau0`` (the fictitious-time step ``eps``, since ``rho(q_0) = 1``);
the steps follow ``g(q) = 1/rho``: on Kepler ``h ~ tau0 r^{3/2}``. The chunk carries ``(t, z,
rho_{k+1/2})`` from step to step; the last step is cut to end on ``t_end``. Steps are kept while
finite and positive. Order 2, symmetric; not symplectic in ``t`` (the time transformation is
not canonical), no exact energy conservation, but no drift of ``H`` on the orbits tested (a
reversible method on a reversible problem).
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from ...cache import cached
from ...discrete.adaptive_verlet import adaptive_verlet_step, density_parts
from ...physics.hamiltonian import HamiltonianSystem, not_separable
from ...solution import Status
from ..driver import Advance, Nodes, describe_phase_space, drive
from .chunks import CHUNK, Columns, load, solution_of
from .integrator import Integrator

# rho's floor relative to its value at q_0: c = kappa_0 / FLOOR_RATIO.
FLOOR_RATIO = 100.0


def _chunk(system: HamiltonianSystem, chunk: int, compiler, cache_dir):
    """``chunk`` steps per call: ``(state, constants) -> (states, rows)``; a row is the next
    state itself."""
    def build():
        n = system.n
        layout = Columns(t=1, z=2 * n, rho=1)
        state = ca.SX.sym("state", 2 + 2 * n)
        constants = ca.SX.sym("constants", 4 + system.theta.numel())
        eps, t_end, c2, norm = (constants[i] for i in range(4))
        theta = constants[4:]
        now = layout.split(state)
        z_next, t_next, rho_next = adaptive_verlet_step(system)(
            now["z"], now["t"], now["rho"], eps, t_end, theta, c2, norm)
        row = layout.pack(t=t_next, z=z_next, rho=rho_next)
        one = ca.Function("verlet_adaptive_step", [state, constants], [row, row])
        return load(one.mapaccum("verlet_adaptive_chunk", chunk), compiler, cache_dir)
    return cached(system, ("verlet_adaptive", chunk, compiler, str(cache_dir)), build)


class _AdaptiveSteps:
    """Stepper (``driver.py``): a compiled chunk from the newest node and ``rho``; a step is kept
    while finite with ``t`` increasing."""

    describe = staticmethod(describe_phase_space)

    def __init__(self, function, chunk: int, constants, rho_half: float, n: int):
        self.function, self.chunk, self.constants = function, chunk, constants
        self.rho = rho_half
        self.layout = Columns(t=1, z=2 * n, rho=1)

    def advance(self, nodes: Nodes, budget: int) -> Advance:
        k = nodes.count - 1
        state = self.layout.join(t=nodes.t[k], z=nodes.z[k], rho=self.rho)
        _, rows = self.function(state, self.constants)
        rows = np.asarray(rows).T[:min(self.chunk, budget)]
        columns = self.layout.unpack(rows)
        previous = np.concatenate([[nodes.t[k]], columns["t"][:-1]])
        good = np.all(np.isfinite(rows), axis=1) & (columns["t"] > previous) \
            & (columns["rho"] > 0)
        kept = int(np.argmin(good)) if not good.all() else rows.shape[0]
        if kept:
            self.rho = float(columns["rho"][kept - 1])
        status = Status.SUCCESS if kept == rows.shape[0] else Status.NON_FINITE
        detail = "" if status is Status.SUCCESS else "the step density rho left (0, inf)"
        return Advance(columns["t"][:kept].copy(), columns["z"][:kept], status, detail)


def density_constants(system: HamiltonianSystem, q0, t0: float, theta) -> tuple[float, float]:
    """``(c2, norm)`` of ``rho`` (``discrete/adaptive_verlet.py``) for the start ``q0, t0``:
    ``rho(q_0) = 1``; a force without curvature at ``q_0`` gives ``rho = 1`` there."""
    n = system.n
    kappa2, _, _ = density_parts(system)(q0, np.zeros(n), t0, theta, 0.0, 1.0)
    kappa2 = float(kappa2)
    c2 = kappa2 / FLOOR_RATIO ** 2 if kappa2 > 0 else 1.0
    return c2, kappa2 + c2


def adaptive_verlet_run(system: HamiltonianSystem, q0, p0, *, tau0: float, t_end: float,
                        t0: float, theta, compiler, cache_dir=None, max_steps: int,
                        time_limit: float | None = None):
    """March reversible adaptive Stormer-Verlet from ``(q0, p0)`` at ``t0`` to ``t_end``."""
    started = time.perf_counter()
    theta = np.asarray(theta, float)
    c2, norm = density_constants(system, q0, t0, theta)
    _, rho0, G0 = density_parts(system)(q0, p0, t0, theta, c2, norm)
    rho_half = float(rho0) + tau0 / 2 * float(G0)
    chunk = CHUNK
    function, compile_s = _chunk(system, chunk, compiler, cache_dir)
    built = time.perf_counter()
    constants = np.tile(np.concatenate([[tau0, t_end, c2, norm], theta])[:, None], (1, chunk))
    stepper = _AdaptiveSteps(function, chunk, constants, rho_half, system.n)
    outcome = drive(stepper, Nodes(t0, np.concatenate([q0, p0])), t_end=t_end,
                    max_steps=max_steps, time_limit=time_limit)
    return solution_of(outcome.t, outcome.z, system.n, outcome.status, outcome.message,
                       "verlet_adaptive",
                       {"build_s": built - started, "solve_s": time.perf_counter() - built,
                        "compile_s": compile_s},
                       stats={"path": "vm" if compiler is None else "compiled"})


def _run(system, config, value, *, compiler, cache_dir, max_steps, time_limit=None):
    return adaptive_verlet_run(system, np.asarray(config.q0, float),
                               np.asarray(config.p0, float), tau0=value, t_end=config.t_end,
                               t0=config.t0, theta=system.parameter_vector(config.params),
                               compiler=compiler, cache_dir=cache_dir, max_steps=max_steps,
                               time_limit=time_limit)


VERLET_ADAPTIVE = Integrator("verlet_adaptive", "reversible adaptive Stormer-Verlet (Sundman "
                             "g(q) by Hairer-Soderlind step-density control; separable H)",
                             order=2, symplectic=False, energy_conserving=False, knob="tau0",
                             run=_run, applies=not_separable)
