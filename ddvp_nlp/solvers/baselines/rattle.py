"""RATTLE and SHAKE, the fixed-step methods of constrained mechanics, as compared methods:
their steps (``discrete/constrained_verlet.py``) in compiled chunks on uniform steps that end
on ``t_end``, as the other fixed-step baselines.

The constraint solves stop at ``tol`` in the units of ``g``; by default
``tol = DEFAULT_TOL * c``, ``c = max_i |G_q,i(q_0, t_0)|_2 |q_0|_inf``, the size of the terms
of ``g`` at the start (for ``x^2 + y^2 - L^2`` at a start on the circle, ``2 L^2``), so the
tolerance follows the units and the round-off of ``g``. A step is kept while it is finite and
its solves reached ``tol``; otherwise the run ends there with ``RESIDUAL_TOO_LARGE``.
Both methods refuse a system without constraints (a named error, ``applies``).
"""

from __future__ import annotations

import math
import time

import casadi as ca
import numpy as np

from ...cache import cached
from ...discrete.constrained_verlet import METHODS, constrained_separable, rattle_step
from ...errors import InputError
from ...solution import Solution, Status
from ..driver import Advance, Nodes, describe_phase_space, drive
from .chunks import CHUNK, Columns, load, solution_of
from .integrator import Integrator

DEFAULT_TOL = 1e-14  # relative to the size of g's terms at the start (module docstring)


def _layout(n: int) -> tuple[Columns, Columns]:
    """The chunk's state (step index, ``z``) and row (``t``, ``z``, residual, Newton count)."""
    return Columns(k=1, z=2 * n), Columns(t=1, z=2 * n, residual=1, newton=1)


def constraint_size(system, q0, t0: float, theta) -> float:
    """``max_i |G_q,i(q0, t0)|_2 |q0|_inf``: the size of the terms of ``g`` at the start."""
    G = ca.vec(system.G)
    Gq = ca.Function("G_q", [system.q, system.t, system.theta], [ca.jacobian(G, system.q)])
    rows = np.asarray(Gq(np.asarray(q0, float), float(t0), np.asarray(theta, float)))
    return float(np.max(np.linalg.norm(rows, axis=1)) * np.max(np.abs(q0)))


def rattle_chunk(system, method: str, chunk: int, compiler, cache_dir):
    """``chunk`` steps per call: ``(state, constants) -> (states, rows)``, the constants
    ``(theta, t0, h, tol)``; step ``k`` starts at ``t0 + k h``."""
    step = rattle_step(system, method)

    def build():
        state_layout, row = _layout(system.n)
        state = ca.SX.sym("state", 1 + 2 * system.n)
        constants = ca.SX.sym("constants", system.theta.numel() + 3)
        theta, first, h, tol = (constants[:-3], constants[-3], constants[-2],
                                constants[-1])
        parts = state_layout.split(state)
        k, z = parts["k"], parts["z"]
        z_next, residual, newton = step(z, first + k * h, h, theta, tol)
        one = ca.Function(f"{method}_chunk_step", [state, constants],
                          [state_layout.pack(k=k + 1, z=z_next),
                           row.pack(t=first + (k + 1) * h, z=z_next, residual=residual,
                                    newton=newton)])
        return load(one.mapaccum(f"{method}_chunk", chunk), compiler, cache_dir)
    return cached(system, (f"{method}_chunk", chunk, compiler, str(cache_dir)), build)


class RattleSteps:
    """Stepper (``driver.py``) of a compiled RATTLE or SHAKE chunk on ``t0 + k h``; its step
    ``total`` lands on ``t_end``. A step is kept while finite and solved to ``tol``."""

    describe = staticmethod(describe_phase_space)

    def __init__(self, function, chunk: int, constants, total: int, t_end: float, n: int,
                 tol: float):
        self.function, self.chunk, self.constants = function, chunk, constants
        self.total, self.t_end, self.tol = total, t_end, tol
        self.state, self.row = _layout(n)
        self.newton = []  # Newton iterations of every kept step

    def advance(self, nodes: Nodes, budget: int) -> Advance:
        k = nodes.count - 1
        _, rows = self.function(self.state.join(k=k, z=nodes.z[k]), self.constants)
        rows = np.asarray(rows).T[:min(self.chunk, budget, self.total - k)]
        columns = self.row.unpack(rows)
        finite = np.all(np.isfinite(rows), axis=1)
        good = finite & (columns["residual"] <= self.tol)
        kept = int(np.argmin(good)) if not good.all() else rows.shape[0]
        t = columns["t"][:kept].copy()
        if k + kept == self.total and kept:
            t[-1] = self.t_end  # k h may differ from t_end by round-off
        self.newton.append(columns["newton"][:kept])
        if kept == rows.shape[0]:
            return Advance(t, columns["z"][:kept])
        if not finite[kept]:
            return Advance(t, columns["z"][:kept], Status.NON_FINITE)
        return Advance(t, columns["z"][:kept], Status.RESIDUAL_TOO_LARGE,
                       f"the constraint solve stopped at {columns['residual'][kept]:.3g} > "
                       f"tol = {self.tol:.3g}")


def rattle_run(system, q0, p0, *, tau: float, t_end: float, t0: float = 0.0, theta=(),
               method: str = "rattle", tol: float | None = None, compiler=None,
               cache_dir=None, time_limit: float | None = None,
               max_steps: int = 10_000_000) -> Solution:
    """March ``method`` (``"rattle"`` or ``"shake"``) from a consistent ``(q0, p0)`` on uniform
    steps ending on ``t_end`` (the step ``(t_end - t0) / ceil((t_end - t0) / tau)``); ``tol``
    (units of ``g``) the constraint solves' stop, by default ``DEFAULT_TOL`` times the size of
    ``g``'s terms (module docstring). ``stats["newton"]``: iterations of every step."""
    constrained_separable(system, method)
    q0, p0 = np.asarray(q0, float).ravel(), np.asarray(p0, float).ravel()
    theta = np.asarray(theta, float).ravel()
    for name, value in (("q0", q0), ("p0", p0), ("theta", theta)):
        size = system.theta.numel() if name == "theta" else system.n
        if value.size != size or not np.all(np.isfinite(value)):
            raise InputError(f"{name} must be {size} finite numbers, got {value.tolist()}")
    if not (np.isfinite(tau) and tau > 0):
        raise InputError(f"tau must be positive and finite, got {tau!r}")
    if not (np.isfinite(t0) and np.isfinite(t_end) and t_end > t0):
        raise InputError(f"t_end must be finite and after t0 = {t0!r}, got {t_end!r}")
    if tol is None:
        tol = DEFAULT_TOL * (constraint_size(system, q0, t0, theta) or 1.0)
    if not (np.isfinite(tol) and tol > 0):
        raise InputError(f"tol must be positive and finite, got {tol!r}")
    total = max(1, math.ceil((t_end - t0) / tau - 1e-9))
    if total > max_steps:
        raise InputError(f"tau = {tau!r} needs {total} steps to reach t_end, more than "
                         f"max_steps = {max_steps}")
    started = time.perf_counter()
    function, compile_s = rattle_chunk(system, method, CHUNK, compiler, cache_dir)
    built = time.perf_counter()
    constants = np.tile(np.concatenate([theta, [t0, (t_end - t0) / total, tol]])[:, None],
                        (1, CHUNK))
    stepper = RattleSteps(function, CHUNK, constants, total, t_end, system.n, tol)
    outcome = drive(stepper, Nodes(t0, np.concatenate([q0, p0])), t_end=t_end,
                    max_steps=total, time_limit=time_limit)
    newton = np.concatenate(stepper.newton) if stepper.newton else np.zeros(0)
    return solution_of(outcome.t, outcome.z, system.n, outcome.status, outcome.message,
                       method, {"build_s": built - started,
                                "solve_s": time.perf_counter() - built,
                                "compile_s": compile_s},
                       stats={"path": "vm" if compiler is None else "compiled", "tol": tol,
                              "newton": newton})


def _run_of(method: str):
    """``Integrator.run`` of ``method``, knob ``tau``, the default tolerance."""
    def run(system, config, value, *, compiler, cache_dir, max_steps, time_limit=None):
        return rattle_run(system, config.q0, config.p0, tau=value, t_end=config.t_end,
                          t0=config.t0, theta=system.parameter_vector(config.params),
                          method=method, compiler=compiler, cache_dir=cache_dir,
                          time_limit=time_limit, max_steps=max_steps)
    return run


def not_constrained(system) -> str | None:
    """Why RATTLE or SHAKE does not apply (no constraints, or ``H`` not separable)."""
    try:
        constrained_separable(system, METHODS[0])
    except InputError as error:
        return str(error).replace("rattle needs", "needs")
    return None


RATTLE = Integrator("rattle", "RATTLE: Stormer-Verlet with the position and momentum "
                    "constraints solved by Newton (constrained systems, separable H)", order=2,
                    symplectic=True, energy_conserving=False, knob="tau", run=_run_of("rattle"),
                    applies=not_constrained, constrained_only=True, constrained=True)
SHAKE = Integrator("shake", "SHAKE: Stormer-Verlet with the position constraint solved by "
                   "its classical iteration (constrained systems, separable H); positions of "
                   "order 2, node momenta not projected (order 1)", order=1, symplectic=False,
                   energy_conserving=False, knob="tau", run=_run_of("shake"),
                   applies=not_constrained, constrained_only=True, constrained=True)
