"""Discretisation: the scheme (`Scheme`: energy rule, weight ``alpha``, clock) and every
discrete equation, written once as a CasADi expression: the interval action of each form and,
derived from it, the canonical (or Euler-Lagrange) equations, the ``vddvp`` and ``lee`` energy
equations and the interval energy; the step equations of the compared integrators. The march,
the grid solvers and every check take their equations from here. The module map is in
``docs/architecture.md``.

Rules: discrete imports only ``physics`` and the base modules.
"""

from typing import TYPE_CHECKING

from ..cache import lazy_exports
from .scheme import CLOCKS, RULES, Scheme

if TYPE_CHECKING:  # for readers and static tools; loaded on first use below
    from .equations import (
        canonical_function,
        diagnostic_rule,
        grid_residuals,
        interval_action_expression,
        interval_energies,
    )

# The equations load when first asked for: `import ddvp_nlp` needs only the scheme.
__getattr__, __dir__ = lazy_exports(__name__, {
    name: "equations" for name in ("canonical_function", "diagnostic_rule", "grid_residuals",
                                   "interval_action_expression", "interval_energies")})

__all__ = ["CLOCKS", "RULES", "Scheme", "canonical_function", "diagnostic_rule", "grid_residuals",
           "interval_action_expression", "interval_energies"]
