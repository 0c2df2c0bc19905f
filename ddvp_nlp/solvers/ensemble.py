"""Many initial states marched together: one compiled call per chunk for all orbits.

``march_ensemble`` runs ``M`` marches of the same system, scheme and options in lock step. Each
round, every orbit whose march would run a compiled chunk (``MarchStepper.wants_chunk``) gets its
chunk from one call of the chunk mapped over the orbits (``FastChunk(orbits=M)``); an orbit on
its careful path (step 0 of the energy rules, the window after a chunk step failed its check)
takes its careful step alone. Everything else is each orbit's own, exactly as in :func:`march`:
its nodes, step lengths, acceptance, monitors (solvability, accuracy check), status and message.
An orbit that ends (``t_end``, a failed step, the accuracy check, ``max_steps``) leaves the
round; the others go on. Each orbit's nodes are those ``march`` gives from the same start (the
chunk's arithmetic is the same per orbit).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..cache import cached
from ..discrete.scheme import Scheme
from ..errors import InputError
from ..solution import Solution, Status, bound_reached
from .accuracy import Tolerance
from .chunk import FastChunk
from .compiler import find_compiler
from .driver import Nodes, Outcome, accept, message
from .march import (
    _accuracy_monitor,
    _build,
    _check_options,
    _check_start,
    _monitors,
    _Parts,
    _solution,
    _start,
)
from .stepper import CompiledStepper, MarchStepper
from .steps import step_functions


@dataclass
class _Orbit:
    """One march of the ensemble: its parts, nodes, monitors, and how it ended."""

    parts: _Parts
    stepper: MarchStepper
    nodes: Nodes
    monitors: list
    solvability: object
    checker: object
    status: Status | None = None
    detail: str = ""

    @property
    def running(self) -> bool:
        return self.status is None


def march_ensemble(system, q0s, p0s, *, tau0: float, t_end: float, t0: float = 0.0,
                   scheme="vddvp", params=None, tol: float = 1e-10,
                   max_steps: int = 10_000_000, tau_min=None, tau_max=None,
                   max_step_ratio: float | None = 10.0, chunk: int = 1024,
                   compiler: str | None = "auto", cache_dir=None, rtol: float = 1e-2,
                   atol: float = 1e-2, energy_tol: float = 0.1, global_tol=None,
                   accept_inaccurate: bool = False,
                   check_accuracy: bool = True) -> list[Solution]:
    """March each ``(q0s[i], p0s[i])`` (arrays of shape ``(M, n)``) as :func:`march` would,
    all ``M`` at once; the arguments after them are :func:`march`'s.

    Returns one :class:`Solution` per orbit, in order, each with its own status: a failing
    orbit ends alone. ``timing["solve_s"]`` is the whole ensemble's stepping time."""
    scheme = Scheme.coerce(scheme)
    q0s, p0s = np.atleast_2d(np.asarray(q0s, float)), np.atleast_2d(np.asarray(p0s, float))
    if q0s.shape != p0s.shape or q0s.shape[0] == 0:
        raise InputError(f"q0s and p0s must be (M, n) arrays of the same shape, got "
                         f"{q0s.shape} and {p0s.shape}")
    options = _check_options(scheme, t0=t0, t_end=t_end, tau0=tau0, tol=tol,
                             max_steps=max_steps, tau_min=tau_min, tau_max=tau_max,
                             max_step_ratio=max_step_ratio, chunk=chunk, time_limit=None,
                             energy_guard=None, breakdown="stop")
    tolerance = Tolerance(rtol=rtol, atol=atol, energy_tol=energy_tol, global_tol=global_tol,
                          stop=not accept_inaccurate)
    theta = system.parameter_vector(params)
    compiler = find_compiler(compiler)
    started = time.perf_counter()
    fast = cached(system, ("ensemble", scheme, options.chunk, q0s.shape[0], compiler,
                           str(cache_dir), check_accuracy),
                  lambda: FastChunk(system, scheme, step_functions(system, scheme),
                                    chunk=options.chunk, compiler=compiler, cache_dir=cache_dir,
                                    accuracy=check_accuracy, orbits=q0s.shape[0]))
    orbits = [_orbit(system, scheme, theta, options, tolerance, fast, q0, p0,
                     check_accuracy=check_accuracy, cache_dir=cache_dir)
              for q0, p0 in zip(q0s, p0s, strict=True)]
    built = time.perf_counter()
    while any(orbit.running for orbit in orbits):
        _round(orbits, fast, options)
    solved = time.perf_counter()
    compiled = compiler if fast.path == "compiled" else None
    return [_finish(system, scheme, theta, orbit, compiled, cache_dir,
                    {"build_s": built - started, "solve_s": solved - built,
                     "orbits": len(orbits)}) for orbit in orbits]


def _orbit(system, scheme, theta, options, tolerance, fast, q0, p0, *, check_accuracy,
           cache_dir) -> _Orbit:
    """One orbit's parts, as :func:`march` builds them, its chunk the ensemble's."""
    q0, p0, _ = _check_start(system, q0, p0, None)
    p0, H0 = _start(system, scheme, q0, p0, None, t0=options.t0, tau0=options.tau0,
                    theta=theta)
    parts = _build(system, scheme, theta, options, fast=False, compiler=None,
                   cache_dir=cache_dir, check_accuracy=check_accuracy)
    stepper = MarchStepper(parts.stepper, CompiledStepper(
        fast, theta, options.acceptance, parts.stepper.clock, parts.tally,
        errors=parts.errors))
    parts.fast_chunk = fast
    nodes = Nodes(options.t0, np.concatenate([q0, p0]))
    monitors, solvability = _monitors(parts, scheme, options, H0, nodes, theta)
    checker = None
    if check_accuracy:
        checker = _accuracy_monitor(system, scheme, theta, tolerance, H0, parts.errors)
        monitors.append(checker)
    return _Orbit(parts, stepper, nodes, monitors, solvability, checker)


def _round(orbits: list[_Orbit], fast: FastChunk, options) -> None:
    """One call of the ensemble's chunk for the orbits that run one, then one stepper call
    (that chunk, or a careful step) and the driver's acceptance for every running orbit."""
    running = [orbit for orbit in orbits if orbit.running]
    chunked = [i for i, orbit in enumerate(orbits)
               if orbit.running and orbit.stepper.wants_chunk(orbit.nodes)]
    steps = {}
    if chunked:
        inputs = {i: orbits[i].stepper.compiled.inputs(orbits[i].nodes) for i in chunked}
        filler, parameters = inputs[chunked[0]]
        states = np.array([inputs[i][0] if i in inputs else filler
                           for i in range(len(orbits))])
        results = fast.steps(states, parameters)
        steps = {id(orbits[i]): results[i] for i in chunked}
    for orbit in running:
        nodes = orbit.nodes
        taken = nodes.count - 1
        reached = bound_reached(taken, options.max_steps, 0.0, None)
        if reached:
            orbit.status, orbit.detail = reached
            continue
        advance = orbit.stepper.advance(nodes, options.max_steps - taken,
                                        steps.get(id(orbit)))
        status, detail = accept(nodes, advance, options.t_end, orbit.monitors)
        if status is not Status.SUCCESS:
            orbit.status, orbit.detail = status, detail
        elif nodes.t[nodes.count - 1] >= options.t_end:
            orbit.status = Status.SUCCESS


def _finish(system, scheme, theta, orbit: _Orbit, compiler, cache_dir, timing) -> Solution:
    """The orbit's :class:`Solution`, as :func:`march` writes it."""
    t, z = orbit.nodes.arrays()
    text = message(orbit.status, steps=t.size - 1, t_end=orbit.stepper.careful.clock.t_end,
                   t=float(t[-1]), state=orbit.stepper.describe(z[-1]), detail=orbit.detail)
    solution = _solution(system, scheme, theta, Outcome(t, z, orbit.status, text), orbit.parts,
                         orbit.solvability, compiler=compiler, cache_dir=cache_dir,
                         timing=timing)
    if orbit.checker is not None:
        solution.local_error = orbit.checker.local_errors(solution.steps)
        solution.stats["accuracy"] = orbit.checker.report(solution.steps)
    return solution
