"""Whole-grid problems: what the fixed-endpoint, periodic and higher-order solvers share.

A grid problem is one square system ``F(x) = 0`` in all node values of a grid (times, states,
and a family's extra unknowns), assembled from per-block CasADi functions of the equations of
``discrete/``. The families supply the assembly and the verification; this package supplies:

- ``problem.py``: the contract of an assembly (``GridProblem``), the request every grid
  solver receives (``GridRequest``, with the family's own data) and the result every grid
  solver returns (``GridResult``);
- ``maps.py``: per-block functions evaluated over the whole grid in windows, compiled where
  there is a compiler;
- ``linear.py`` and ``band.py``: the banded LU (LAPACK's loops compiled, or LAPACK through
  scipy) and SuperLU where the Jacobian is not narrowly banded;
- ``newton.py``: the grid's one Newton, with the ``tau_floor`` safeguard and a pluggable step
  test (``NaturalMonotonicity``, ``DecreaseOrMonotonicity``);
- ``ipopt.py``: the grid's one IPOPT build (``FeasibilityNlp``: objective 0, the rows as
  equalities, the steps bounded below).

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
   tolerances above their round-off, whatever the solver said, and quote what it said;
   ``"auto"`` is Newton, then IPOPT from the same start when Newton's point fails.

This package imports only the core (``options``, ``compiler``) and ``discrete``; no family.
"""

from .problem import GridProblem, GridRequest, GridResult

__all__ = ["GridProblem", "GridRequest", "GridResult"]
