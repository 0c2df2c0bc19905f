"""Initial-value problems: march node by node with a CasADi rootfinder (docs/theory.md section 5).

Step 0 is a plain implicit step of length ``tau0``: the ``2n`` canonical equations of interval 0
are solved for ``z_1``. Every later step ``k`` solves ``2n + 1`` equations, the canonical equations
of interval ``k`` and the energy equation at node ``k``, for ``(z_{k+1}, tau_k)``. ``tau0`` thus
fixes the discrete energy level and every later step. With ``rule="fixed"`` every step solves the
canonical equations only, on uniform steps that end on ``t_end``.

A step is accepted only if Newton converged, every value is finite, ``tau_k > 0`` (the
time-reversed root ``(z_{k-1}, -tau_{k-1})`` solves the midpoint step equations for every state),
the step's own unscaled residuals are below ``StepControl.tol`` (relative to ``max(|z_k|, Z)``
and ``max(|H_k|, E)``, scales of the run from its start) and the optional step bounds hold
(``acceptance.py``). The first step that
fails ends the march with a status; every accepted node is kept.

Where this is done: this module takes `march`'s and `continue_march`'s arguments (the option
objects coerced, a backward march handed to ``backward.py``, a march to an error asked for to
``target.py``, a continued march checked against its earlier run by ``resume.py``);
``march_problem.py`` checks the inputs into a `MarchProblem`; ``session.py`` marches it (a
`MarchSession`: its parts built, its monitors made from the options, the loop run by the driver,
``solvers/driver.py``, every equation rechecked, the verdict). The parts: ``steps.py`` (the
step functions), ``step_newton.py`` (Newton on one step, with retries, and its compiled unrolled
form), ``chain_newton.py`` (the compiled Newton for many unknowns), ``least_squares.py`` (the
step that replaces a failed one with ``breakdown="least_squares"``), ``chunk.py`` (compiled
chunks of steps), ``stepper.py`` (the careful, compiled and composite steppers),
``monitors.py`` (energy guard, solvability monitor, early verdict, events, stop requests,
checkpoints), ``thinning.py`` (a march that keeps some of its nodes), ``recheck.py`` (every
equation recomputed on the returned grid) and ``resume.py`` (what the loop carries).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ...discrete.scheme import Scheme
from ...errors import InputError
from ...physics.hamiltonian import HamiltonianSystem
from ...solution import Solution
from ...validation import check_memory, check_times
from ..options import (
    DEFAULT_TOLERANCE,
    Compilation,
    Output,
    StepControl,
    Tolerance,
    answers_removed_keywords,
    coerce,
)
from .backward import is_backward, march_backward
from .derivatives import check_derivatives, derivative_request, refuse_unsupported
from .march_problem import check_problem
from .resume import MarchState, check_resume
from .session import MarchSession
from .target import check_target, march_to_error


def coerced(scheme, steps, accuracy, compilation, output):
    """The options of a march as their objects (``InputError`` naming a wrong one), before
    anything is built."""
    if accuracy is not None:
        coerce(accuracy, Tolerance, "accuracy")
    return (Scheme.coerce(scheme), coerce(steps, StepControl, "steps"),
            coerce(compilation, Compilation, "compilation"), coerce(output, Output, "output"))


@answers_removed_keywords
def march(system: HamiltonianSystem, q0, p0=None, t_span=None, *, tau0: float, v0=None,
          scheme: str | Scheme = "vddvp", params: Mapping[str, float] | None = None,
          steps: StepControl | None = None, accuracy: Tolerance | None = DEFAULT_TOLERANCE,
          compilation: Compilation | None = None, output: Output | None = None,
          target_error: float | None = None, derivatives=None) -> Solution:
    """March ``z_0 = (q0, p0)`` from ``t0`` until the first node at or past ``t_end``.

    Args:
        system: the Hamiltonian or Lagrangian system.
        q0: initial position, shape ``(n,)``.
        p0: initial momentum, shape ``(n,)`` (or give ``v0``).
        t_span: ``(t0, t_end)``; energy rules stop at the first node with ``t >= t_end``.
            With ``t_end < t0`` the march runs backwards in time, as scipy's ``solve_ivp``
            does: the forward march of ``H(q, -p, -t)`` mapped back (``backward.py``), its
            times decreasing, ``t_eval`` sorted in decreasing order.
        tau0: first step; for energy rules it sets the discrete energy level, for ``fixed`` the
            step is ``(t_end - t0) / ceil((t_end - t0) / tau0)``, so the march ends on ``t_end``.
        v0: instead of ``p0``, for a Lagrangian system: the first interval's velocity; the
            march takes ``q_1 = q_0 + tau0 v0`` and ``p_0`` by the discrete Legendre transform.
        scheme: ``"vddvp"``, ``"lee"``, ``"fixed"`` or a `Scheme`.
        params: values of the system's parameters (defaults filled in).
        steps: when a step is accepted and when the march stops (`StepControl`: the
            residual tolerance, step bounds, what to do at a breakdown, ``max_steps``,
            ``time_limit``, ``energy_guard``).
        accuracy: the accuracy check (``solvers/accuracy/judgement.py``), which does not trust the
            scheme's own equations and measures the run against the exact flow
            (``solvers/exact/``, adaptive order-8 Runge-Kutta): each step's local error against
            the flow over that step (a step that one compiled RK4 step of the flow already
            clears is screened with it), the energy level of the first step and the nodal
            energy, and the trajectory error against a reference from the first node that
            states its own error. The verdict is ``accurate``, ``drifted`` or ``inaccurate``;
            the first steps are judged as they come (the early verdict), so a march that
            plainly does not follow the motion ends there with status ``inaccurate`` (unless
            ``Tolerance.stop`` is off); ``Solution.verdict`` and ``Solution.local_error`` hold
            the figures. ``None`` leaves the check out (the comparison does, so that run times
            compare like with like, and judges afterwards against the same exact flow).
        compilation: compiled chunks of steps or the careful path, the compiler and its cache
            (`Compilation`).
        output: progress bar, checkpoints, the stop request, the times to report
            (``t_eval``) and the events (`Output`; ``solvers/dense.py``).
        target_error: the trajectory error asked for, relative to the motion's size: the
            march chooses its own first step from a pilot march at ``tau0`` over the start of
            the span, so that the run is ``accurate`` at ``global_tol = target_error``, with
            one second try where it is not (``target.py``); ``march.target_error`` holds
            the choice and what it cost.
        derivatives: inputs to differentiate the states at ``output.t_eval`` in, any of
            ``"q0"``, ``"p0"``, ``"params"``: ``Solution.derivatives`` then holds
            ``d(q, p)(t_eval) / d q0`` (``(M, 2n, n)``), ``/ d p0`` (``(M, 2n, n)``) and ``/ d
            theta`` (``(M, 2n, m)``, columns in ``system.params`` order) of the discrete
            solution read through its dense output, every step length's dependence included
            (``derivatives.py``; docs/gradients.md). Needs ``t_eval`` or events; a march
            from ``v0`` is differentiated in ``"v0"`` (and ``q0``, ``params`` at fixed
            ``v0``; ``velocity_start.py``) in place of ``"p0"``. Not yet with a backward span,
            ``target_error``, thinned output or least-squares breakdown steps.
            ``Solution.derivatives.check`` holds their own check (a directional finite
            difference, one pair of marches more, and whether the energy row is close to
            losing its root; ``derivative_check.py``).
            ``DerivativeOptions(inputs, mode)`` chooses forward or reverse mode (``"auto"``,
            the default: reverse where the ``2n len(t_eval)`` outputs are fewer than the
            inputs; the same values either way).

    A step is accepted only if Newton converged, every value is finite, ``tau_k > 0``, its own
    unscaled residuals are below ``steps.tol`` and the step bounds hold (``acceptance.py``).
    The first step that fails ends the march with a status; every accepted node is kept.

    The solvability monitor (energy rules): at every node the site-density weight
    ``w = f' H_zz f = -8 c(z)`` (docs/theory.md section 7). A positive step needs ``c`` to keep its
    sign and the step to be short against the change of ``w``; the march warns (a
    ``RuntimeWarning`` and ``march.solvability_warning``) at the first node where ``w``
    changes sign or ``|ln(w_k / w_{k-1})|`` exceeds ``MONITOR_LIMIT`` (``monitors.py``).
    ``Solution.solvability`` holds ``c(z_k)`` at every node.

    Returns:
        A `Solution`; failures are a status on it, never an exception.
    """
    names, mode = derivative_request(derivatives)  # before anything, also a backward march's
    if getattr(system, "n_constraints", 0):  # constrained_march.py: its own march, for now
        from .constrained_march import march_constrained

        scheme, steps, compilation, output = coerced(scheme, steps, accuracy, compilation,
                                                     output)
        return march_constrained(system, q0, p0, t_span, tau0=tau0, v0=v0, scheme=scheme,
                                 params=params, steps=steps, accuracy=accuracy,
                                 compilation=compilation, output=output,
                                 target_error=target_error, derivatives=names)
    if names and is_backward(t_span):
        refuse_unsupported(names, v0=v0, backward=True, target_error=target_error,
                           output=coerce(output, Output, "output"), steps=None)
    if is_backward(t_span):  # t_end < t0: the forward march of H(q, -p, -t) (backward.py)
        return march_backward(march, system, q0, p0, t_span, tau0=tau0, v0=v0, scheme=scheme,
                              params=params, steps=steps, accuracy=accuracy,
                              compilation=compilation, output=output,
                              target_error=target_error)
    scheme, steps, compilation, output = coerced(scheme, steps, accuracy, compilation, output)
    refuse_unsupported(names, v0=v0, backward=False, target_error=target_error, output=output,
                       steps=steps)
    target = None
    if target_error is not None:
        target = check_target(target_error, accuracy)
        if v0 is not None:
            raise InputError("target_error needs p0: with v0 the start itself depends on tau0")
    # the options first: the start (p0 from v0, H0) already builds CasADi functions
    check_output_memory(output, system)
    problem = check_problem(system, scheme, q0, p0, v0, t_span, tau0, steps, params)
    check_times(output.t_eval, (problem.t0, problem.t_end))
    if target is not None:
        def run(tau, span, tolerance):
            return march(system, problem.q0, problem.p0, span, tau0=tau, scheme=scheme,
                         params=params, steps=steps, accuracy=tolerance,
                         compilation=compilation,
                         output=output if tolerance is not None else None)
        return march_to_error(run, system, np.concatenate([problem.q0, problem.p0]),
                              problem.t0, problem.t_end, problem.tau0, problem.theta, target,
                              accuracy)
    session = MarchSession(problem, accuracy, compilation, output, derivatives=names)
    session.derivatives_mode, session.march = mode, march  # for Sensitivity's check
    session.start_velocity = None if v0 is None else np.asarray(v0, float)
    solution = session.run()
    if v0 is not None and solution.march is not None:  # gradient() differentiates in v0
        solution.march.start_velocity = {"v0": np.asarray(v0, float).tolist(),
                                         "tau0": problem.tau0}
    return solution


@answers_removed_keywords
def continue_march(system: HamiltonianSystem, state: MarchState, t_end: float | None = None, *,
                   tau0: float, scheme: str | Scheme = "vddvp",
                   params: Mapping[str, float] | None = None, steps: StepControl | None = None,
                   accuracy: Tolerance | None = DEFAULT_TOLERANCE,
                   compilation: Compilation | None = None,
                   output: Output | None = None, derivatives=None) -> Solution:
    """Continue the march whose nodes and carried state are ``state`` (a killed run's last
    checkpoint, or a finished run) to ``t_end`` (default: the one it was asked for; the same or
    later), with the options it ran with (``tau0``, ``scheme``, ``params``, ``steps``,
    ``accuracy``, ``compilation``, as for `march`).

    The loop goes on as if it had never stopped (``resume.py``): the returned nodes are the
    earlier ones followed by those an uninterrupted `march` to ``t_end`` gives, bit for
    bit, on the compiled and the careful path. A fixed-step march keeps its ``t_end``.
    ``derivatives`` are not supported yet (refused by name).

    Returns:
        A `Solution` of the whole run, from the first node.
    """
    if check_derivatives(derivatives):
        raise InputError("derivatives are not supported by continue_march yet: march the "
                         "whole span with march(..., derivatives=...)")
    scheme, steps, compilation, output = coerced(scheme, steps, accuracy, compilation, output)
    if not isinstance(state, MarchState):
        raise InputError(f"state must be a MarchState, got {type(state).__name__}")
    if output.thinned:
        raise InputError(f"continue_march keeps every node (it goes on from consecutive "
                         f"nodes): give output without keep_every = {output.keep_every!r} or "
                         f"keep = {output.keep!r}")
    if getattr(system, "n_constraints", 0):  # constrained_march.py: its own continuation
        from .constrained_march import continue_constrained

        return continue_constrained(system, state, t_end, tau0=tau0, scheme=scheme,
                                    params=params, steps=steps, accuracy=accuracy,
                                    compilation=compilation, output=output)
    check_output_memory(output, system)
    n = state.z.shape[1] // 2
    t_end = state.t_end if t_end is None else t_end
    problem = check_problem(system, scheme, state.z[0, :n], state.z[0, n:], None,
                            (state.t[0], t_end), tau0, steps, params)
    check_resume(state, problem, scheme.variable_steps)
    check_times(output.t_eval, (problem.t0, problem.t_end))
    return MarchSession(problem, accuracy, compilation, output, start=state).run()


def check_output_memory(output: Output, system) -> None:
    """``t_eval`` refused by name where its states (and the dense output's work arrays: the
    two nodes, their slopes and the Hermite weights of every time) would not fit in memory,
    before anything is built (``Output(t_eval=10**8 times)`` ended in a ``MemoryError`` after
    half a minute)."""
    if output.t_eval is None:
        return
    count = output.t_eval.size
    per_time = 8.0 * (8 + 8 * 2 * int(system.n))
    check_memory("len(t_eval)", count, count * per_time, f"the states at {count} output times")
