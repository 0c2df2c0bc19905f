"""Physics: the mechanical systems, each declared once by its generating function: ``H(q, p, t)``
(`HamiltonianSystem`), ``L(q, v, t)`` with ``H`` by the Legendre transform
(`LagrangianSystem`), ``L(q, v_1, ..., v_l, t)`` (`HigherOrderSystem`); their derivatives
and vector fields as CasADi functions. Nothing here knows about grids, schemes, solvers or any
integrator. The module map is in ``docs/architecture.md``.

Rules: physics imports only the base modules (``errors``, ``validation``, ``cache``).
"""

from .hamiltonian import (
    HamiltonianSystem,
    derivatives_function,
    site_density_weight_function,
    vector_field_function,
)
from .higher_order import HigherOrderSystem, euler_lagrange_field
from .lagrangian import Lagrangian, LagrangianSystem

__all__ = ["HamiltonianSystem", "HigherOrderSystem", "Lagrangian", "LagrangianSystem",
           "derivatives_function", "euler_lagrange_field", "site_density_weight_function",
           "vector_field_function"]
