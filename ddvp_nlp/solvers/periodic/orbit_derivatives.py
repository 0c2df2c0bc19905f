"""Derivatives of a periodic orbit's discrete solution in its energy and the system's
parameters (issue 47): ``solve_periodic(..., derivatives=("energy", "params"))``.

The orbit ``x`` (node times and states, the unfoldings) solves the closed grid's rows
``F(x, E, theta) = 0`` (``closed_grid.py``); the implicit-function theorem on them
(``grid/implicit_derivatives.py``) gives ``dx/dE`` and ``dx/dtheta`` from one factorisation of
``F_x`` at
the orbit and one sparse solve per input column. The energy enters only the rows
``H(Q_k, P_k) - E`` (``F_E = -1`` there), the parameters every interval's rows
(``PeriodicAssembly.parameter_jacobian``). The period ``T = t_N - t_0`` is two components of
``x``: ``dT/dv = dt_N/dv - dt_0/dv`` is the derivative of the *discrete* period, every step
length's derivative included; it converges to the exact period's at the scheme's order.

``Solution.derivatives`` then holds::

    "period": {"energy": float, "params": (m,)}       (the names asked)
    "nodes":  {"energy": (N+1, 2n+1), "params": (N+1, 2n+1, m)}   rows (t, q, p) of node k
    "checks": {name: directional finite difference of the discrete solve and its verdict}
    "error_estimate", "nodes_error_estimate", "ill_conditioned", "nodes_ill_conditioned"
    "derivatives_cpu_s", "derivatives_wall_s" (factorisation and solves), "cpu_s", "wall_s" (all)

The grid's nodes are fixed quantities of a solve on ``N`` intervals (their count does not
jump, unlike a march's), so their derivatives are offered. A solve that found no orbit gets a
``grid.implicit_derivatives.Refused`` in their place.
"""

from __future__ import annotations

import time

import numpy as np

from ...errors import InputError
from ...solution import Solution, Status
from ..grid.implicit_derivatives import (
    Linearisation,
    Refused,
    check_names,
    checked,
    resolver,
    step_scales,
)
from ..grid.motion_size import energy_traded, orbit_sizes
from .closed_grid import Closure, PeriodicAssembly, closed_targets, integral_gradients

# The inputs a periodic orbit differentiates in, in the order of the derivative's columns.
PERIODIC_DERIVATIVES = ("energy", "params")


def check_derivatives(system, derivatives) -> tuple[str, ...]:
    """``derivatives=`` of `solve_periodic` read (``implicit_derivatives.check_names``);
    ``"params"`` of a system without parameters is refused by name."""
    names = check_names(derivatives, PERIODIC_DERIVATIVES, "solve_periodic")
    if "params" in names and not getattr(system, "params", None):
        raise InputError(f"derivatives: 'params' asked, but system "
                         f"{getattr(system, 'name', system)!r} has no parameters")
    return names


def orbit_derivatives(request, solution: Solution, integrals, names) -> dict:
    """The derivatives ``names`` of the orbit ``solution`` of ``request`` (module docstring);
    a `Refused` when the solve found no orbit that holds the discrete equations."""
    if solution.status not in (Status.SUCCESS, Status.INACCURATE):
        return Refused(f"the periodic solve failed (status {solution.status.code!r}): "
                       f"{solution.message}")
    wall, cpu = time.perf_counter(), time.process_time()
    system, orbit = request.system, solution.orbit
    N = solution.t.size - 1
    assembly = PeriodicAssembly(system, request.scheme, N, tuple(integrals))
    x = assembly.layout.pack(solution.t, solution.q, solution.p)
    x[assembly.layout.nodes * assembly.layout.m:] = [orbit.unfolding,
                                                      *orbit.integral_unfoldings]
    closure = orbit_closure(request, solution, integrals)
    linear = Linearisation(assembly, x, closure, "sparse")
    columns = {name: input_columns(assembly, x, closure, name) for name in names}
    solved = {name: linear.forward(columns[name]) for name in names}
    dx = {name: solved[name][0] for name in names}
    times = assembly.layout.time_index()
    m = assembly.layout.m

    def project(v):
        return v[times[-1]] - v[times[0]]
    result = {"period": {}, "nodes": {}, "checks": {}}
    for name in names:
        period = dx[name][times[-1]] - dx[name][times[0]]
        nodes = dx[name][:(N + 1) * m].reshape(N + 1, m, -1)
        result["period"][name] = float(period[0]) if name == "energy" else period
        result["nodes"][name] = nodes[:, :, 0] if name == "energy" else nodes
    # the derivatives themselves (factorisation and forward solves), before their checks
    result["derivatives_cpu_s"] = time.process_time() - cpu
    result["derivatives_wall_s"] = time.perf_counter() - wall
    fallback = float(np.max(np.abs(x)))
    # the orbit solve's own targets (orbit.py): each row's round-off, read off the rows
    z = np.hstack([solution.q, solution.p])
    target = closed_targets(assembly, x, closure,
                            orbit_sizes(system, request.theta, solution.t, z))

    def resolve_of(name):
        return resolver(assembly, x, _data_at(closure, name), target, tau_floor=0.0,
                        linear="sparse")
    # the energy by what the orbit trades in a radian of its period (|E| moves with a
    # constant added to H), a parameter by its value
    traded = energy_traded(solution.t, z, float(solution.t[-1] - solution.t[0]) / (2 * np.pi))
    scales = {"energy": step_scales([traded], abs(closure.energy)),
              "params": step_scales(closure.theta, fallback)}
    result.update(checked(linear, dx, {name: solved[name][1] for name in names}, resolve_of,
                          scales, project,
                          {"energy": [closure.energy], "params": closure.theta}))
    result["cpu_s"] = time.process_time() - cpu
    result["wall_s"] = time.perf_counter() - wall
    return result


def orbit_closure(request, solution: Solution, integrals) -> Closure:
    """The orbit's `Closure`, with the integrals' phase conditions referred to the orbit's own
    node 0 (their rows vanish there; the symmetries they fix are exact symmetries of the
    discrete rows, which the period does not see)."""
    system, data = request.system, request.data
    n = system.n
    z0 = np.concatenate([solution.q[0], solution.p[0]])
    generators = np.zeros((len(integrals), 2 * n))
    if integrals:
        gradients = np.asarray(integral_gradients(system, tuple(integrals))(
            z0[:n], z0[n:], request.theta))[:, 1:].T
        generators = np.hstack([gradients[:, n:], -gradients[:, :n]])
    shift = np.zeros(2 * n)
    shift[:n] = 2 * np.pi * np.asarray(solution.orbit.winding, float)
    return Closure(data.energy, data.index, data.value, np.asarray(request.theta, float),
                   z0, generators, shift)


def input_columns(assembly: PeriodicAssembly, x, closure: Closure, name: str) -> np.ndarray:
    """``F_v`` of one input: ``-1`` on every interval's energy row for ``"energy"``, the
    parameter Jacobian for ``"params"``."""
    if name == "params":
        return assembly.parameter_jacobian(x, closure).toarray()
    layout = assembly.layout
    column = np.zeros((layout.size, 1))
    rows = assembly.header + np.arange(layout.intervals) * layout.m + 2 * layout.n
    column[rows, 0] = -1.0
    return column


def _data_at(closure: Closure, name: str):
    """``delta -> Closure`` with the input ``name`` moved by ``delta``."""
    def data(delta):
        if name == "energy":
            return Closure(closure.energy + float(delta[0]), closure.section_index,
                           closure.section_value, closure.theta, closure.reference,
                           closure.generators, closure.shift)
        return Closure(closure.energy, closure.section_index, closure.section_value,
                       closure.theta + delta, closure.reference, closure.generators,
                       closure.shift)
    return data
