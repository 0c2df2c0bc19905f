"""scipy's DOP853 (Dormand-Prince 8(5,3), adaptive) on ``z' = (H_p, -H_q)``, run by the driver.

The nodes are DOP853's own accepted steps at ``rtol = atol = value``. The steps are taken one by
one through scipy's ``OdeSolver`` interface (the loop ``solve_ivp`` runs), several per stepper
call, so that the driver's ``max_steps`` and ``time_limit`` bound the run. Order 8, neither
symplectic nor energy-conserving.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

import casadi as ca
import numpy as np

from ...physics.hamiltonian import HamiltonianSystem, vector_field_function
from ...solution import Solution, Status
from ..driver import Advance, Nodes, describe_phase_space, drive
from .integrator import Integrator

# scipy steps per stepper call: enough that the driver's per-call work is small beside them,
# few enough that time_limit is still checked every millisecond or so.
STEPS_PER_CALL = 16


def flow_callable(system: HamiltonianSystem, theta) -> Callable[[float, np.ndarray], np.ndarray]:
    """``f(t, z) = (H_p, -H_q)`` as a Python callable for scipy, through CasADi's buffer interface
    (about 0.5 us per call here, less than a numpy right-hand side of the pendulum)."""
    n = system.n
    z, t = ca.SX.sym("z", 2 * n), ca.SX.sym("t")
    field = vector_field_function(system)(z, t, ca.DM(np.asarray(theta, float)))
    function = ca.Function("flow", [z, t], [field])
    buffer, trigger = function.buffer()
    z_in, t_in, out = np.zeros(2 * n), np.zeros(1), np.zeros(2 * n)
    buffer.set_arg(0, memoryview(z_in))
    buffer.set_arg(1, memoryview(t_in))
    buffer.set_res(0, memoryview(out))

    def flow(t_value, z_value):
        z_in[:] = z_value
        t_in[0] = t_value
        trigger()
        return out.copy()

    flow.keep = (function, buffer)  # the buffer must outlive the callable
    return flow


class _Dop853Steps:
    """Stepper (``driver.py``) over a scipy ``DOP853`` solver: each accepted scipy step is a node
    if finite; scipy's failure is ``SOLVER_FAILED``. With ``dense_output`` it keeps each step's
    interpolant."""

    describe = staticmethod(describe_phase_space)

    def __init__(self, solver, dense_output: bool):
        self.solver = solver
        self.pieces = [] if dense_output else None

    def advance(self, nodes: Nodes, budget: int) -> Advance:
        solver = self.solver
        times, states = [], []
        status, detail = Status.SUCCESS, ""
        for _ in range(min(budget, STEPS_PER_CALL)):
            scipy_message = solver.step()
            if solver.status == "failed":
                status, detail = Status.SOLVER_FAILED, f"scipy says {scipy_message!r}"
                break
            if not np.all(np.isfinite(solver.y)):
                status = Status.NON_FINITE
                break
            times.append(solver.t)
            states.append(solver.y.copy())
            if self.pieces is not None:
                self.pieces.append(solver.dense_output())
            if solver.status != "running":  # scipy ends on t_end exactly
                break
        return Advance(np.array(times), np.array(states).reshape(len(times), nodes.width),
                       status, detail)


def dop853(system, config, value, *, compiler=None, cache_dir=None, max_steps=None,
           time_limit=None, dense_output=False) -> Solution:
    """scipy's DOP853 at ``rtol = atol = value``; its own accepted steps are the nodes.

    ``max_steps`` (``None``: no bound) and ``time_limit`` (seconds) bound the run; with
    ``dense_output`` the solution's ``dense`` is scipy's ``OdeSolution`` over the nodes (else
    ``None``). ``compiler`` and ``cache_dir`` are accepted for the common ``run`` signature.
    """
    from scipy import integrate

    started = time.perf_counter()
    flow = flow_callable(system, system.parameter_vector(config.params))
    built = time.perf_counter()
    z0 = np.concatenate([config.q0, config.p0])
    solver = integrate.DOP853(flow, config.t0, z0, config.t_end, rtol=value, atol=value)
    stepper = _Dop853Steps(solver, dense_output)
    outcome = drive(stepper, Nodes(config.t0, z0), t_end=config.t_end,
                    max_steps=sys.maxsize if max_steps is None else max_steps,
                    time_limit=time_limit)
    solved = time.perf_counter()
    n = system.n
    solution = Solution(t=outcome.t, q=outcome.z[:, :n].copy(), p=outcome.z[:, n:].copy(),
                        status=outcome.status, message=outcome.message, scheme="dop853",
                        energy_residual=np.zeros(0), canonical_residual=np.zeros(0),
                        timing={"build_s": built - started, "solve_s": solved - built},
                        stats={"nfev": int(solver.nfev)})
    solution.dense = integrate.OdeSolution(outcome.t, stepper.pieces) if stepper.pieces else \
        None
    return solution


DOP853 = Integrator("dop853", "scipy's adaptive DOP853, rtol = atol", order=8, symplectic=False,
                    energy_conserving=False, knob="rtol", run=dop853)
