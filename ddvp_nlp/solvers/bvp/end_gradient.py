"""Reverse mode of a fixed-end solution's derivatives (issue 47): ``gradient(bvp, cotangent)``
for a `solve_bvp` result, with or without ``derivatives=``.

For a scalar ``L = c . x`` of the solution's end momenta and nodes (``cotangent``: any of
``"p_start"`` ``(n,)``, ``"p_end"`` ``(n,)``, ``"nodes"`` ``(N, 2n+1)``, rows ``(t, q, p)``),
the implicit-function theorem ``F_x dx/dv = -F_v`` (``end_derivatives.py``) gives every input's
gradient from one transposed solve on the same band factorisation: ``dL/dv = -(F_x^-T c) .
F_v`` (``grid/implicit_derivatives.reverse``). The problem is rebuilt from the solution (its
ends, span, node count, scheme, parameters; the ``fixed`` rule's node times), and ``F_x`` is
factored at its nodes: the solve itself is not repeated.
"""

from __future__ import annotations

import numpy as np

from ...discrete.scheme import Scheme
from ...errors import InputError
from ...solution import Solution, Status
from ..grid.implicit_derivatives import GridGradient, Linearisation, check_grid_cotangent, reverse
from ..grid.linear import band_kernel
from ..grid.problem import GridRequest
from ..options import Compilation, GridOptions, coerce
from .end_derivatives import BVP_DERIVATIVES, input_columns
from .interleaved import NodeLayout
from .phases import Boundary, assembly, ends

__all__ = ["bvp_gradient"]


def bvp_gradient(sol: Solution, cotangent, *, compilation=None) -> GridGradient:
    """``dL/d(q_start, q_end, params)`` of ``L = sum c . (p_start, p_end, nodes)`` of a
    verified `solve_bvp` solution (module docstring): ``{"q_start": (n,), "q_end": (n,),
    "params": (m,)}`` (``params`` only for a system with parameters), a `GridGradient` with
    its error estimate and ``ill_conditioned`` flag."""
    if not isinstance(sol, Solution) or sol.ends is None:
        raise InputError(f"sol must be a solve_bvp Solution, got {type(sol).__name__}")
    if sol.status is not Status.SUCCESS:
        raise InputError(f"sol is not a verified fixed-end solution (status "
                         f"{sol.status.code!r}): no derivative to take")
    system = sol.system
    if system is None or sol.vector_field is None:
        raise InputError("sol has no system (an unpickled Solution): gradient needs the "
                         "solved system; solve again")
    n, N = system.n, sol.t.size
    c = check_grid_cotangent(cotangent, {"p_start": (n,), "p_end": (n,),
                                         "nodes": (N, 2 * n + 1)}, "solve_bvp")
    compilation = coerce(compilation, Compilation, "compilation")
    theta = np.asarray(sol.vector_field.theta, float)
    scheme = Scheme.coerce(sol.scheme)
    boundary = Boundary(sol.q[0].copy(), sol.q[-1].copy(), float(sol.t[0]), float(sol.t[-1]),
                        None if scheme.variable_steps else sol.t.copy(), None)
    request = GridRequest(system, scheme, N, theta, boundary,
                          GridOptions().resolved(max_iter=1), compilation)
    grid, data = assembly(request, request.scheme), ends(request, request.scheme)
    m = 2 * n + 1
    x = NodeLayout(n, N).pack(sol.t, sol.q, sol.p)
    linear = Linearisation(grid, x, data, request.linear, band_kernel(request.compilation))
    weights = np.zeros((N, m))
    weights += c.get("nodes", 0.0)
    weights[0, n + 1:] += c.get("p_start", 0.0)
    weights[-1, n + 1:] += c.get("p_end", 0.0)
    names = [name for name in BVP_DERIVATIVES if name != "params" or system.params]
    columns = {name: input_columns(grid, x, data, name, n, N * m) for name in names}
    found = reverse(linear, weights.ravel(), columns)
    grid.release()
    return found

