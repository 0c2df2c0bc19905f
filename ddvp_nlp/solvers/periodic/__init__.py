"""Periodic orbits at a prescribed energy: ``solve_periodic`` and ``solve_periodic_family``.

A closed grid of ``N`` intervals with free node times, the energy of every interval prescribed,
the period an unknown, a phase condition and unfolding parameters that make the count square
(the docstring of ``solve.py`` derives it).

Where things are:

- ``solve.py``: ``solve_periodic``: the checks into a ``GridRequest`` whose data is an
  ``Orbit``, the solvers, the verification, the ``Solution``;
- ``assembly.py``: the closed system and its sparse Jacobian, a ``grid.GridProblem``;
- ``ipopt.py``: the same rows for the grid's IPOPT build;
- ``start.py``: the section's point at the energy, the march to its return, the predicted
  grid (``tau ~ |w|^(-1/3)``) and resampling;
- ``continuation.py``: continuation in the number of intervals (``continue_in_nodes``: a
  coarse grid first, each finer one from the last refined by node index), the walk
  ``solve_periodic`` takes from its default start and any closed-grid solve can take;
- ``family.py``: orbits along a range of energies, each from the last.

The contract, on top of the grid's (``grid/__init__.py``):

1. Only autonomous ``H`` and the energy rules: anything else is refused before a build.
2. The canonical residuals are verified without the unfolding: a point whose unfolding
   parameter is above round-off fails its verification.
3. Success is the point's own residuals (canonical, the scheme's energy equations with the
   wrap-around node, the prescribed energy, closure, section), every step positive, then the
   accuracy check against the exact flow.
4. This package imports the core, ``grid/`` and ``march/`` (the start is a march).
"""

from typing import TYPE_CHECKING

from ...cache import lazy_exports

if TYPE_CHECKING:  # for readers and static tools (the API pages); loaded on first use below
    from .family import solve_periodic_family
    from .solve import solve_periodic

# loaded when first asked for: importing one module of the family loads only what it needs
__getattr__, __dir__ = lazy_exports(__name__, {"solve_periodic": "solve",
                                                "solve_periodic_family": "family"})

__all__ = ["solve_periodic", "solve_periodic_family"]
