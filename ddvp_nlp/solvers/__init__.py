"""Solvers: turning the discrete equations into trajectories.

- ``driver.py``: the one step loop and the contract of a stepper (numbered rules).
- ``march.py``: initial-value problems, node by node: input checks, building the parts below,
  the driver call, the ``Solution``.

  - ``steps.py``: one march step as CasADi functions, and its careful solve (Newton, retries).
  - ``acceptance.py``: when a step is accepted (residuals, step bounds), for both paths.
  - ``least_squares.py``: Kane-Marsden-Ortiz's step where an energy step has no root.
  - ``chunk.py``: many march steps per call in compiled CasADi code, inputs and outputs named
    in one layout; ``compiler.py``: finding gcc and caching compiled libraries.
  - ``stepper.py``: the careful, compiled and composite steppers the driver runs.
  - ``monitors.py``: the energy guard and the solvability monitor.
- ``bvp.py``: fixed-endpoint problems as one NLP (IPOPT) or one Newton system.
- ``higher.py``: the same two for higher-derivative Lagrangians.
- ``baselines.py``: the integrators users would pick instead (Stormer-Verlet, RK4, Lee's
  left-point scheme), compiled the same way.

Every solver returns a ``Solution`` whose failures are a status, never an exception. May import:
``discrete``, ``physics``, ``solution``, ``errors``, ``validation``, ``cache``.
"""
