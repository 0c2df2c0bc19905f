"""A march backwards in time (``t_span = (t0, t_end)`` with ``t_end < t0``), by time reversal.

For ``H(q, p, t)`` the map ``s = -t``, ``Q = q``, ``P = -p`` takes Hamilton's equations into
Hamilton's equations of ``K(Q, P, s) = H(Q, -P, -s)``: ``dQ/ds = -H_p = K_P`` and ``dP/ds =
dp/dt = -H_q = -K_Q``. So a backward march of ``H`` from ``t0`` to ``t_end`` is the forward march
of ``K`` from ``-t0`` to ``-t_end`` from ``(q0, -p0)``, mapped back node by node: every equation
the scheme solves, the accuracy check against the exact flow (of ``K``, which is ``H``'s flow
run backwards) and the step bounds are the forward march's own. A Lagrangian ``L(q, v, t)``
becomes ``L(Q, -V, -s)`` likewise, and ``v0`` becomes ``-v0``. Holonomic constraints
``g(q, t)`` become ``g(Q, -s)``: the same positions on the same surfaces, so the reversed
march keeps ``g(q_k, t_k) = 0`` in the original time; its hidden constraint is the original's
with the sign of ``p`` and ``t`` changed, and the record's multipliers are the reversed
march's, step by step in the order of the returned nodes. The returned `Solution` is in
``t``: decreasing times, negative steps ``tau = diff(t)``, ``p`` and the states at ``t_eval``
and events in the original signs, the verdict's times (``t_drift``, ...) negated, and its
dense output on ``H``'s own vector field.
"""

from __future__ import annotations

import copy
import re
import warnings
from dataclasses import replace

import casadi as ca
import numpy as np

from ...cache import cached
from ...errors import InputError
from ...physics.hamiltonian import HamiltonianSystem
from ...physics.lagrangian import LagrangianSystem
from ...validation import check_real, check_times
from ..dense import Event, attach
from ..options import Output, Tolerance

__all__ = ["is_backward", "march_backward", "run_time_reversed"]


def is_backward(t_span) -> bool:
    """Whether ``t_span`` is a pair of real numbers with ``t_end < t0`` (anything else is
    left to the forward march's checks)."""
    try:
        t0, t_end = t_span
        return bool(float(t_end) < float(t0))
    except (TypeError, ValueError):
        return False


def time_reversed(system: HamiltonianSystem) -> HamiltonianSystem:
    """``K(q, p, t) = H(q, -p, -t)`` (or ``L(q, -v, -t)``), built once per system by
    substitution into its expression (the user's function is not called again)."""
    def build():
        lagrangian = isinstance(system, LagrangianSystem)
        expression, second = (system.L, system.v) if lagrangian else (system.H, system.p)
        old = ca.vertcat(system.q, second, system.t, system.theta)

        def reversed_function(q, second_new, t, **params):
            theta = ca.vertcat(*[params[name] for name in system.params]) if system.params \
                else ca.SX(0, 1)
            return ca.substitute(expression, old, ca.vertcat(q, -second_new, -t, theta))
        kind = LagrangianSystem if lagrangian else HamiltonianSystem
        return kind(reversed_function, system.n, dict(system.params), name=system.name,
                    constraints=_reversed_constraints(system))
    return cached(system, "time_reversed", build)


def _reversed_constraints(system):
    """``g(q, -t)`` of a system with holonomic constraints (``None`` without): the reversed
    march keeps the same positions on the same constraint surfaces, met at ``s = -t``."""
    if not getattr(system, "n_constraints", 0):
        return None
    old = ca.vertcat(system.q, system.t, system.theta)

    def reversed_g(q, t, **params):
        theta = ca.vertcat(*[params[name] for name in system.params]) if system.params \
            else ca.SX(0, 1)
        return ca.substitute(system.G, old, ca.vertcat(q, -t, theta))
    return reversed_g


def march_backward(march, system, q0, p0, t_span, *, v0, output, **options):
    """``march`` (the forward one, passed in) of the time-reversed system, mapped back."""
    t0, t_end = check_real("t0", t_span[0]), check_real("t_end", t_span[1])
    output = output if output is not None else Output()
    if not isinstance(output, Output):
        raise InputError(f"output must be an Output, got {type(output).__name__}")
    reversed_output = Output(progress=output.progress, checkpoint=output.checkpoint,
                             checkpoint_interval=output.checkpoint_interval, stop=output.stop,
                             t_eval=_reversed_times(output.t_eval, t0, t_end),
                             events=[_reversed_event(event) for event in output.events] or None)
    accuracy = options.get("accuracy")
    if isinstance(accuracy, Tolerance) and accuracy.exact is not None:
        options["accuracy"] = replace(accuracy, exact=_reversed_exact(accuracy.exact, system.n))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        solution = march(time_reversed(system), q0, _flipped(p0), (-t0, -t_end), v0=_flipped(v0),
                         output=reversed_output, **options)
    for warning in caught:  # the monitors' warnings name times of the reversed march
        warnings.warn_explicit(_TIME.sub(_negated, str(warning.message)), warning.category,
                               warning.filename, warning.lineno)
    return _forward(solution, system, t_end)


def run_time_reversed(run, system, config, *args, **options):
    """A forward-only method (``run(system, config, *args, **options) -> Solution``, ``config``
    read by attribute: ``q0``, ``p0``, ``t0``, ``t_end``, ...) run backwards in time,
    ``config.t_end < config.t0``: ``run`` of the time-reversed system from ``(q0, -p0)`` at
    ``-t0`` to ``-t_end``, its `Solution` mapped back as the march's is. A compared method
    told to run backwards thus marches the same steps as forwards on ``H(q, -p, -t)``; before
    this it returned ``success`` with no step taken."""
    t0, t_end = float(config.t0), float(config.t_end)
    flipped = copy.copy(config)
    flipped.t0, flipped.t_end = -t0, -t_end
    flipped.p0 = _flipped(config.p0)
    if hasattr(config, "v0"):
        flipped.v0 = _flipped(config.v0)
    solution = run(time_reversed(system), flipped, *args, **options)
    return _forward(solution, system, t_end)


def _flipped(momentum):
    """``p0`` or ``v0`` of the time-reversed system: its sign changed (``None`` stays)."""
    return None if momentum is None else -np.asarray(momentum, dtype=float)


def _reversed_times(t_eval, t0: float, t_end: float):
    """``-t_eval`` for the reversed march: a backward march reports at times sorted in
    decreasing order (as scipy's ``solve_ivp``), inside ``[t_end, t0]``."""
    return None if t_eval is None else -check_times(t_eval, (t0, t_end))


def _reversed_exact(exact, n: int):
    """The exact solution ``exact(t) -> z`` (rows) as the reversed march reads it, in ``s``
    and ``(Q, P) = (q, -p)``."""
    def reversed_exact(s):
        z = np.array(exact(-np.asarray(s, dtype=float)), dtype=float)
        z[..., n:] *= -1
        return z
    return reversed_exact


def _reversed_event(event: Event):
    """``g(t, q, p)`` as the reversed march sees it, ``g(-s, Q, -P)``; the sign changes are
    the same in the order of integration, so ``direction`` and ``terminal`` carry over."""
    g = event.g

    def reversed_g(s, q, p):
        return g(-s, q, -np.asarray(p))
    reversed_g.direction, reversed_g.terminal = event.direction, event.terminal
    reversed_g.vectorized = event.vectorized
    return reversed_g


# "t = 12.5", "t_end = 50", "t_drift = 3": the times a march's messages name
_TIME = re.compile(r"(\bt(?:_end|_drift)? = )(-?\d+(?:\.\d*)?(?:e[+-]?\d+)?)")


def _negated(match: re.Match) -> str:
    number = match.group(2)
    negated = number[1:] if number.startswith("-") else \
        number if float(number) == 0 else "-" + number
    return match.group(1) + negated


def _forward(solution, system, t_end: float):
    """The reversed march's `Solution` in the original time and momenta."""
    n = system.n
    solution.t = -solution.t
    solution.p = -solution.p
    solution.message = _TIME.sub(_negated, solution.message)
    if solution.z_eval is not None:
        solution.t_eval = -solution.t_eval
        solution.z_eval = np.hstack([solution.z_eval[:, :n], -solution.z_eval[:, n:]])
    if solution.t_events is not None:
        solution.t_events = [-np.asarray(t) for t in solution.t_events]
        solution.z_events = [np.hstack([z[:, :n], -z[:, n:]]) if np.size(z) else z
                             for z in solution.z_events]
    if solution.verdict is not None:
        solution.verdict = solution.verdict.time_reversed()
    if solution.march is not None:  # a compared method keeps no march record
        solution.march.backward = True
    theta = solution.march.theta if solution.march is not None else system.parameter_vector()
    theta = np.asarray(theta, dtype=float)
    return attach(solution, system, theta, t_end)
