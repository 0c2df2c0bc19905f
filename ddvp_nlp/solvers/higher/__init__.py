"""Higher-derivative Lagrangians (the paper's case 1): ``march_higher`` and
``solve_bvp_higher``.

A Lagrangian of order ``l`` couples ``2l + 1`` nodes in its Euler-Lagrange equation at a node,
so a march starts from ``2l`` nodes and a fixed-endpoint problem fixes ``l`` nodes at each end.

Where things are:

- ``stepping.py``: ``march_higher`` (node by node, in the one step loop of ``driver.py``) and
  ``solve_bvp_higher`` (``bvp_request`` checks its inputs into a ``GridRequest`` whose data is
  a ``problem.FixedNodes``);
- ``fixed_nodes.py``: that data and what follows from it (uniform times, scales, the pins);
- ``windows.py``: the system window by window (the window's action and its derivatives), a
  ``grid.GridProblem``;
- ``window_solve.py``: one rule's solve (the grid's Newton with the ``DecreaseOrMonotonicity`` test,
  through a Newton homotopy where plain Newton does not converge; or IPOPT), and the
  verification;
- ``window_nlp.py``: the window gradient mapped over the grid for the grid's IPOPT build;
- ``accuracy/positions.py``: the accuracy check of a higher-order trajectory against the exact
  Euler-Lagrange flow (its positions, step by step and over the run).

The contract, on top of the grid's (``grid/__init__.py``):

1. Fixed steps are solved first on uniform times; an energy rule releases the times from that
   solution.
2. Verification decides, whatever the solver said: the Euler-Lagrange rows in the units of
   ``q``, the energy rows, the pins held, every step positive, against bounds of each row's own
   round-off computed from the data, not from the point.
3. Every result is then judged against the exact Euler-Lagrange flow through its data
   (``accuracy/positions.py``); a fixed-endpoint problem with no continuous solution ends
   ``inaccurate``, saying so.
4. This package imports the core and ``grid/``.
"""

from typing import TYPE_CHECKING

from ...cache import lazy_exports

if TYPE_CHECKING:  # for readers and static tools (the API pages); loaded on first use below
    from .stepping import march_higher, solve_bvp_higher

# loaded when first asked for: importing one module of the family loads only what it needs
__getattr__, __dir__ = lazy_exports(__name__, {"march_higher": "stepping",
                                                "solve_bvp_higher": "stepping"})

__all__ = ["march_higher", "solve_bvp_higher"]
