"""Derivatives of a fixed-end problem's discrete solution in its ends and the system's
parameters (issue 47): ``solve_bvp(..., derivatives=("q_start", "q_end", "params"))``.

The solution ``x`` (every node's ``(t, q, p)``) solves the interleaved rows ``F(x, v) = 0``
(``interleaved.py``) of ``v = (q_start, q_end, theta)``; the implicit-function theorem
(``grid/implicit_derivatives.py``) gives ``dx/dv`` from one factorisation of ``F_x`` at the
solution, on
the band the grid's Newton factors, and one band solve per input column. The ends enter only
their pin rows (``q_0 - q_start``, ``q_{N-1} - q_end``: ``F_v = -I`` there), the parameters
every block's rows (``GridAssembly.parameter_jacobian``). The interior node times are
unknowns, so their derivatives (the steps') are included.

``Solution.derivatives`` then holds::

    "p_start": {name: (n, k)}   d p_0 / d input      (k = n for an end, m for "params")
    "p_end":   {name: (n, k)}   d p_{N-1} / d input
    "nodes":   {name: (N, 2n+1, k)}                   rows (t, q, p) of node k
    "checks":  {name: directional finite difference of the discrete solve and its verdict}
    "error_estimate", "nodes_error_estimate", "ill_conditioned", "nodes_ill_conditioned"
    "derivatives_cpu_s", "derivatives_wall_s" (factorisation and solves), "cpu_s", "wall_s" (all)

The discrete action ``S_D(q_start, q_end)`` of the solution has ``dS_D/dq_end = p_end`` and
``dS_D/dq_start = -p_start`` (the discrete Hamilton-Jacobi relations; tested): the momenta are
the action's gradient, and ``d p_end / d q_end`` its Hessian. A solve that found no verified
solution gets a ``grid.implicit_derivatives.Refused`` in their place.
"""

from __future__ import annotations

import time
from dataclasses import replace

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
from ..grid.linear import band_kernel
from .phases import assembly, ends, newton_targets

# The inputs a fixed-end problem differentiates in, in the order of the derivative's columns.
BVP_DERIVATIVES = ("q_start", "q_end", "params")


def check_derivatives(system, derivatives, t_span=None) -> tuple[str, ...]:
    """``derivatives=`` of `solve_bvp` read (``implicit_derivatives.check_names``); ``"params"`` of
    a system without parameters, and a transfer at an energy (its end time an unknown of
    another system), are refused by name."""
    names = check_names(derivatives, BVP_DERIVATIVES, "solve_bvp")
    if "params" in names and not getattr(system, "params", None):
        raise InputError(f"derivatives: 'params' asked, but system "
                         f"{getattr(system, 'name', system)!r} has no parameters")
    if names and t_span is not None and not isinstance(t_span, (tuple, list, np.ndarray)):
        raise InputError(f"derivatives are not supported for a transfer at an energy "
                         f"(t_span={t_span!r}): give a fixed (t0, t_end), or call "
                         f"transfer_derivatives(sol) on the transfer")
    return names


def bvp_derivatives(request, x: np.ndarray, solution: Solution, names) -> dict:
    """The derivatives ``names`` of the fixed-end solution ``x`` of ``request`` (module
    docstring); a `Refused` when the solve found no verified solution."""
    if solution.status is not Status.SUCCESS:
        return Refused(f"the fixed-end solve failed (status {solution.status.code!r}): "
                       f"{solution.message}")
    wall, cpu = time.perf_counter(), time.process_time()
    scheme = request.scheme
    grid, data = assembly(request, scheme), ends(request, scheme)
    n, N, m = request.system.n, request.nodes, 2 * request.system.n + 1
    kernel = band_kernel(request.compilation)
    linear = Linearisation(grid, x, data, request.linear, kernel)
    result = {"p_start": {}, "p_end": {}, "nodes": {}, "checks": {}}
    dx, corrections = {}, {}
    for name in names:
        dx[name], corrections[name] = linear.forward(
            input_columns(grid, x, data, name, n, N * m))
        nodes = dx[name].reshape(N, m, -1)
        result["nodes"][name] = nodes
        result["p_start"][name] = nodes[0, n + 1:].copy()
        result["p_end"][name] = nodes[-1, n + 1:].copy()
    # the derivatives themselves (factorisation and forward solves), before their checks
    result["derivatives_cpu_s"] = time.process_time() - cpu
    result["derivatives_wall_s"] = time.perf_counter() - wall
    ends_rows = np.r_[n + 1:m, (N - 1) * m + n + 1:N * m]

    def project(v):
        return v[ends_rows]
    scales = end_scales(x.reshape(N, m)[:, 1:n + 1], data.theta, float(np.max(np.abs(x))))
    target = newton_targets(request, grid, x, data)

    def resolve_of(name):  # a nearby solve: no step approaches the floor
        return resolver(grid, x, _data_at(data, name), target, tau_floor=-np.inf,
                        linear=request.linear, kernel=kernel)
    values = {"q_start": data.q_start, "q_end": data.q_end, "params": data.theta}
    result.update(checked(linear, dx, corrections, resolve_of, scales, project, values))
    grid.release()
    result["cpu_s"] = time.process_time() - cpu
    result["wall_s"] = time.perf_counter() - wall
    return result


def end_scales(q: np.ndarray, theta: np.ndarray, fallback: float) -> dict:
    """The derivative checks' step scales of the ends and the parameters of a motion with
    positions ``q`` (``(N, n)`` nodes): an end moves by the motion's range in each coordinate
    (offsets of the origin leave it), a parameter by its value (``fallback`` where all are
    0)."""
    q = np.asarray(q, float)
    ranges = step_scales(np.ptp(q, axis=0), float(np.max(np.abs(q), initial=0.0)) or fallback)
    return {"q_start": ranges, "q_end": ranges, "params": step_scales(theta, fallback)}


def input_columns(grid, x, data, name: str, n: int, size: int) -> np.ndarray:
    """``F_v`` of one input: ``-I`` on the pin rows of an end, the parameter Jacobian."""
    if name == "params":
        return grid.parameter_jacobian(x, data).toarray()
    columns = np.zeros((size, n))
    first = 1 if name == "q_start" else size - n
    columns[first + np.arange(n), np.arange(n)] = -1.0
    return columns


def _data_at(data, name: str):
    """``delta -> Ends`` with the input ``name`` moved by ``delta``."""
    field = {"q_start": "q_start", "q_end": "q_end", "params": "theta"}[name]

    def moved(delta):
        return replace(data, **{field: np.asarray(getattr(data, field), float) + delta})
    return moved
