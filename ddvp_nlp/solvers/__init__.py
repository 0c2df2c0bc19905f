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
- ``ensemble.py``: ``march_ensemble``, many initial states, each marched by ``march``, split
  across worker processes that inherit the loaded compiled chunk.
- ``bvp.py``: fixed-endpoint problems as one NLP (IPOPT) or one Newton system.
- ``periodic.py``: periodic orbits at a prescribed energy on a closed grid (node times free,
  an unfolding parameter; the equation count in its docstring); ``periodic_assembly.py`` its
  residual and sparse Jacobian, ``periodic_start.py`` its starts (a march from the section to
  its return, or a user's guess resampled).
- ``higher.py``: the same two for higher-derivative Lagrangians.
- The integrators users would pick instead, each a stepper of the driver, compiled like the
  march: ``baselines.py`` (Stormer-Verlet kick-drift-kick and drift-kick-drift (``leapfrog``),
  RK4, and what every compiled baseline shares), ``avf.py`` (the averaged vector field method),
  ``verlet_adaptive.py`` (reversible adaptive Stormer-Verlet), ``lee_left.py`` (T.D. Lee's
  left-point scheme), ``scipy_dop853.py`` (scipy's DOP853).
- ``integrator.py``: what a method of the comparison declares about itself (order, symplectic,
  energy-conserving, knob, where it applies), beside its implementation; ``paper_schemes.py``
  declares the paper's own three (vddvp, lee, midpoint).

Every solver returns a ``Solution`` whose failures are a status, never an exception. May import:
``discrete``, ``physics``, ``solution``, ``errors``, ``validation``, ``cache``.
"""
