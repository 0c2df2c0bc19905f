"""Discretisation: the scheme and every discrete equation, written once as CasADi expressions.

- ``scheme.py``: which equations (energy rule, weight ``alpha``, clock).
- ``action.py``: the interval action ``S_k(t_a, t_b, z_a, z_b, theta)`` and, derived from it for
  every form, the ``vddvp`` and ``lee`` energy equations and the interval energy.
- ``hamiltonian.py``, ``lagrangian.py``: the action of each form, its interval equations (the
  canonical equations; the discrete Legendre transform) and its energy.
- ``equations.py``: those equations as CasADi functions of the nodes, and the grid residuals
  every solver and every check uses; the form of a system is looked up once, in ``FORMS``.
- ``higher.py``: the discrete action of a higher-derivative Lagrangian and its energies.
- ``lee_left.py``: T.D. Lee's left-point action and its step equations.
- ``explicit.py``, ``runge_kutta.py``: the step maps of Stormer-Verlet (both forms) and RK4.
- ``avf.py``: the averaged vector field equation (Gauss-Legendre segment integral).
- ``adaptive_verlet.py``: reversible adaptive Stormer-Verlet (Sundman ``g(q)``, step density).

The march and the fixed-endpoint solver both take their equations from here. May import:
``physics``, ``errors``, ``validation``, ``cache``.
"""
