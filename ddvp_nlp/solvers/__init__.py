"""Solvers: turning the discrete equations into trajectories.

- ``march.py``: initial-value problems, node by node (careful Newton path and compiled chunks).
- ``chunk.py``: many march steps per call in compiled CasADi code; ``compiler.py``: finding gcc
  and caching compiled libraries.
- ``bvp.py``: fixed-endpoint problems as one NLP (IPOPT) or one Newton system.
- ``higher.py``: the same two for higher-derivative Lagrangians.
- ``baselines.py``: the integrators users would pick instead (Stormer-Verlet, RK4, Lee's
  left-point scheme), compiled the same way.

Every solver returns a ``Solution`` whose failures are a status, never an exception. May import:
``discrete``, ``physics``, ``solution``, ``errors``, ``validation``, ``cache``.
"""
