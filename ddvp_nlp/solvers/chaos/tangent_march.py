"""A march carrying tangent vectors: the checked problem, step 0 by the march's careful Newton
and then the compiled chunk (``tangent.py``) one call at a time, kept up to the first node at
or past ``t_end`` or the first step that fails its check (the march would redo that step on
its careful path; here the indicators stop there and the status says so).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ...cache import cached
from ...discrete.scheme import Scheme
from ...errors import InputError
from ...physics.hamiltonian import symplectic_weights
from ...solution import Status
from ..compiler import find_compiler
from ..marching.initial_value import check_problem
from ..marching.step_newton import NewtonSteps
from ..marching.steps import step_functions
from ..options import Compilation, StepControl, coerce
from .tangent import TangentChunk


@dataclass
class TangentMarch:
    """The pieces of a march with tangent vectors: the checked problem, its careful Newton
    (step 0) and the compiled chunk carrying the vectors."""

    problem: object
    newton: NewtonSteps
    chunk: TangentChunk
    weights: np.ndarray  # the tangent norm's (`physics.hamiltonian.symplectic_weights`)

    @classmethod
    def build(cls, system, q0, p0, t_span, *, tau0, scheme, params, steps, compilation,
              vectors: int, observation: str) -> TangentMarch:
        scheme = Scheme.coerce(scheme)
        steps = coerce(steps, StepControl, "steps")
        compilation = coerce(compilation, Compilation, "compilation")
        if not scheme.variable_steps:
            raise InputError(f"chaos indicators need an energy rule (vddvp or lee), got scheme "
                             f"{scheme.rule!r}")
        problem = check_problem(system, scheme, q0, p0, None, t_span, tau0, steps, params)
        if system.time_dependent:
            raise InputError("chaos indicators need an autonomous H (the level map and the "
                             f"synchronous tangent assume it); {system.name!r} depends on t")
        functions = step_functions(system, scheme)
        compiler = find_compiler(compilation.compiler) if compilation.fast else None
        cache_dir = compilation.cache_dir
        chunk = cached(system, ("chaos", scheme, vectors, observation, compilation.chunk,
                                compiler, str(cache_dir)),
                       lambda: TangentChunk(system, scheme, functions, vectors=vectors,
                                            observation=observation, chunk=compilation.chunk,
                                            compiler=compiler, cache_dir=cache_dir))
        newton = NewtonSteps(system, scheme, functions, problem.theta, problem.acceptance)
        weights = symplectic_weights(system, np.concatenate([problem.q0, problem.p0]), problem.t0,
                                  problem.theta)
        return cls(problem, newton, chunk, weights)

    def first_step(self):
        """Step 0 of the march (careful, length ``tau0``): ``(t_1, z_1)`` or a failure
        ``(status, message)``."""
        p = self.problem
        z0 = np.concatenate([p.q0, p.p0])
        result = self.newton.fixed_step(p.t0, p.t0 + p.tau0, z0)
        if result.status is not Status.SUCCESS:
            return None, (result.status, f"step 0 failed: {result.detail}")
        return (result.t_next, z0, result.z_next), None

    def chunks(self, start, X1):
        """The steps after step 0, one chunk at a time: yields ``(columns, count)`` where
        ``count`` steps of ``columns`` (`TangentChunk.run`) were accepted, until the first
        node at or past ``t_end``, a failed step or a limit; finally returns
        ``(status, message)``."""
        p, chunk = self.problem, self.chunk
        t1, z0, z1 = start
        state = chunk.tangent_state(p.t0, t1, z0, z1, 0.0, X1, self.weights)
        parameters = chunk.energy_parameters(p.theta, p.acceptance)
        started, done = time.perf_counter(), 1
        while True:
            columns, states = chunk.run(state, parameters)
            t_next = columns["t_next"]
            ends = np.flatnonzero(t_next >= p.t_end)
            limit = int(ends[0]) + 1 if ends.size else t_next.size
            limit = min(limit, p.steps.max_steps - done)
            bad = np.flatnonzero(~columns["good"][:limit])
            kept = int(bad[0]) if bad.size else limit
            if kept:
                yield columns, kept
            done += kept
            if bad.size:
                return (Status.NEWTON_FAILED,
                        f"step {done} failed its check in the compiled chunk at t = "
                        f"{float(t_next[kept - 1]) if kept else t1:.6g} (the march would redo "
                        "it carefully; the indicators stop there)")
            if ends.size and kept == limit == int(ends[0]) + 1:
                return Status.SUCCESS, f"reached t_end = {p.t_end:.12g} in {done} steps"
            if done >= p.steps.max_steps:
                return Status.MAX_STEPS, f"max_steps = {p.steps.max_steps}"
            if p.steps.time_limit is not None and \
                    time.perf_counter() - started > p.steps.time_limit:
                return Status.TIME_LIMIT, f"time_limit = {p.steps.time_limit} s"
            state = states[kept - 1]


def start_tangent(n: int, tangent0, weights: np.ndarray | None = None) -> np.ndarray:
    """The start's tangent ``dz_0``, of unit length in the weighted norm ``|W dz|``
    (`physics.hamiltonian.symplectic_weights`; ``None``: the plain one): ``tangent0``, default
    all ones in the weighted coordinates."""
    weights = np.ones(2 * n) if weights is None else np.asarray(weights, float)
    if tangent0 is None:
        return (np.full(2 * n, 1.0 / math.sqrt(2 * n)) / weights)[:, None]
    v = np.asarray(tangent0, float).reshape(-1)
    if v.size != 2 * n or not np.all(np.isfinite(v)) or not np.linalg.norm(v) > 0:
        raise InputError(f"tangent0 must be {2 * n} finite numbers, not all zero, got "
                         f"{tangent0!r}")
    return (v / np.linalg.norm(weights * v))[:, None]


