"""The fixed-step schemes users would pick instead, run the same way as the march: compiled
chunks.

- Stormer-Verlet for separable ``H = T(p) + V(q, t)``, order 2, symplectic, in both forms
  (``discrete/explicit.py``): ``stormer_verlet`` kick-drift-kick, ``leapfrog`` drift-kick-drift.
- Classical Runge-Kutta (RK4) on ``z' = (H_p, -H_q)``, order 4, neither symplectic nor
  energy-conserving.
- The averaged vector field method (``avf.py``), order 2, symmetric, energy-conserving for
  autonomous ``H``, not symplectic: an implicit step map, listed in `IMPLICIT_STEPS`.

They march on uniform steps that end on ``t_end``; each chunk's steps are accepted while finite
and, for an implicit step map, while its own residual is under the tolerance.
"""

from __future__ import annotations

import math
import time
from types import MappingProxyType

import casadi as ca
import numpy as np

from ...cache import cached
from ...discrete.avf import GAUSS_NODES, avf_residual
from ...discrete.explicit import FIXED_STEPS
from ...errors import InputError
from ...physics.hamiltonian import HamiltonianSystem, not_separable
from ...solution import Solution, Status
from ..driver import Advance, Nodes, describe_phase_space, drive
from ..marching.acceptance import start_scales
from .avf_stepper import avf_step
from .chunks import CHUNK, Columns, load, solution_of
from .integrator import Integrator


def _fixed_layout(n: int) -> tuple[Columns, Columns]:
    """A fixed-step chunk's state (step index, ``z``) and output row (``t``, ``z``, the step's
    own residual ``|r|_inf``, zero for an explicit map)."""
    return Columns(k=1, z=2 * n), Columns(t=1, z=2 * n, residual=1)


def step_map(system: HamiltonianSystem, method: str) -> ca.Function:
    """``(z, t, tau, theta) -> (z_next, residual)`` of a fixed-step method: an explicit map of
    ``discrete/explicit.py`` (residual 0), or an implicit one registered in
    `IMPLICIT_STEPS` (its equation's residual at the returned ``z_next``)."""
    if method in IMPLICIT_STEPS:
        return IMPLICIT_STEPS[method][0](system)
    explicit = FIXED_STEPS[method](system)
    z, t, tau = ca.SX.sym("z", 2 * system.n), ca.SX.sym("t"), ca.SX.sym("tau")
    return ca.Function(f"{method}_with_residual", [z, t, tau, system.theta],
                       [explicit(z, t, tau, system.theta), ca.SX(0)])


# Implicit fixed-step methods: name -> (the map as in `step_map`, the equation as in
# `step_equation`), each ``(system) -> Function``.
IMPLICIT_STEPS = MappingProxyType({"avf": (avf_step, avf_residual)})


def step_equation(system: HamiltonianSystem, method: str) -> ca.Function:
    """``(z_next, z, t, tau, theta) -> r``: the equation a fixed-step method's nodes satisfy,
    ``z_next - Phi(z)`` for an explicit map ``Phi``."""
    if method in IMPLICIT_STEPS:
        return IMPLICIT_STEPS[method][1](system)
    explicit = FIXED_STEPS[method](system)
    z, z_next = ca.SX.sym("z", 2 * system.n), ca.SX.sym("z_next", 2 * system.n)
    t, tau = ca.SX.sym("t"), ca.SX.sym("tau")
    return ca.Function(f"{method}_equation", [z_next, z, t, tau, system.theta],
                       [z_next - explicit(z, t, tau, system.theta)])


def step_residuals(system: HamiltonianSystem, method: str, t, z, theta) -> np.ndarray:
    """``|r_k|_inf`` of every step of a returned fixed-step trajectory (``t`` ``(N+1,)``, ``z``
    ``(N+1, 2n)``): the method's own equation recomputed on its nodes."""
    if t.size < 2:
        return np.zeros(0)
    equation = step_equation(system, method).map(t.size - 1)
    r = np.asarray(equation(z[1:].T, z[:-1].T, t[:-1], np.diff(t),
                            np.tile(np.asarray(theta, float)[:, None], (1, t.size - 1))))
    return np.max(np.abs(r), axis=0)


def fixed_chunk(system: HamiltonianSystem, method: str, chunk: int, compiler, cache_dir):
    """``chunk`` steps of ``method`` per call: ``(state, constants) -> (states, rows)``, the
    constants ``(theta, t0, h)``, so that step ``k`` starts at ``t0 + k h``."""
    def build():
        step = step_map(system, method)
        state_layout, row = _fixed_layout(system.n)
        state = ca.SX.sym("state", 1 + 2 * system.n)
        constants = ca.SX.sym("constants", system.theta.numel() + 2)
        theta, first, h = constants[:-2], constants[-2], constants[-1]
        parts = state_layout.split(state)
        k, z = parts["k"], parts["z"]
        z_next, residual = step(z, first + k * h, h, theta)
        one = ca.Function(f"{method}_step", [state, constants],
                          [state_layout.pack(k=k + 1, z=z_next),
                           row.pack(t=first + (k + 1) * h, z=z_next, residual=residual)])
        return load(one.mapaccum(f"{method}_chunk", chunk), compiler, cache_dir)
    return cached(system, (method, chunk, compiler, str(cache_dir)), build)


class _FixedSteps:
    """Stepper (``driver.py``) of a compiled fixed-step chunk on the grid ``t0 + k h``, whose
    step ``total`` lands on ``t_end`` exactly. A step is kept while its row is finite and its
    residual at most ``tol max(|z_k+1|_inf, Z)``, ``Z`` the run's scale from its start
    (``marching/acceptance.py``, `start_scales`: no floor of 1 in the units of the state)."""

    describe = staticmethod(describe_phase_space)

    def __init__(self, function, chunk: int, constants, total: int, t_end: float, n: int,
                 z_scale: float):
        self.function, self.chunk, self.constants = function, chunk, constants
        self.total, self.t_end, self.z_scale = total, t_end, z_scale
        self.state, self.row = _fixed_layout(n)

    def advance(self, nodes: Nodes, budget: int) -> Advance:
        k = nodes.count - 1
        _, rows = self.function(self.state.join(k=k, z=nodes.z[k]), self.constants)
        rows = np.asarray(rows).T[:min(self.chunk, budget)]
        return _kept(self.row, rows, self.total - k, self.t_end, self.z_scale)


def _kept(row: Columns, rows: np.ndarray, left: int, t_end: float, z_scale: float) -> Advance:
    """The leading rows that are finite and whose residual is small against ``max(|z_k+1|,
    z_scale)`` (``left``: steps to ``t_end``, whose last node is put on ``t_end`` exactly)."""
    finite = np.all(np.isfinite(rows), axis=1)
    columns = row.unpack(rows)
    scale = np.maximum(z_scale, np.max(np.abs(np.where(np.isfinite(columns["z"]), columns["z"],
                                                        0)), axis=1))
    solved = columns["residual"] <= RESIDUAL_TOL * scale
    good = finite & solved
    kept = int(np.argmin(good)) if not good.all() else rows.shape[0]
    t = columns["t"][:kept].copy()
    if kept == left:
        t[-1] = t_end  # k h may differ from t_end by round-off
    if kept == rows.shape[0]:
        return Advance(t, columns["z"][:kept])
    status = Status.NON_FINITE if not finite[kept] else Status.RESIDUAL_TOO_LARGE
    detail = ("" if not finite[kept] else
              f"residual {columns['residual'][kept]:.3g} > {RESIDUAL_TOL:g} max(|z|, Z), "
              f"Z = {z_scale:.3g}")
    return Advance(t, columns["z"][:kept], status, detail)


# An implicit step is accepted when its equation holds to this, relative to max(|z|, Z) (Z from
# the start: ``marching/acceptance.py``).
RESIDUAL_TOL = 1e-10


def fixed_step_run(system: HamiltonianSystem, method: str, q0, p0, *, tau: float, t_end: float,
                   t0: float, theta, compiler, cache_dir=None,
                   time_limit: float | None = None) -> Solution:
    """March ``method`` (``"stormer_verlet"`` or ``"rk4"``) on uniform steps that end on
    ``t_end`` (the step is ``(t_end - t0)/ceil((t_end - t0)/tau)``); ``time_limit`` (seconds)
    is checked between chunks."""
    started = time.perf_counter()
    total = max(1, math.ceil((t_end - t0) / tau - 1e-9))
    chunk = CHUNK
    function, compile_s = fixed_chunk(system, method, chunk, compiler, cache_dir)
    built = time.perf_counter()
    constants = np.tile(np.concatenate([theta, [t0, (t_end - t0) / total]])[:, None], (1, chunk))
    z_scale, _ = start_scales(system, q0, p0, t0, (t_end - t0) / total, theta)
    stepper = _FixedSteps(function, chunk, constants, total, t_end, system.n, z_scale)
    outcome = drive(stepper, Nodes(t0, np.concatenate([q0, p0])), t_end=t_end, max_steps=total,
                    time_limit=time_limit)
    return solution_of(outcome.t, outcome.z, system.n, outcome.status, outcome.message, method,
                       {"build_s": built - started, "solve_s": time.perf_counter() - built,
                        "compile_s": compile_s},
                       stats={"path": "vm" if compiler is None else "compiled"})


def fixed_step_run_of(name: str):
    """``Integrator.run`` of the fixed-step method ``name``, knob ``tau``."""
    def run(system, config, value, *, compiler, cache_dir, max_steps, time_limit=None):
        steps = math.ceil((config.t_end - config.t0) / value - 1e-9)
        if steps > max_steps:
            raise InputError(f"tau = {value!r} needs {steps} steps to reach t_end, more than "
                             f"max_steps = {max_steps}")
        return fixed_step_run(system, name, config.q0, config.p0, tau=value,
                              t_end=config.t_end, t0=config.t0,
                              theta=system.parameter_vector(config.params),
                              compiler=compiler, cache_dir=cache_dir, time_limit=time_limit)
    return run


STORMER_VERLET = Integrator("stormer_verlet", "Stormer-Verlet kick-drift-kick (velocity Verlet; "
                            "separable H)", order=2, symplectic=True, energy_conserving=False,
                            knob="tau", run=fixed_step_run_of("stormer_verlet"),
                            applies=not_separable)
LEAPFROG = Integrator("leapfrog", "Stormer-Verlet drift-kick-drift (position Verlet, SUNDIALS' "
                      "leapfrog; separable H)", order=2, symplectic=True,
                      energy_conserving=False, knob="tau", run=fixed_step_run_of("leapfrog"),
                      applies=not_separable)
RK4 = Integrator("rk4", "classical Runge-Kutta", order=4, symplectic=False,
                 energy_conserving=False, knob="tau", run=fixed_step_run_of("rk4"))
AVF = Integrator("avf", f"averaged vector field (Quispel-McLaren), {GAUSS_NODES}-point "
                 "Gauss-Legendre segment integral", order=2, symplectic=False,
                 energy_conserving=True, knob="tau", run=fixed_step_run_of("avf"))
