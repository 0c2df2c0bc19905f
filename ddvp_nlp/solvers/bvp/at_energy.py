"""Transfers at a prescribed energy: ``q(t_0) = q_start``, ``q(t_end) = q_end`` with ``t_end`` an
unknown and the discrete energy prescribed, ``solve_bvp(system, q_start, q_end, AtEnergy(E),
nodes=N)``.

The unknowns are those of the fixed-endpoint problem (interior ``q``, all ``p``, the node times)
with ``t_{N-1}`` free too; the equations are the canonical equations of every interval and the
energy equations ``H_k = H_{k-1}`` of the interior nodes, as there, and in place of the pin
``t_{N-1} = t_end`` the last interval's energy ``H(Q_{N-2}, P_{N-2}) = E``. The count stays
square and the Jacobian banded (the new row lies in the last block, ``assembly.
prescribed_energy_block``); with the energy equations it prescribes every interval's energy
(autonomous ``H``), so the transfer time is whatever the motion at energy ``E`` takes.

The solve (``fixed_ends.py`` calls these in order):

1. the fixed-endpoint problem on ``(t_0, t_0 + D)`` with the duration guess ``D``
   (``AtEnergy.duration``, else the guess's span, else `duration_guess`), by
   ``solve_bvp`` itself, then a secant iteration on ``D`` towards ``E(D) = E``
   (`fixed_time_start`): a grid on the right path, at an energy ``E_1`` near ``E``;
2. `release_end_time`: the grid's Newton on the system above from that grid, the energy
   continued from ``E_1`` to ``E`` (the whole way first; a failed step halves, a successful one
   doubles up to what remains; each from the secant predictor), then the verification
   (residuals of every kind, the prescribed energy on every interval, every step positive), the
   accuracy check (``accuracy.assess``, level ``E``) and a check against the exact flow:
   shooting on the exact flow (``solvers/exact/variational.py``) for ``(p_0, T)`` with
   ``q(T) = q_end``, ``H(q_start, p_0) = E`` from the grid's ``p_0`` and ``t_end - t_0``, whose
   transfer time and path (at the grid's node times) the grid's are compared with
   (``transfer.exact``).

Only autonomous ``H`` and the energy rules; Newton only (IPOPT's build has no free end time).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ...cache import PROBLEMS
from ...discrete import equations
from ...errors import InputError
from ...physics.hamiltonian import derivatives_function, flow_jacobian_function
from ...solution import Solution, Status, TransferRecord
from ...validation import check_real
from ..accuracy.judgement import Level, assess, fixed_ends_report, judge
from ..exact.flow_newton import exact_newton
from ..exact.tolerance import EXACT_TOLERANCE
from ..exact.variational import flow_with_derivatives
from ..grid.linear import band_kernel
from ..grid.motion_size import energy_rate, energy_traded
from ..grid.newton import newton
from ..grid.problem import check_energy_problem
from ..grid.round_off import row_noise
from ..options import Tolerance
from .interleaved import Ends, GridAssembly, prescribed_energy_block
from .phases import BOUNDS_ALLOWED, NOISE_TARGET, canonical_sizes

EPS = float(np.finfo(float).eps)
# The energy's continuation from the fixed-time grid's: a failed step halves (at most this many
# times in all), a successful one doubles up to what remains.
MAX_HALVINGS = 40
# Newton's iterations on one step of that continuation: from the secant predictor a step that
# converges takes a few; one that does not is halved rather than iterated on.
STEP_ITERATIONS = 60
# The secant on the duration before the end time is released: steps, and the energy distance
# (relative to the energy the motion trades over its duration) at which it stops.
SECANT_STEPS = 12
SECANT_TOL = 1e-3
SECANT_REACH = 0.1
# The exact flow's transfer (`shoot_transfer`): Newton's evaluations, and the residual (relative
# to the scales of the positions and the energy) it stops at and the transfer is accepted at.
SHOOTING_ITERATIONS = 15
SHOOTING_STOP = EXACT_TOLERANCE.newton_tight_tol
SHOOTING_ACCEPT = EXACT_TOLERANCE.newton_accept_tol


@dataclass(frozen=True)
class AtEnergy:
    """The time span of a transfer at a prescribed energy, given to ``solve_bvp`` in place of
    ``(t0, t_end)``: the start time is fixed, the end time is an unknown, and the energy of
    every interval is ``energy`` (module docstring).

    Attributes:
        energy: the prescribed energy ``E`` (autonomous ``H``).
        t0: the start time.
        duration: a guess of the transfer time ``t_end - t0`` (default: the guess's span, else
            the straight line at the speed ``H = E`` gives at its midpoint).
    """

    energy: float
    t0: float = 0.0
    duration: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "energy", check_real("energy", self.energy))
        object.__setattr__(self, "t0", check_real("t0", self.t0))
        object.__setattr__(self, "duration", check_real("duration", self.duration,
                                                        positive=True, allow_none=True))


def check_transfer(system, scheme, options) -> None:
    """What a transfer at a prescribed energy needs of the system, scheme and solver."""
    check_energy_problem(system, scheme, "a transfer at a prescribed energy")
    if options is not None and options.solver == "ipopt":
        raise InputError("solver 'ipopt' has no free end time: a transfer at a prescribed "
                         "energy is solved by Newton (solver 'newton' or 'auto')")


def duration_guess(system, theta, q_start, q_end, energy: float, guess=None) -> float:
    """``AtEnergy.duration``'s default: the span of a guess with times, else ``|q_end -
    q_start| / |v . d|`` with ``d`` the straight line's direction and ``v = H_p(q_m, s d)`` at
    its midpoint ``q_m``, ``s > 0`` the first root of ``H(q_m, s d) = E``, sought up to a
    thousand times the momentum `_momentum_scale` gives (``InputError`` when there is none:
    then give the duration)."""
    times = getattr(guess, "t", None)
    if times is None and isinstance(guess, dict):
        times = guess.get("t")
    if times is not None and np.size(times) >= 2:
        return float(np.ravel(times)[-1] - np.ravel(times)[0])
    chord = np.asarray(q_end, float) - np.asarray(q_start, float)
    length = float(np.linalg.norm(chord))
    middle = (np.asarray(q_start, float) + np.asarray(q_end, float)) / 2
    direction = chord / length if length > 0 else np.eye(system.n)[0]
    scale = np.linspace(0.0, 1e3, 20001) * _momentum_scale(system, theta, middle, direction,
                                                           energy)
    H = system.energy(np.tile(middle, (scale.size, 1)), scale[:, None] * direction,
                      np.zeros(scale.size), theta) - energy
    change = np.flatnonzero(np.sign(H[:-1]) * np.sign(H[1:]) <= 0)
    if length == 0 or change.size == 0:
        raise InputError(f"no duration guess for the transfer at energy {energy!r}: give "
                         f"AtEnergy(energy, duration=...) (along the straight line's midpoint "
                         f"H(q, s d) - E has no root for s in (0, {scale[-1]:.6g}])")
    from scipy.optimize import brentq  # loaded here: 0.3-0.7 s that every `ddvp bvp` paid

    k = int(change[0])
    s = brentq(lambda a: float(system.energy(middle[None], a * direction[None], [0.0], theta)[0])
               - energy, scale[k], scale[k + 1]) if H[k] != 0 else scale[k]
    _, _, H_p, _ = derivatives_function(system)(middle, s * direction, 0.0, theta)
    speed = abs(float(np.asarray(H_p).ravel() @ direction))
    if speed == 0:
        raise InputError("no duration guess for the transfer: the speed along the straight "
                         "line is 0; give AtEnergy(energy, duration=...)")
    return length / speed


def _momentum_scale(system, theta, middle, direction, energy: float) -> float:
    """The momentum along ``d`` at which ``H(q_m, s d)`` reaches ``E`` if ``H`` were quadratic
    in it from ``s = 0``: ``sqrt(2 |E - H_0| / |d' H_pp d|)``, or ``|E - H_0| / |H_p . d|``
    where ``H_pp`` is 0 along ``d``, or 1 where neither tells. It follows the units of the
    momenta and of ``H``, and no constant added to ``H`` moves it (a scan of ``s`` in ``(0,
    1000]`` found no root in lengths of ``1e6`` and time units of ``1e-3``)."""
    n = system.n
    f, A = flow_jacobian_function(system)(np.r_[middle, np.zeros(n)], 0.0, theta)
    slope = abs(float(np.asarray(f, float).ravel()[:n] @ direction))
    curvature = abs(float(direction @ np.asarray(A, float)[:n, n:] @ direction))
    gap = abs(energy - float(system.energy(middle[None], np.zeros((1, n)), [0.0], theta)[0]))
    with np.errstate(all="ignore"):
        scale = np.sqrt(2 * gap / curvature) if curvature > 0 else gap / slope
    return float(scale) if np.isfinite(scale) and scale > 0 else 1.0


def fixed_time_start(solve_fixed, system, scheme, theta, duration: float, energy: float):
    """``(grid, durations)``: a fixed-endpoint grid whose energy is near ``E``, by a damped
    secant iteration on the duration. ``solve_fixed(D, guess)`` solves the fixed-time problem on
    ``(t_0, t_0 + D)``; from the guessed duration, then ``D (1 + 1e-2)``, each next ``D`` from
    the secant through the last two ``(D, E(D))``, changed by at most ``SECANT_REACH`` of ``D``
    and halved while a solve fails or ends farther from ``E`` (``E(D)`` folds where the
    fixed-time solver changes branch: the pendulum's two-swing transfer jumped to a direct one
    at a 15 % longer duration), each solve from the last grid with its times stretched, until
    ``|E(D) - E|`` is below ``SECANT_TOL`` of the energy the first grid's motion trades over
    its duration (`grid.motion_size.energy_traded`: in the units of ``H`` whatever the
    coordinates', and blind to a constant added to ``H``; ``max(1, |E|)`` stopped the secant
    at once in lengths of ``1e-8``, and the continuation from there failed). The end time is
    then released from a grid whose energy is close: the continuation in ``E`` that follows
    has little left."""
    grid = solve_fixed(duration, None)
    if not grid.success:
        return grid, [duration]
    tried = [(duration, _energy(system, scheme, grid, theta))]
    close = SECANT_TOL * energy_traded(grid.t, np.hstack([grid.q, grid.p]), duration)
    for _ in range(SECANT_STEPS):
        if abs(tried[-1][1] - energy) <= close:
            break
        d1, e1 = tried[-1]
        if len(tried) == 1:
            step = 1e-2 * d1
        else:
            d0, e0 = tried[-2]
            step = (energy - e1) * (d1 - d0) / (e1 - e0) if e1 != e0 else 0.0
        step = float(np.clip(step, -SECANT_REACH * d1, SECANT_REACH * d1))
        for _ in range(4):
            stretch = (d1 + step) / d1
            trial = solve_fixed(d1 + step, {"t": grid.t[0] + (grid.t - grid.t[0]) * stretch,
                                            "q": grid.q, "p": grid.p})
            level = _energy(system, scheme, trial, theta) if trial.success else None
            if level is not None and (len(tried) == 1 or abs(level - energy) < abs(e1 - energy)):
                break
            step /= 2
        else:
            break
        grid = trial
        tried.append((d1 + step, level))
    return grid, [d for d, _ in tried]


def _energy(system, scheme, grid: Solution, theta) -> float:
    return float(equations.interval_energies(system, scheme, grid.t[:2], grid.q[:2],
                                             grid.p[:2], theta)[0])


def _assembly(system, scheme, nodes, compilation) -> GridAssembly:
    key = ("bvp_transfer", scheme, nodes, compilation.compiler, str(compilation.cache_dir))
    return PROBLEMS.get(system, key, lambda: GridAssembly(
        system, scheme, nodes, compilation, last=prescribed_energy_block(system, scheme)))


def newton_targets(system, grid: GridAssembly, x, ends: Ends) -> np.ndarray:
    """Per-row targets near ``x``, in each row's own units, as the fixed-endpoint grid's
    (``phases.newton_targets``): ``NOISE_TARGET`` times the largest change of each kind of row
    (the canonical rows of each column, the scaled energy rows, the prescribed energy's row)
    when every unknown moves by one unit in its last place (`grid.round_off.row_noise`); a
    pin's row its own, never below eps times its column's magnitude. With ``16 eps max(1,
    |x|, |E|)`` a pendulum in lengths of ``1e-8`` stopped with its prescribed energy
    unreached (``inaccurate``), and in time units of ``1e5`` its transfer time ``4e-9`` off."""
    layout = grid.layout
    n, N, m = layout.n, layout.nodes, layout.m
    noise = row_noise(grid, x, ends)
    columns = EPS * np.max(np.abs(np.asarray(x, float).reshape(N, m)), axis=0)
    target = np.maximum(noise, np.r_[columns[:n + 1], np.zeros((N - 1) * m),
                                     columns[1:n + 1]][:noise.size])
    body = target[n + 1:n + 1 + (N - 1) * m].reshape(N - 1, m)
    t, q, p = layout.unpack(x)
    floor = EPS * canonical_sizes(system, grid.scheme, q, p)
    body[:, :2 * n] = np.maximum(body[:, :2 * n].max(axis=0), floor)
    if N > 2:
        body[:-1, 2 * n] = np.max(body[:-1, 2 * n])
    # the prescribed energy's row alone: a move of one unit in the last place can round away
    # in every term of H (the pendulum's at E = 0.5 did not change in three draws); its
    # round-off is at least that of |E| and of the energy rows' H (unscaled)
    unscaled = float(body[0, 2 * n]) * ends.energy_scale if N > 2 else 0.0
    body[-1, 2 * n] = max(body[-1, 2 * n], EPS * abs(ends.energy), unscaled)
    return NOISE_TARGET * np.maximum(target, np.finfo(float).tiny)


def _limits(system, grid: GridAssembly, x, ends: Ends, tol: float) -> dict:
    """The largest residual of each kind the transfer may have and pass: ``tol`` relative to
    what the row measures, or ``BOUNDS_ALLOWED`` of its Newton target (`newton_targets`), whichever
    is larger: the motion's size in each canonical row's units; for the energy rows and the
    prescribed energy (unscaled) ``tol`` times the mean step times the rate at which the motion
    trades energy (`grid.motion_size.energy_rate`), as the fixed-endpoint grid's; for the end
    position the motion's size in positions. A floor of 1 and ``tol`` as an absolute number
    passed transfers in small units whose rows were not solved."""
    layout = grid.layout
    n, N, m = layout.n, layout.nodes, layout.m
    targets = newton_targets(system, grid, x, ends)
    body = targets[n + 1:n + 1 + (N - 1) * m].reshape(N - 1, m)
    t, q, p = layout.unpack(x)
    rate = energy_rate(t, np.hstack([q, p])) * (t[-1] - t[0]) / (N - 1)
    energy = max(tol * rate, BOUNDS_ALLOWED * float(body[0, 2 * n]) * ends.energy_scale
                 if N > 2 else 0.0)
    return {"canonical": float(np.max(np.maximum(tol * canonical_sizes(system, grid.scheme, q, p),
                                                 BOUNDS_ALLOWED * body[0, :2 * n]))),
            "energy": energy,
            "prescribed_energy": max(tol * rate, BOUNDS_ALLOWED * float(body[-1, 2 * n])),
            "q_end": max(tol * float(np.max(np.ptp(q, axis=0))),
                         BOUNDS_ALLOWED * float(np.max(targets[-n:])))}


def release_end_time(system, scheme, fixed: Solution, span: AtEnergy, theta, *, tol: float,
                     max_iter: int, compilation, accuracy: Tolerance | None = None
                     ) -> Solution:
    """Phase 2 of the module docstring from the fixed-endpoint grid ``fixed``; ``accuracy``:
    the check's tolerances (default `Tolerance`)."""
    started = time.perf_counter()
    nodes = fixed.t.size
    grid = _assembly(system, scheme, nodes, compilation)
    x = grid.layout.pack(fixed.t, fixed.q, fixed.p)
    first = float(equations.interval_energies(system, scheme, fixed.t[:2], fixed.q[:2],
                                              fixed.p[:2], theta)[0])
    level, step, halvings, iterations, said = first, span.energy - first, 0, 0, ""
    secant = None  # (the last step's change of the grid, that step): the predictor
    while True:
        trial_level = level + step
        scale = (x[-grid.layout.m] - span.t0) / (nodes - 1)
        ends = Ends(fixed.q[0], fixed.q[-1], np.array([span.t0, x[-grid.layout.m]]), theta,
                    scale, energy=trial_level)
        start = x if secant is None else x + secant[0] * (step / secant[1])
        result = newton(grid, start, ends, newton_targets(system, grid, x, ends),
                        tau_floor=1e-3 * scale, max_iter=min(max_iter, STEP_ITERATIONS),
                        linear="auto", kernel=band_kernel(compilation))
        iterations += result.iterations
        said = result.outcome
        if result.converged and np.all(np.diff(result.x[grid.layout.time_index()]) > 0):
            secant = (result.x - x, step)
            x, level = result.x, trial_level
            if level == span.energy:
                break
            remaining = span.energy - level
            step = remaining if abs(2 * step) >= abs(remaining) else 2 * step
        elif halvings < MAX_HALVINGS:
            halvings, step = halvings + 1, step / 2
        else:
            break
    return _verified(system, scheme, grid, x, ends, span, theta, tol, accuracy or Tolerance(),
                     {"iterations": iterations, "outcome": said, "halvings": halvings,
                      "start_energy": first, "reached_energy": level,
                      "seconds": time.perf_counter() - started})


def _verified(system, scheme, grid, x, ends, span, theta, tol, tolerance, phase) -> Solution:
    """The point's own residuals (canonical, the energy equations, the prescribed energy on
    every interval), the accuracy check and the exact flow's shooting (module docstring)."""
    t, q, p = grid.layout.unpack(x)
    ends = Ends(ends.q_start, ends.q_end, np.array([span.t0, t[-1]]), theta,
                ends.energy_scale, energy=span.energy)
    F, _ = grid.evaluate(x, ends, jacobian=False)
    canonical, energy_rows = grid.residuals(F, ends)
    intervals = equations.interval_energies(system, scheme, t, q, p, theta)
    worst = {"canonical": float(np.max(np.abs(canonical))),
             "energy": float(np.max(np.abs(energy_rows), initial=0.0)),
             "prescribed_energy": float(np.max(np.abs(intervals - span.energy))),
             "q_end": float(np.max(np.abs(q[-1] - ends.q_end)))}
    limits = _limits(system, grid, x, ends, tol)
    listed = _listed(worst)
    tau = np.diff(t)
    if not np.all(np.isfinite(x)):
        status, message = Status.NON_FINITE, f"non-finite values ({phase['outcome']})"
    elif np.min(tau) <= 0:
        status, message = Status.NO_ADMISSIBLE_STEP, (
            f"step {int(np.argmin(tau))} is not positive ({phase['outcome']})")
    elif any(worst[key] > limits[key] for key in worst) or \
            phase["reached_energy"] != span.energy:
        status, message = Status.SOLVER_FAILED, (
            f"no transfer at energy {span.energy:.10g} found: reached "
            f"{phase['reached_energy']:.10g} from {phase['start_energy']:.10g}; largest "
            f"residuals {listed} (limits {_listed(limits)}; newton: {phase['outcome']})")
    else:
        status, message = Status.SUCCESS, (
            f"transfer at energy {span.energy:.10g} found and verified: transfer time "
            f"{t[-1] - t[0]:.12g}; largest residuals {listed} (limits {_listed(limits)}); newton: "
            f"{phase['iterations']} iterations from the fixed-time grid at energy "
            f"{phase['start_energy']:.8g}")
    report, local_error, exact = None, np.zeros(0), None
    if np.all(np.isfinite(x)):
        report, local_error, exact = _judged(system, scheme, t, q, p, span,
                                                                 theta, tolerance)
    found = TransferRecord(transfer_time=float(t[-1] - t[0]), energy=span.energy,
                           residuals=worst, residual_limit=limits, tau_min=float(np.min(tau)),
                           tau_max=float(np.max(tau)), exact=exact)
    solution = Solution(t=t, q=q, p=p, status=status, message=message, scheme=scheme.rule,
                    energy_residual=energy_rows,
                    canonical_residual=np.max(np.abs(canonical), axis=1),
                    newton_iterations=phase["iterations"],
                    timing={"build_s": 0.0, "solve_s": phase["seconds"]},
                    stats={"transfer": phase}, transfer=found)
    judge(solution, report, tolerance, local_error=local_error, advice="try more nodes")
    return solution


def _listed(values: dict) -> str:
    return ", ".join(f"{name} {value:.3e}" for name, value in values.items())


def _judged(system, scheme, t, q, p, span: AtEnergy, theta, tolerance: Tolerance):
    """The accuracy check of a transfer (``accuracy/judgement.py``): every interval and the energy
    level against the prescribed ``E`` (the first interval's clock), then the trajectory against the
    exact flow's transfer near it (`shoot_transfer`); with none near, the transfer is
    ``inaccurate`` with that reason. Returns the report, the local errors and the shooting's
    figures."""
    clock = float(t[0] + (t[1] - t[0]) / 2 if scheme.clock == "midpoint" else t[0])
    z = np.hstack([q, p])
    report, local = assess(system, t, z, theta, tolerance, level=Level(span.energy, clock))
    exact = shoot_transfer(system, theta, t, q, p, span.energy)
    path = exact.pop("path")
    if report["verdict"] == "inaccurate":
        return report, local, exact
    if path is None:
        report["verdict"] = "inaccurate"
        report["first_failure"] = {
            "step": t.size - 2, "t": float(t[-2]), "test": "exact transfer", "value": None,
            "limit": tolerance.global_tol,
            "detail": (f"no transfer of the exact flow at energy {span.energy:.10g} was found "
                       f"near this one (shooting from its p_0 and transfer time: residual "
                       f"{exact['residual']:.2e} after {exact['iterations']} iterations)")}
        return report, local, exact
    report, local = assess(system, t, z, theta, tolerance, level=Level(span.energy, clock),
                           exact=lambda _: path)
    report = fixed_ends_report(report, t)  # both ends fixed: off the transfer, not drifted
    report["estimate"] = ("the exact flow's transfer near this one (shooting on p_0 and the "
                          f"transfer time {exact['transfer_time']:.12g})")
    return report, local, exact


def shoot_transfer(system, theta, t, q, p, energy: float) -> dict:
    """The exact flow's transfer near the grid: Newton on ``(p_0, T)`` for ``q(T) = q_end`` and
    ``H(q_start, p_0) = E`` (the exact flow with its variational equations; the one Newton on
    it, ``exact/flow_newton.py``, undamped), from the grid's ``p_0`` and transfer time; the
    differences of the transfer time and of the path at the grid's node times (largest over
    ``z``) and the exact path there (``path``, ``None`` unless the shooting converged; its
    residuals relative to the end positions' scale and the energy's).

    Newton stops at ``SHOOTING_STOP`` of those scales or where the flow fails, and the transfer
    counts as found at ``SHOOTING_ACCEPT``. Where ``SHOOTING_ITERATIONS`` evaluations do not
    reach the stop, one more step is taken and not evaluated: the transfer time and the path
    are then those of that step, accepted on the residual before it."""
    n = system.n
    q_start, q_end = q[0], q[-1]
    # Scales of the residuals from the problem, none from 1: positions by the end positions
    # and the distance between them, the energy by |E| (its round-off) and by H_p . p, the
    # energy a momentum of this size carries.
    span = max(float(np.max(np.abs(q_end - q_start))), float(np.max(np.abs(q_end))),
               float(np.max(np.abs(q_start))), np.finfo(float).tiny)

    def evaluate(x):  # x = (p_0, T)
        momentum, duration = x[:n], x[n]
        flow = flow_with_derivatives(system, theta, np.concatenate([q_start, momentum]),
                                     duration)
        H0, _, H_p, _ = derivatives_function(system)(q_start, momentum, 0.0, theta)
        residual = np.r_[flow.z[:n] - q_end, float(H0) - energy]
        scale = np.r_[np.full(n, span), max(abs(energy), float(np.abs(np.asarray(H_p).ravel())
                                                                @ np.abs(momentum)),
                                             np.finfo(float).tiny)]
        jacobian = np.vstack([np.hstack([flow.monodromy[:n, n:], flow.field[:n, None]]),
                              np.r_[np.asarray(H_p).ravel(), 0.0]])
        scaled = np.abs(residual) / scale
        return (scaled if flow.success else None), (residual, scaled, jacobian)

    def step(_x, _scaled, payload):
        return np.linalg.solve(payload[2], -payload[0])

    start = np.r_[p[0], float(t[-1] - t[0])]
    weights = np.r_[np.full(n, max(float(np.max(np.abs(p[0]))), np.finfo(float).tiny)),
                    start[n]]
    result = exact_newton(evaluate, step, start, size=lambda scaled: float(np.max(scaled)),
                          tolerance=SHOOTING_STOP, max_iterations=SHOOTING_ITERATIONS - 1,
                          step_size=lambda dx: _largest_ratio(dx, weights))
    residual, scaled, _ = result.payload
    x = result.x
    if not result.converged and not result.failed_evaluation:
        x = x + step(x, scaled, result.payload)
    momentum, duration = x[:n], (float(x[n]) if x is start else x[n])
    converged = bool(float(np.max(scaled)) <= SHOOTING_ACCEPT)
    path = flow_with_derivatives(system, theta, np.concatenate([q_start, momentum]), duration,
                                 times=np.clip(t - t[0], 0.0, duration)).path if converged \
        else None
    return {"converged": converged, "transfer_time": duration,
            "time_difference": float(t[-1] - t[0] - duration),
            "momentum": momentum.tolist(), "iterations": result.iterations,
            "residual": float(np.max(np.abs(residual))),
            "path_difference": None if path is None else float(
                np.max(np.abs(np.hstack([q, p]) - path))), "path": path}


def _largest_ratio(values, sizes) -> float:
    """The largest ``|v_i| / s_i`` (``inf`` past the largest float)."""
    with np.errstate(over="ignore"):
        return float(np.max(np.abs(values) / sizes))
