"""Periodic orbits at a prescribed energy: ``solve_periodic``, ``solve_periodic_family``, their
stability (``periodic_stability``) and families followed through folds with their bifurcations
(``follow_periodic_family``).

A closed grid of ``N`` intervals with free node times, the energy of every interval prescribed,
the period an unknown, a phase condition and unfolding parameters that make the count square
(the docstring of ``orbit.py`` derives it).

Where things are:

- ``orbit.py``: ``solve_periodic``: the checks into a ``GridRequest`` whose data is an
  ``Orbit``, the solvers, the verification, the ``Solution``;
- ``closed_grid.py``: the closed system and its sparse Jacobian, a ``grid.GridProblem``;
- ``orbit_nlp.py``: the same rows for the grid's IPOPT build;
- ``first_orbit.py``: the section's point at the energy, the march to its return, the predicted
  grid (``tau ~ |w|^(-1/3)``) and resampling;
- ``refinement.py``: continuation in the number of intervals (``continue_in_nodes``: a
  coarse grid first, each finer one from the last refined by node index), the walk
  ``solve_periodic`` takes from its default start and any closed-grid solve can take;
- ``linearised.py``: the linearised orbit about an equilibrium at an energy (a start);
- ``family.py``: orbits along a range of energies, each from the last;
- ``floquet.py``: the discrete monodromy (the step maps' derivatives by implicit
  differentiation), its reduction by the trivial directions, the stability indices and the
  verdict; the exact orbit near a discrete one and its monodromy come from
  ``solvers/exact/closure.py`` (the exact flow's variational equations);
- ``arclength.py``: pseudo-arclength continuation in the energy, the bifurcations between
  members located; ``bifurcation.py``: their test functions and their confirmation on the exact
  flow; ``switching.py``: at a branch point, the new branch's direction from the kernel of the
  extended system and both its halves followed; ``doubling.py``: at a period doubling, the same
  on the grid of the orbit traversed twice.

The contract, on top of the grid's (``grid/__init__.py``):

1. Only autonomous ``H`` and the energy rules: anything else is refused before a build.
2. The canonical residuals are verified without the unfolding: a point whose unfolding
   parameter is above round-off fails its verification.
3. Success is the point's own residuals (canonical, the scheme's energy equations with the
   wrap-around node, the prescribed energy, closure, section), every step positive, then the
   accuracy check against the exact flow.
4. This package imports the core, ``grid/`` and ``marching/`` (the start is a march).
5. Multipliers are reported apart: the trivial ones (two per fixed direction: the flow's and
   each symmetry's) from the blocks of the reduction, the nontrivial ones from the reduced
   monodromy; a verdict is made on the stability indices with a stated tolerance.
6. A bifurcation is reported only where a test function changes sign between two verified
   members, with the bracket it was narrowed to; its confirmation on the exact flow is
   reported beside it, never in its place.
"""

from typing import TYPE_CHECKING

from ...cache import lazy_exports
from ..marching.gradient import register_gradient

if TYPE_CHECKING:  # for readers and static tools (the API pages); loaded on first use below
    from .arclength import Continuation, follow_periodic_family
    from .family import solve_periodic_family
    from .floquet import Stability, periodic_stability
    from .linearised import linearised_orbit
    from .orbit import solve_periodic
    from .switching import Switch

# loaded when first asked for: importing one module of the family loads only what it needs
__getattr__, __dir__ = lazy_exports(__name__, {
    "solve_periodic": "orbit", "solve_periodic_family": "family",
    "Continuation": "arclength", "follow_periodic_family": "arclength",
    "Stability": "floquet", "periodic_stability": "floquet",
    "linearised_orbit": "linearised", "Switch": "switching"})

__all__ = ["Continuation", "Stability", "Switch", "follow_periodic_family", "linearised_orbit",
           "periodic_stability",
           "solve_periodic", "solve_periodic_family"]


def _orbit_gradient(sol, cotangent, **options):
    if "system" not in options:
        from ...errors import InputError
        raise InputError("gradient of a periodic orbit needs system= (and params=, integrals= "
                         "if the solve had them): a periodic Solution does not keep them")
    from .orbit_gradient import orbit_gradient
    return orbit_gradient(sol, cotangent, **options)


# gradient(sol, ...) of a periodic orbit (marching/gradient.py: marching/ may not import this
# package, so the family says what its reverse mode is)
register_gradient("orbit", _orbit_gradient, ("system", "params", "integrals"),
                  "a periodic orbit")
