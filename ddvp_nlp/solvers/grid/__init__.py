"""Whole-grid problems: what the fixed-endpoint, periodic and higher-order solvers share.

A grid problem is one square system ``F(x) = 0`` in all node values of a grid (times, states,
and a family's extra unknowns), assembled from per-block CasADi functions of the equations of
``discrete/``. The families supply the assembly and the verification; this package supplies the
contract of an assembly and the request and result every grid solver passes, block maps over
the whole grid, the banded and sparse LU, the grid's one Newton, its one IPOPT build and its one
solve policy (Newton, then IPOPT, each run recorded as a ``Stage``). The module map is in
``docs/architecture.md``.

The contract of a grid problem. An assembly must:

1. Be square: ``layout.size`` unknowns and as many rows; ``layout.time_index()`` gives where the
   node times sit in ``x`` (the Newton safeguard keeps every ``t_{k+1} - t_k >= tau_floor``),
   ``layout.bandwidth`` how wide the Jacobian's band is (wider than 32: sparse LU).
2. Separate structure from data: built once per system, scheme and grid size, it takes the
   problem's data (ends, energy, section, parameters) in every ``evaluate(x, data,
   jacobian)``, so that one assembly serves a family of problems.
3. Return from ``evaluate`` a new residual array and, if asked, the Jacobian in its own form,
   with the same residual bits whether or not the Jacobian was asked for (tested for every
   assembly); ``sparse(J)`` and, for a banded Jacobian, ``banded(J)`` give it to the LU, from
   ``J`` alone (the data of the evaluation travels with it); ``release()`` drops the
   Jacobian's storage (the assembly stays cached).
4. Write no equation itself: its blocks are the expressions of ``discrete/``.

And a family using them must:

5. Check its inputs into a ``GridRequest`` (its ``GridOptions`` with the family's defaults in
   place of ``None``) before anything is built.
6. Verify every point a solver returns by the point's own unscaled residuals against
   tolerances above their round-off, whatever the solver said, and quote what it said; run
   the solvers through ``policy.solve_in_order`` (``"auto"``: Newton, then IPOPT from the same
   start when Newton's point fails) and decide a failed point's status by
   ``policy.failure_status``.

This package imports only the core (``options``, ``compiler``) and ``discrete``; no family.
"""

from .problem import GridProblem, GridRequest, GridResult

__all__ = ["GridProblem", "GridRequest", "GridResult"]
