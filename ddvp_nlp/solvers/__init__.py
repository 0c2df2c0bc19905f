"""Solvers: the discrete equations of ``discrete/`` turned into trajectories.

One folder per family, around a small core:

- ``march/``: initial-value problems node by node (``march``, ``march_ensemble``): the step
  equations as functions, the march's Newton (careful and compiled), the steppers, the monitors.
- ``grid/``: what every whole-grid problem shares: the contract of an assembly
  (``GridProblem``), the request (``GridRequest``), block maps, the banded LU, the grid's one
  Newton and its one IPOPT build.
- ``bvp/``: fixed-endpoint problems (``solve_bvp``) on the node-interleaved banded assembly.
- ``periodic/``: periodic orbits at a prescribed energy and their families (``solve_periodic``,
  ``solve_periodic_family``).
- ``higher/``: higher-derivative Lagrangians, marched and on a grid (``march_higher``,
  ``solve_bvp_higher``).
- ``baselines/``: the integrators the comparison runs (the paper's schemes and what users would
  pick instead), each a stepper of the one step loop, in one registry.
- The core: ``options.py`` (the option objects every solver takes), ``driver.py`` (the one
  step loop and the contract of a stepper), ``accuracy.py`` (the accuracy check that does not
  trust the scheme's equations: its verdict ``accurate``, ``drifted`` or ``inaccurate``),
  ``reference.py`` (the exact flow integrated by a compiled order-8 Runge-Kutta method with
  its own error controlled: the reference the check measures against), ``dense.py`` (the
  interpolant behind ``Solution.at``),
  ``compiler.py`` (finding gcc, compiling and caching generated code).

Every solver keeps these rules:

1. Its inputs are checked before anything is built: a bad value is an ``InputError`` that
   names the argument (or the option's field) and the value.
2. It returns a ``Solution``; a numerical failure is a status on it with a message, never an
   exception, and every accepted node is kept.
3. Success is decided by the returned points' own unscaled residuals, recomputed after the
   solve, and by the accuracy check against the exact flow; what a solver said is quoted in the
   message, never trusted.
4. Its options are objects (``options.py``) passed in the call; nothing is configured by a
   module global.
5. The equations come from ``discrete/`` and are written nowhere here.

What may import what (``tests/test_architecture.py``): the core imports no family; ``grid/``
and ``march/`` import only the core; ``baselines/`` the core and ``march/``; ``bvp/`` and
``periodic/`` the core, ``grid/`` and ``march/`` (their starts march); ``higher/`` the core and
``grid/``. The package as a whole imports ``discrete``, ``physics`` and the base modules.
"""
