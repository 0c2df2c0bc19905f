"""Every integrator the comparison runs, behind one interface, with its traits.

A :class:`Method` turns ``(system, run configuration, knob value)`` into a :class:`Solution`.
The knob is what a user turns for accuracy: the first step ``tau0`` of the energy-determined
schemes, the step ``tau`` of fixed-step ones, the tolerance ``rtol`` of DOP853. Traits (order,
symplectic, energy-conserving) are stated here once and read by the reports and the tests.

| name | what | order | symplectic | conserves energy |
|---|---|---|---|---|
| ``vddvp`` | the paper's variable-step midpoint scheme | 2 | yes | yes (midpoint ``H``) |
| ``lee`` | same action, node-time variation ``dS_D/dt_k = 0`` | 2 | yes | yes |
| ``midpoint`` | fixed-step implicit midpoint (the paper's DDVP with fixed steps) | 2 | yes | no |
| ``stormer_verlet`` | leapfrog, separable ``H`` only | 2 | yes | no |
| ``rk4`` | classical Runge-Kutta | 4 | no | no |
| ``dop853`` | scipy's adaptive Dormand-Prince 8(5,3) | 8 | no | no |
| ``lee_left`` | T.D. Lee's original left-point scheme, ``H = p.A p/2 + V`` only | 1 | yes | yes |
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..errors import InputError
from ..physics.hamiltonian import HamiltonianSystem, vector_field_function
from ..scenes import RunConfig
from ..solution import Solution, Status
from ..solvers import baselines
from ..solvers.march import march


@dataclass(frozen=True)
class Method:
    """One integrator of the comparison.

    Attributes:
        name: key used on the command line and in the CSV.
        description: one line for reports.
        order: order of accuracy.
        symplectic, energy_conserving: traits.
        knob: the accuracy setting swept (``"tau0"``, ``"tau"`` or ``"rtol"``).
        run: ``run(system, config, value, *, compiler, cache_dir, max_steps, time_limit=None)
            -> Solution``.
        applies: ``applies(system) -> None`` or the reason the method does not apply.
        redundant: ``redundant(system) -> None`` or why, on this system, the method repeats
            another one exactly (left out of default comparisons, run when asked for by name).
    """

    name: str
    description: str
    order: int
    symplectic: bool
    energy_conserving: bool
    knob: str
    run: Callable[..., Solution]
    applies: Callable[[HamiltonianSystem], str | None] = lambda system: None
    redundant: Callable[[HamiltonianSystem], str | None] = lambda system: None

    def sweep(self, config: RunConfig, halvings: int) -> list[float]:
        """Default knob values, coarse to fine: steps ``2 tau0, tau0, tau0/2, ...``
        (``halvings + 1`` values; ``tau0`` of the scene) or tolerances ``1e-3 ... 1e-12``."""
        if self.knob == "rtol":
            return [10.0 ** -k for k in range(3, 13)]
        largest = min(2 * config.tau0, (config.t_end - config.t0) / 4)
        return [largest / 2 ** j for j in range(halvings + 1)]


def _march(rule):
    def run(system, config, value, *, compiler, cache_dir, max_steps, time_limit=None):
        return march(system, config.q0, config.p0, tau0=value, t_end=config.t_end, t0=config.t0,
                     scheme=rule, params=config.params, max_steps=max_steps, compiler=compiler,
                     cache_dir=cache_dir, time_limit=time_limit,
                     chunk=baselines.chunk_for((config.t_end - config.t0) / value))
    return run


def _fixed_step(name):
    def run(system, config, value, *, compiler, cache_dir, max_steps, time_limit=None):
        _check_steps(config, value, max_steps)
        return baselines.fixed_step_run(system, name, config.q0, config.p0, tau=value,
                                        t_end=config.t_end, t0=config.t0,
                                        theta=system.parameter_vector(config.params),
                                        compiler=compiler, cache_dir=cache_dir,
                                        time_limit=time_limit)
    return run


def _check_steps(config, tau, max_steps):
    steps = math.ceil((config.t_end - config.t0) / tau - 1e-9)
    if steps > max_steps:
        raise InputError(f"tau = {tau!r} needs {steps} steps to reach t_end, more than "
                         f"max_steps = {max_steps}")


def _lee_left(system, config, value, *, compiler, cache_dir, max_steps, time_limit=None):
    return baselines.lee_left_march(system, config.q0, config.p0, tau0=value,
                                    t_end=config.t_end, t0=config.t0,
                                    theta=system.parameter_vector(config.params),
                                    max_steps=max_steps, compiler=compiler, cache_dir=cache_dir,
                                    time_limit=time_limit)


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


def dop853(system, config, value, *, compiler=None, cache_dir=None, max_steps=None,
           time_limit=None, dense_output=False):
    """scipy's DOP853 at ``rtol = atol = value``; its own accepted steps are the nodes.

    The steps are taken one by one (scipy's ``OdeSolver`` interface, the loop ``solve_ivp`` runs)
    so that ``max_steps`` and ``time_limit`` (seconds) bound the run.
    """
    from scipy.integrate import DOP853, OdeSolution

    started = time.perf_counter()
    theta = system.parameter_vector(config.params)
    flow = flow_callable(system, theta)
    built = time.perf_counter()
    solver = DOP853(flow, config.t0, np.concatenate([config.q0, config.p0]), config.t_end,
                    rtol=value, atol=value)
    times, states, pieces = [config.t0], [solver.y.copy()], []
    status, detail = Status.SUCCESS, ""
    while solver.status == "running":
        if max_steps is not None and len(times) > max_steps:
            status, detail = Status.MAX_STEPS, f"max_steps = {max_steps}"
            break
        if time_limit is not None and time.perf_counter() - built > time_limit:
            status, detail = Status.TIME_LIMIT, f"time_limit = {time_limit:g} s"
            break
        scipy_message = solver.step()
        if solver.status == "failed":
            status, detail = Status.SOLVER_FAILED, f"scipy says {scipy_message!r}"
            break
        if not np.all(np.isfinite(solver.y)):
            status = Status.NON_FINITE
            break
        times.append(solver.t)
        states.append(solver.y.copy())
        if dense_output:
            pieces.append(solver.dense_output())
    solved = time.perf_counter()
    n = system.n
    z = np.array(states)
    if status is Status.SUCCESS:
        message = f"{status.value} = {config.t_end:.6g} in {z.shape[0] - 1} steps"
    else:
        message = (f"{status.value}: step {z.shape[0] - 1} from t = {times[-1]:.10g}, "
                   f"q = {z[-1, :n]}, p = {z[-1, n:]}" + (f"; {detail}" if detail else ""))
    solution = Solution(t=np.array(times), q=z[:, :n].copy(), p=z[:, n:].copy(), status=status,
                        message=message, scheme="dop853", energy_residual=np.zeros(0),
                        canonical_residual=np.zeros(0),
                        timing={"build_s": built - started, "solve_s": solved - built},
                        stats={"nfev": int(solver.nfev)})
    solution.dense = OdeSolution(times, pieces) if dense_output and pieces else None
    return solution


def _needs_separable(system):
    parts = baselines.separable_parts(system)
    return parts if isinstance(parts, str) else None


def _needs_quadratic_kinetic(system):
    A = baselines.quadratic_kinetic_matrix(system)
    return A if isinstance(A, str) else None


def _same_as_vddvp(system):
    if system.time_dependent:
        return None
    return "for autonomous H its energy equation is the vddvp one (H_k = H_{k-1})"


METHODS: dict[str, Method] = {m.name: m for m in [
    Method("vddvp", "the paper's variable-step midpoint scheme (energy of interval k at the "
           "previous clock)", 2, True, True, "tau0", _march("vddvp")),
    Method("lee", "same action, node-time variation dS_D/dt_k = 0", 2, True, True, "tau0",
           _march("lee"), redundant=_same_as_vddvp),
    Method("midpoint", "fixed-step implicit midpoint (the paper's DDVP with fixed steps)", 2,
           True, False, "tau", _march("fixed")),
    Method("stormer_verlet", "Stormer-Verlet leapfrog (separable H)", 2, True, False, "tau",
           _fixed_step("stormer_verlet"), applies=_needs_separable),
    Method("rk4", "classical Runge-Kutta", 4, False, False, "tau", _fixed_step("rk4")),
    Method("dop853", "scipy's adaptive DOP853, rtol = atol", 8, False, False, "rtol", dop853),
    Method("lee_left", "T.D. Lee's original left-point scheme with the node-time variation", 1,
           True, True, "tau0", _lee_left, applies=_needs_quadratic_kinetic),
]}


def get_methods(names) -> list[Method]:
    """Methods by name, in the order given; an unknown name is an error listing the known ones."""
    if isinstance(names, str):
        names = [s.strip() for s in names.split(",") if s.strip()]
    if not names:
        raise InputError("methods must name at least one method "
                         f"(choose from {', '.join(METHODS)})")
    chosen = []
    for name in names:
        if name not in METHODS:
            raise InputError(f"unknown method {name!r} (choose from {', '.join(METHODS)})")
        if METHODS[name] not in chosen:
            chosen.append(METHODS[name])
    return chosen
