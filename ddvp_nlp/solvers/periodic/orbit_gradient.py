"""Reverse mode of a periodic orbit's derivatives (issue 47): ``gradient(orbit, cotangent)`` for
a `solve_periodic` result, with or without ``derivatives=``.

For a scalar ``L = c . x`` of the orbit's period and nodes (``cotangent``: any of ``"period"``
(a number) and ``"nodes"`` ``(N+1, 2n+1)``, rows ``(t, q, p)``), the implicit-function theorem
on the closed grid's rows (``orbit_derivatives.py``) gives the gradient in the energy and the
parameters from one transposed solve on the same factorisation: ``dL/dv = -(F_x^-T c) . F_v``
(``grid/implicit_derivatives.reverse``). The problem is rebuilt from the solution (energy,
section, scheme, winding) and from what a periodic `Solution` does not keep: the ``system``,
its ``params`` and the first ``integrals`` the orbit was solved with, given again as to
`solve_periodic`. The orbit must hold the rebuilt rows (largest ``|F|`` within ``HOLDS`` of
the nodes' size), else the arguments are not the solve's and the gradient is refused by name.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ...discrete.scheme import Scheme
from ...errors import InputError
from ...solution import Solution, Status
from ..grid.implicit_derivatives import GridGradient, Linearisation, check_grid_cotangent, reverse
from ..grid.motion_size import orbit_sizes
from .closed_grid import PeriodicAssembly
from .orbit import check_integrals, parse_section
from .orbit_derivatives import PERIODIC_DERIVATIVES, input_columns, orbit_closure

__all__ = ["HOLDS", "orbit_gradient"]

# The largest row of the rebuilt equations at the orbit, relative to how far the row moves when
# the nodes move by the orbit's size, that says they are the solve's (the solve verifies them
# to 1e-10 of that size; a parameter moved by 1e-6 leaves rows of its size).
HOLDS = 1e-8


def orbit_gradient(sol: Solution, cotangent, *, system, params=None,
                   integrals=()) -> GridGradient:
    """``dL/d(energy, params)`` of ``L = c_T T + sum c . nodes`` of a periodic orbit found by
    `solve_periodic` (module docstring): ``{"energy": float, "params": (m,)}`` (``params``
    only for a system with parameters), a `GridGradient` with its error estimate and
    ``ill_conditioned`` flag. ``system``, ``params``, ``integrals``: those of the solve."""
    if not isinstance(sol, Solution) or sol.orbit is None:
        raise InputError(f"sol must be a solve_periodic Solution, got {type(sol).__name__}")
    if sol.status not in (Status.SUCCESS, Status.INACCURATE):
        raise InputError(f"sol is not a periodic orbit (status {sol.status.code!r}): no "
                         f"derivative to take")
    orbit = sol.orbit
    if not hasattr(system, "parameter_vector") or system.n != sol.q.shape[1]:
        raise InputError(f"system must be the HamiltonianSystem the orbit was solved for "
                         f"({sol.q.shape[1]} degrees of freedom), got {system!r:.80}")
    theta = np.asarray(system.parameter_vector(params), float)
    integrals = check_integrals(integrals)
    if len(integrals) != len(orbit.integral_unfoldings):
        raise InputError(f"integrals: the orbit was solved with {len(orbit.integral_unfoldings)}"
                         f" first integrals, got {len(integrals)}: give the same ones")
    n, N = system.n, sol.t.size - 1
    c = check_grid_cotangent(cotangent, {"period": (), "nodes": (N + 1, 2 * n + 1)},
                             "solve_periodic")
    index, value, _ = parse_section(orbit.section, n)
    request = SimpleNamespace(system=system, theta=theta,
                              data=SimpleNamespace(energy=orbit.energy, index=index, value=value))
    assembly = PeriodicAssembly(system, Scheme.coerce(sol.scheme), N, tuple(integrals))
    layout = assembly.layout
    x = layout.pack(sol.t, sol.q, sol.p)
    x[layout.nodes * layout.m:] = [orbit.unfolding, *orbit.integral_unfoldings]
    closure = orbit_closure(request, sol, integrals)
    rows = np.asarray(assembly.evaluate(x, closure, jacobian=False)[0], float)
    linear = Linearisation(assembly, x, closure, "sparse")
    # each row against how far it moves when the nodes move by the orbit's sizes (its period
    # over N for a time), in its own units: max(1, |x|) passed any orbit in small units
    sizes = np.empty((layout.nodes, layout.m))
    sizes[:, 0] = (sol.t[-1] - sol.t[0]) / N
    sizes[:, 1:] = orbit_sizes(system, theta, sol.t, np.hstack([sol.q, sol.p]))
    scale = np.zeros(layout.size)
    scale[:sizes.size] = sizes.ravel()
    response = abs(linear.matrix) @ scale
    if not np.all(np.abs(rows) <= HOLDS * response):
        worst = int(np.argmax(np.abs(rows) / np.maximum(response, np.finfo(float).tiny)))
        raise InputError(f"the orbit does not hold the equations of system={system.name!r} at "
                         f"params={params!r} (row {worst}: {rows[worst]:.3g}, against "
                         f"{HOLDS:g} of its response {response[worst]:.3g} to the orbit's "
                         "size): give the system, params and integrals it was solved with")
    weights = np.zeros(layout.size)
    weights[:(N + 1) * layout.m] += np.ravel(c.get("nodes", np.zeros((N + 1, layout.m))))
    times = layout.time_index()
    period = float(c.get("period", 0.0))
    weights[times[-1]] += period
    weights[times[0]] -= period
    names = [name for name in PERIODIC_DERIVATIVES if name != "params" or system.params]
    found = reverse(linear, weights, {name: input_columns(assembly, x, closure, name)
                                      for name in names})
    found["energy"] = float(np.ravel(found["energy"])[0])
    return found
