"""Physics: the mechanical systems, each declared once by its generating function.

- ``hamiltonian.py``: ``HamiltonianSystem``, ``H(q, p, t)``, its derivatives and vector field
  ``f = (H_p, -H_q)``.
- ``lagrangian.py``: ``LagrangianSystem``, ``L(q, v, t)``, and ``H`` by the Legendre transform.
- ``higher.py``: ``HigherOrderSystem``, ``L(q, v_1, ..., v_l, t)``.
- ``flow.py``: the exact flow with its derivatives (variational equations by DOP853), the
  reference of the checks against the exact motion.

Nothing here knows about grids, schemes or solvers. May import: ``errors``, ``validation``,
``cache``.
"""
