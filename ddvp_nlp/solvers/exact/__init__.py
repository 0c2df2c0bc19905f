"""The exact flow ``z' = f(z, t) = (H_p, -H_q)`` (for a higher-order ``L``, its Euler-Lagrange
equation in Ostrogradsky's variables): the one truth every verdict, comparison, shooting and
monodromy measures against. The module map is in ``docs/architecture.md``.

The contract of the exact flow. An implementer must keep:

1. It shares nothing with the schemes it checks: no equation of ``discrete/`` (only the vector
   field of ``physics/``), no Newton of the march, no step a scheme chose other than the times
   it is read at.
2. Its own error is controlled and said: every result comes with a bound of its own error,
   and a caller that needs the error below a budget gets it there or is told it could not be.
3. Its derivatives (the variational equations) are those of the same flow, so a shooting
   Newton and a monodromy matrix agree with the trajectory they belong to.
4. This package imports only the core (``options``, ``compiler``) and the base modules.
5. A Newton on the flow (shooting, closure, and outside this package the transfer at an energy
   and the higher-order fit) is the one ``flow_newton.exact_newton``, its tolerances read from
   the one policy (``options.ExactTolerance``), its result carrying the bound of its own error.
"""

from typing import TYPE_CHECKING

from ...cache import lazy_exports

if TYPE_CHECKING:  # for readers and static tools; loaded on first use below
    from .variational import flow_with_derivatives

# loaded when first asked for: the verdicts import the flow without its derivatives
__getattr__, __dir__ = lazy_exports(__name__, {"flow_with_derivatives": "variational"})

__all__ = ["flow_with_derivatives"]
