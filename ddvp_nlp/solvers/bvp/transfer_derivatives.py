"""Derivatives of a transfer at a prescribed energy (issue 47):
``transfer_derivatives(sol)`` for ``sol = solve_bvp(system, q_start, q_end, AtEnergy(E), ...)``.

The transfer ``x`` (every node's ``(t, q, p)``, the end time ``t_{N-1}`` among them) solves the
rows ``F(x, v) = 0`` of ``at_energy.py``: the canonical equations, the interior energy
equations, the pins of ``t_0``, ``q_start``, ``q_end``, and in place of ``t_{N-1}``'s pin the
last interval's energy ``H(Q_{N-2}, P_{N-2}) - E``. The implicit-function theorem
(``grid/implicit_derivatives.py``) gives ``dx/dv`` for ``v = (q_start, q_end, E, theta)`` from
one band factorisation of ``F_x`` at the transfer and one solve per input column: the ends'
columns are ``-I`` on their pins, the energy's ``-1`` on that last row (written as it is:
``F(E + 1) - F(E)`` is 0 where ``|E| >= 2^53``), the parameters' the assembly's
``parameter_jacobian`` (its last block included). The transfer time ``T = t_{N-1} - t_0`` is a
component of ``x``, so ``dT/dv`` is the derivative of the discrete transfer time, every step
length's included.

Returns::

    "transfer_time": {name: (k,)}   dT / d input   (k = n for an end, 1 for "energy", m)
    "p_start", "p_end": {name: (n, k)}
    "nodes": {name: (N, 2n+1, k)}   rows (t, q, p) of node k
    "checks": {name: directional finite difference of the discrete solve, its verdict}
    "error_estimate", "nodes_error_estimate", "ill_conditioned", "nodes_ill_conditioned"

Reverse mode, ``transfer_gradient(sol, cotangent)``: for a scalar ``L = c . (T, p_start, p_end,
nodes)`` the gradient in every input from one transposed solve on the same factorisation,
``dL/dv = -(F_x^-T c) . F_v`` (``grid/implicit_derivatives.reverse``).
"""

from __future__ import annotations

import numpy as np

from ...discrete.scheme import Scheme
from ...errors import InputError
from ...solution import Solution, Status
from ..grid.implicit_derivatives import (
    GridGradient,
    Linearisation,
    check_grid_cotangent,
    check_names,
    checked,
    resolver,
    reverse,
    step_scales,
)
from ..grid.linear import band_kernel
from ..grid.motion_size import energy_traded
from ..options import Compilation, coerce
from .at_energy import newton_targets
from .end_derivatives import end_scales, input_columns
from .interleaved import Ends, GridAssembly, prescribed_energy_block
from .phases import BOUNDS_ALLOWED

__all__ = ["TRANSFER_DERIVATIVES", "transfer_derivatives", "transfer_gradient"]

TRANSFER_DERIVATIVES = ("q_start", "q_end", "energy", "params")


def transfer_derivatives(sol: Solution, derivatives=TRANSFER_DERIVATIVES, *,
                         compilation=None) -> dict:
    """The derivatives ``derivatives`` (names from `TRANSFER_DERIVATIVES`) of the verified
    transfer ``sol`` at its prescribed energy (module docstring)."""
    system = _transfer_system(sol)
    names = check_names(derivatives, TRANSFER_DERIVATIVES, "transfer_derivatives")
    if "params" in names and not system.params:
        raise InputError(f"derivatives: 'params' asked, but system {system.name!r} has no "
                         f"parameters")
    compilation = coerce(compilation, Compilation, "compilation")
    n, N, m = system.n, sol.t.size, 2 * system.n + 1
    theta = np.asarray(sol.vector_field.theta, float)
    grid, x, ends, linear = _linearised(sol, compilation)
    kernel = band_kernel(compilation)
    result = {"transfer_time": {}, "p_start": {}, "p_end": {}, "nodes": {}, "checks": {}}
    dx, corrections = {}, {}
    for name in names:
        dx[name], corrections[name] = linear.forward(_columns(grid, x, ends, name, n, N * m))
        nodes = dx[name].reshape(N, m, -1)
        result["nodes"][name] = nodes
        result["transfer_time"][name] = nodes[-1, 0] - nodes[0, 0]
        result["p_start"][name] = nodes[0, n + 1:].copy()
        result["p_end"][name] = nodes[-1, n + 1:].copy()
    watched = np.r_[(N - 1) * m, n + 1:m, (N - 1) * m + n + 1:N * m]

    def project(v):
        return v[watched]
    fallback = float(np.max(np.abs(x)))
    scales = end_scales(sol.q, theta, fallback)
    # the energy by that the motion trades over the transfer (|E| moves with a constant in H)
    scales["energy"] = step_scales([energy_traded(sol.t, np.hstack([sol.q, sol.p]),
                                                  sol.t[-1] - sol.t[0])], abs(ends.energy))
    # the check's re-solves to the verification's allowance of each row's own round-off
    # (at_energy.newton_targets, row by row: 64 round-offs of max(1, |x|, |E|) stalled at 1e-12
    # when q_start moved, and in lengths of 1e-8 meant no target at all)
    target = BOUNDS_ALLOWED * newton_targets(system, grid, x, ends)

    def resolve_of(name):
        return resolver(grid, x, _data_at(ends, name), target, tau_floor=-np.inf,
                        kernel=kernel)
    result.update(checked(linear, dx, corrections, resolve_of, scales, project,
                          {"q_start": ends.q_start, "q_end": ends.q_end,
                           "energy": [ends.energy], "params": theta}))
    grid.release()
    return result


def transfer_gradient(sol: Solution, cotangent, *, compilation=None) -> GridGradient:
    """``dL/d(q_start, q_end, energy, params)`` of ``L = sum c . (transfer_time, p_start,
    p_end, nodes)`` of the verified transfer ``sol`` (``cotangent``: any of
    ``"transfer_time"`` (a number), ``"p_start"``, ``"p_end"`` ``(n,)``, ``"nodes"``
    ``(N, 2n+1)``, rows ``(t, q, p)``): one transposed solve (module docstring); a
    `GridGradient` with its error estimate and ``ill_conditioned`` flag."""
    system = _transfer_system(sol)
    n, N, m = system.n, sol.t.size, 2 * system.n + 1
    c = check_grid_cotangent(cotangent, {"transfer_time": (), "p_start": (n,), "p_end": (n,),
                                         "nodes": (N, m)}, "a transfer")
    compilation = coerce(compilation, Compilation, "compilation")
    grid, x, ends, linear = _linearised(sol, compilation)
    weights = np.zeros((N, m))
    weights += c.get("nodes", 0.0)
    weights[0, n + 1:] += c.get("p_start", 0.0)
    weights[-1, n + 1:] += c.get("p_end", 0.0)
    T = float(c.get("transfer_time", 0.0))
    weights[-1, 0] += T
    weights[0, 0] -= T
    names = [name for name in TRANSFER_DERIVATIVES if name != "params" or system.params]
    found = reverse(linear, weights.ravel(),
                    {name: _columns(grid, x, ends, name, n, N * m) for name in names})
    grid.release()
    return found


def _transfer_system(sol):
    """The system of the verified transfer ``sol``; an ``InputError`` for anything else."""
    if not isinstance(sol, Solution) or sol.transfer is None:
        raise InputError(f"sol must be a transfer at an energy (solve_bvp(..., AtEnergy(E))), "
                         f"got {type(sol).__name__}")
    if sol.status not in (Status.SUCCESS, Status.INACCURATE):
        raise InputError(f"sol is not a verified transfer (status {sol.status.code!r}): no "
                         f"derivative to take")
    if sol.system is None or sol.vector_field is None:
        raise InputError("sol has no system (an unpickled Solution): solve again")
    return sol.system


def _linearised(sol, compilation):
    """The transfer's rows rebuilt at its nodes and ``F_x`` factored: ``(grid, x, ends,
    linear)``."""
    system, N = sol.system, sol.t.size
    theta = np.asarray(sol.vector_field.theta, float)
    scheme = Scheme.coerce(sol.scheme)
    grid = GridAssembly(system, scheme, N, compilation,
                        last=prescribed_energy_block(system, scheme))
    x = grid.layout.pack(sol.t, sol.q, sol.p)
    ends = Ends(sol.q[0].copy(), sol.q[-1].copy(), np.array([sol.t[0], sol.t[-1]]), theta,
                (sol.t[-1] - sol.t[0]) / (N - 1), energy=float(sol.transfer.energy))
    return grid, x, ends, Linearisation(grid, x, ends, "auto", band_kernel(compilation))


def _columns(grid, x, ends: Ends, name: str, n: int, size: int) -> np.ndarray:
    """``F_v`` of one input (module docstring)."""
    if name != "energy":
        return input_columns(grid, x, ends, name, n, size)
    # -1 on the prescribed energy's row (the last block's energy row), exactly: F(E + 1) -
    # F(E) was 0 where |E| >= 2^53 (a swing in lengths of 1e6 and time units of 1e-3)
    column = np.zeros((size, 1))
    column[n + 1 + (grid.layout.nodes - 2) * grid.layout.m + 2 * n, 0] = -1.0
    return column


def _data_at(ends: Ends, name: str):
    """``delta -> Ends`` with the input ``name`` moved by ``delta``."""
    def moved(delta):
        delta = np.asarray(delta, float)
        q_start, q_end, theta, energy = ends.q_start, ends.q_end, ends.theta, ends.energy
        if name == "q_start":
            q_start = q_start + delta
        elif name == "q_end":
            q_end = q_end + delta
        elif name == "params":
            theta = theta + delta
        else:
            energy = energy + float(delta[0])
        return Ends(q_start, q_end, ends.times, theta, ends.energy_scale, energy=energy)
    return moved
