"""Fixed-endpoint problems: ``solve_bvp``, the whole discrete action's equations on one grid.

Given ``q(t_0)``, ``q(t_end)`` and ``N`` nodes the unknowns are the interior positions, all
momenta and (energy rules) the interior node times; the equations the canonical equations of
every interval and the energy equation of every interior node (docs/theory.md sections 2, 4).

Where things are:

- ``fixed_ends.py``: ``solve_bvp``: the checks into a ``GridRequest`` whose data is a
  ``phases.Boundary``, the phases, the verification, the ``Solution``;
- ``interleaved.py``: the node-interleaved system and its banded Jacobian (bandwidth ``3n + 1``
  whatever ``N``), a ``grid.GridProblem``;
- ``phases.py``: one solve of one scheme's system by one solver (the grid's Newton or IPOPT);
- ``ends_nlp.py``: IPOPT fed by the banded assembly through callbacks (the grid's IPOPT build);
- ``first_guess.py``: the starts (straight line or shooting, fixed steps on uniform and on
  predicted times); ``end_continuation.py``: the continuation in the end position, the start of
  last resort (shooting and the continuation's corrector are grid problems solved by the grid's
  Newton);
- ``exact/shooting.py``: the continuous problem near a solution, by multiple shooting with the
  reference flow: what the accuracy check measures the grid against, or why there is none.
- ``at_energy.py``: transfers at a prescribed energy (``AtEnergy``): the end time an unknown, the
  last interval's energy prescribed, checked against the exact flow's shooting.

The contract, on top of the grid's (``grid/__init__.py``):

1. The node times stay unknowns (a cumulative sum of steps would make the Jacobian dense) and
   every step stays above ``tau_floor > 0`` (the time-reversed root is never approached).
2. A phase that fails leaves the previous phase's point; the final solve starts from the best
   point the starts reached.
3. Success is the returned point's own residuals: every canonical residual under ``tol`` times
   the motion's size in its units or 128 of its round-offs, every energy residual under ``tol``
   times the mean step times the motion's rate of energy exchange or 128 of its round-offs (the
   round-off read off the rows at the point), every step positive; the message quotes the
   solver (``fixed_ends.verification_limits``).
4. A verified point is then judged against the exact flow (``accuracy/judgement.py``): its
   intervals, its energy, and its trajectory against the continuous solution near it; a problem
   with no continuous solution near the discrete one ends ``inaccurate``, saying so.
5. This package imports the core, ``grid/`` and ``marching/`` (shooting marches).
"""

from typing import TYPE_CHECKING

from ...cache import lazy_exports
from ..marching.gradient import register_gradient

if TYPE_CHECKING:  # for readers and static tools (the API pages); loaded on first use below
    from .at_energy import AtEnergy
    from .first_guess import Shooting, predicted_times
    from .fixed_ends import solve_bvp

# loaded when first asked for: importing one module of the family loads only what it needs
__getattr__, __dir__ = lazy_exports(__name__, {
    "solve_bvp": "fixed_ends", "Shooting": "first_guess", "predicted_times": "first_guess",
    "AtEnergy": "at_energy"})

__all__ = ["AtEnergy", "Shooting", "predicted_times", "solve_bvp"]


def _transfer_gradient(sol, cotangent, **options):
    from .transfer_derivatives import transfer_gradient
    return transfer_gradient(sol, cotangent, **options)


def _ends_gradient(sol, cotangent, **options):
    from .end_gradient import bvp_gradient
    return bvp_gradient(sol, cotangent, **options)


# gradient(sol, ...) of this family's solutions (marching/gradient.py: marching/ may not
# import this package, so the family says what its reverse mode is)
register_gradient("transfer", _transfer_gradient, ("compilation",), "a transfer at an energy")
register_gradient("ends", _ends_gradient, ("compilation",), "a fixed-end solution")
