"""Discretisation: the scheme and every discrete equation, written once as CasADi expressions.

- ``scheme.py``: which equations (energy rule, weight ``alpha``, clock).
- ``equations.py``: the interval and node equations (canonical or discrete Euler-Lagrange, the
  ``vddvp`` and ``lee`` energy equations, interval energies) and the grid residuals every solver
  and every check uses.
- ``lagrangian.py``: the discrete Legendre transform of a Lagrangian interval.
- ``higher.py``: the discrete action of a higher-derivative Lagrangian and its energies.

The march and the fixed-endpoint solver both take their equations from here. May import:
``physics``, ``errors``, ``validation``, ``cache``.
"""
