"""Initial-value problems, node by node: ``march`` and ``march_ensemble``.

Step 0 is a plain implicit step of length ``tau0`` (the ``2n`` canonical equations of interval 0
for ``z_1``); every later step of an energy rule solves the canonical equations of interval ``k``
and the energy equation at node ``k`` for ``(z_{k+1}, tau_k)``; the ``fixed`` rule solves the
canonical equations on uniform steps that end on ``t_end`` (docs/theory.md section 5).

Where things are:

- ``initial_value.py``: ``march`` and ``continue_march``: the options, then a session;
- ``march_problem.py``: the march's problem (``MarchProblem``), every input checked
  (``check_problem``);
- ``session.py``: ``MarchSession``, one march: its parts built, its monitors made from the
  options (``MONITORS``: each a ``MarchMonitor`` made by ``from_options`` that adds what it
  found to the ``Solution`` with ``finish``; a new one plugs in without editing the session),
  the driver run, every equation rechecked, the verdict;
- ``steps.py``: one step as CasADi functions (residual, predictor, check), from ``discrete/``;
- ``step_newton.py``: the march's Newton: the option set of both paths, the careful solve with
  retries (``NewtonSteps``), the compiled path's unrolled ``fast_newton``, and one step as a
  public problem (``StepProblem``: residual, Jacobians in the new and old nodes and ``theta``,
  a solve and a transposed solve, the step's sensitivity);
  ``chain_newton.py``: the compiled path's Newton for many unknowns (a chain of conditional
  iterations, each update by a sparse elimination: cost linear in ``n`` for a banded step);
- ``acceptance.py``: when a step is accepted, one test for both paths;
- ``chunk.py``: many steps per call in compiled CasADi code; ``stepper.py``: the careful,
  compiled and composite steppers the driver runs;
- ``least_squares.py``: the step of Kane, Marsden and Ortiz where an energy step has no root;
- ``monitors.py``: energy guard, solvability, early verdict, events, stop requests,
  checkpoints;
- ``recheck.py``: every equation recomputed on the returned grid;
- ``ensemble.py``: ``march_ensemble``, many starts on worker processes, with ``Collect``'s
  per-orbit output and reduction run on the workers;
- ``resume.py``: what the loop carries besides the nodes (``MarchState``), so that
  ``continue_march`` goes on from a run's nodes as if it had never stopped;
- ``target.py``: ``march(..., target_error=E)``, the first step chosen from a pilot march
  for the trajectory error asked for;
- ``thinning.py``: ``Output(keep_every=k)`` and ``Output(keep="t_eval")``: a march that keeps
  some of its nodes, rechecked and judged a window at a time as it goes.
- ``derivatives.py``: ``march(..., derivatives=...)``, the exact derivatives of the states at
  ``t_eval`` in ``q0``, ``p0`` and the parameters, step lengths included (the ``Sensitivity``
  monitor);
- ``adjoint.py``: reverse mode, a discrete adjoint sweep backwards over the accepted steps,
  the step Jacobians recomputed a chunk at a time; ``gradient.py``: ``gradient(sol,
  cotangent)``, the sweep on a march with its own check, and a grid solution's reverse mode
  as its family registered it (``register_gradient``);
- ``derivative_check.py``: a derivative's own check (a directional central difference of the
  discrete map, one pair of marches) and its conditioning (the solvability monitor's weights),
  and the ``Sensitivity`` monitor that puts both on ``Solution.derivatives``;
- ``event_derivatives.py``: the crossing times' derivatives and what reverse mode needs of
  them; ``velocity_start.py``: a march from ``v0`` differentiated in ``v0`` (the discrete
  Legendre map's Jacobians);
- ``scipy_method.py``: ``DDVP``, the march as a method of scipy's ``solve_ivp`` (an
  ``OdeSolver`` handing out the march's nodes one step at a time, with its Hermite dense
  output); not imported here, so that a march loads no ``scipy.integrate``;
- ``constrained_march.py``, ``constrained_steps.py``, ``constrained_start.py``: the march of
  a system with holonomic constraints (``discrete/constrained.py``), its step and chunk, and
  its start made consistent; ``march`` hands a constrained system there;
- ``backward.py``: a march with ``t_end < t0``, backwards in time, as the forward march of the
  time-reversed ``H(q, -p, -t)`` mapped back node by node.

The contract of the march. An implementer changing it must keep:

1. Every input is checked by ``check_problem`` (and the option objects' own checks) before
   anything is built; ``march_ensemble`` checks every start the same way first.
2. Both paths solve the same step functions (``steps.StepFunctions``) with the same Newton
   options (``step_newton.NEWTON_OPTIONS``) and accept a step by the same test
   (``acceptance.Acceptance``): finite values, ``tau > 0``, the step's unscaled residuals under
   ``StepControl.tol``, the step bounds. The compiled path never changes what is accepted: a
   step that fails its check inside a chunk is redone by the careful path from the last good
   node. Their nodes differ by round-off only.
3. The steppers keep the driver's rules (``driver.py``): accepted nodes in order, a failure as
   a status with every node before it kept, the cut at ``t_end`` and the monitors left to the
   driver.
4. After the loop every equation is recomputed on the returned grid (``recheck.py``) and the
   accuracy check reports on the whole run; the ``Solution`` carries both. A thinned march
   (``thinning.py``) does both a window at a time as it goes, on every node, kept or not.
5. A Ctrl-C or a stop request ends the march with status ``interrupted`` and every node every
   monitor saw kept (a thinned march: every kept one, and its last). An interrupted march of
   more than ``INTERRUPTED_JUDGED`` nodes is returned without its final accuracy check
   (``Solution.accuracy_skipped`` says so), so that it ends at once.
6. This package imports the core and ``options``; never a grid family or a baseline.
7. Everything the loop carries from step to step that can change a node is in every node's
   ``Advance.values["carry"]`` (``resume.py``): a march continued from any of its nodes gives
   the nodes of an uninterrupted one bit for bit.
8. Whatever watches the nodes as they come is a monitor (``session.py``): made from the options
   by its kind's ``from_options``, listed in ``MONITORS`` in the order it watches, adding to the
   ``Solution`` only in its ``finish``. ``MarchSession.run`` names no monitor.
"""

from .ensemble import Collect, march_ensemble
from .initial_value import continue_march, march
from .march_problem import MarchProblem, check_problem
from .resume import MarchState
from .session import MONITORS, MarchMonitor, MarchSession
from .step_newton import StepProblem

__all__ = ["MONITORS", "Collect", "MarchMonitor", "MarchProblem", "MarchSession", "MarchState",
           "StepProblem", "check_problem", "continue_march", "march", "march_ensemble"]
