"""Physics: the mechanical systems, each declared once by its generating function.

- ``hamiltonian.py``: ``HamiltonianSystem``, ``H(q, p, t)``, its derivatives and vector field
  ``f = (H_p, -H_q)``.
- ``lagrangian.py``: ``LagrangianSystem``, ``L(q, v, t)``, and ``H`` by the Legendre transform.
- ``higher.py``: ``HigherOrderSystem``, ``L(q, v_1, ..., v_l, t)``.

Nothing here knows about grids, schemes or solvers. May import: ``errors``, ``validation``,
``cache``.
"""
