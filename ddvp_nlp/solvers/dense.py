"""What a solution needs for dense output: the exact vector field of the solved system.

``Solution.at`` interpolates with the slopes ``f(t_k, z_k) = (H_p, -H_q)`` at the nodes
(docs/theory.md section 10); the solvers hand it this field, evaluated on all nodes in one mapped
CasADi call.
"""

from __future__ import annotations

import numpy as np

from ..physics.hamiltonian import vector_field_function
from ..solution import Solution


def attach(solution: Solution, system, theta, t_end: float | None) -> Solution:
    """Give ``solution`` the requested ``t_end`` and the vector field of ``system`` at ``theta``
    (for ``Solution.at``); returns it."""
    solution.t_end = None if t_end is None else float(t_end)
    field = vector_field_function(system)
    theta = np.asarray(theta, dtype=float)

    def vector_field(t, z):
        t, z = np.atleast_1d(np.asarray(t, float)), np.atleast_2d(np.asarray(z, float))
        mapped = field.map(t.size)
        return np.asarray(mapped(z.T, t[None, :], theta[:, None])).T

    solution.vector_field = vector_field
    return solution
