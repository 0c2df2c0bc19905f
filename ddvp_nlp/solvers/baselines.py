"""The schemes users would pick instead, run the same way as the march: compiled chunks of steps.

- Stormer-Verlet (leapfrog) for separable ``H = T(p) + V(q, t)``: the Strang splitting of the
  autonomous extended system (time advances with ``q``), order 2, symplectic::

      p_h = p_k - tau/2 V_q(q_k, t_k),   q_{k+1} = q_k + tau T_p(p_h),
      p_{k+1} = p_h - tau/2 V_q(q_{k+1}, t_k + tau).

- Classical Runge-Kutta (RK4) on ``z' = (H_p, -H_q)``, order 4, neither symplectic nor
  energy-conserving.
- T.D. Lee's original discretisation (THEORY.md section 2): for ``H = p.A p/2 + V(q, t)`` with a
  constant matrix ``A``, the left-point discrete Lagrangian
  ``L_d = tau_k [v_k.A^{-1} v_k/2 - V(q_k, t_k)]``, ``v_k = (q_{k+1} - q_k)/tau_k``. Each step
  solves the discrete Euler-Lagrange equation ``dS_D/dq_k = 0`` and the energy equation
  ``dS_D/dt_k = 0``, both taken from the two-interval action by automatic differentiation, for
  ``(v_k, tau_k)``. Order 1; it has no real step once a step overshoots a turning point.

The fixed-step methods are explicit; each chunk's steps are checked for finite values. Lee's
scheme is implicit (``fast_newton``); each of its steps is accepted only if finite, ``tau > 0``
and its own unscaled residuals are under ``tol``, exactly like a march step.
"""

from __future__ import annotations

import math
import time

import casadi as ca
import numpy as np

from ..cache import cached
from ..discrete.runge_kutta import rk4
from ..errors import InputError
from ..physics.hamiltonian import HamiltonianSystem, vector_field_function
from ..solution import Solution, Status, bound_reached
from .chunk import FAST_NEWTON_OPTIONS
from .compiler import cache_folder, compile_function

CHUNK = 1024


def chunk_for(steps: float) -> int:
    """Steps per compiled call for a run of about ``steps`` steps: the next power of two, between
    64 and 1024, so short runs do not pay for 1024 steps they throw away."""
    return int(min(CHUNK, max(64, 2 ** math.ceil(math.log2(max(steps, 1))))))


def separable_parts(system: HamiltonianSystem):
    """``(T_p, V_q)`` as functions if ``H = T(p) + V(q, t)``, else a reason string.

    Read off the expression: ``H_p`` must not depend on ``q`` or ``t``, ``H_q`` not on ``p``.
    """
    H_p = ca.gradient(system.H, system.p)
    H_q = ca.gradient(system.H, system.q)
    if ca.depends_on(H_p, ca.vertcat(system.q, system.t)):
        return "dH/dp depends on q or t, so H is not T(p) + V(q, t)"
    if ca.depends_on(H_q, system.p):
        return "dH/dq depends on p, so H is not T(p) + V(q, t)"
    return (ca.Function("T_p", [system.p, system.theta], [H_p]),
            ca.Function("V_q", [system.q, system.t, system.theta], [H_q]))


def quadratic_kinetic_matrix(system: HamiltonianSystem):
    """``A(theta)`` if ``H = p.A p/2 + V(q, t)`` with ``A`` constant in ``q, p, t``, else a reason
    string. Lee's original scheme needs the Lagrangian ``v.A^{-1} v/2 - V``."""
    parts = separable_parts(system)
    if isinstance(parts, str):
        return parts
    H_p = ca.gradient(system.H, system.p)
    A = ca.jacobian(H_p, system.p)
    if ca.depends_on(A, ca.vertcat(system.q, system.p, system.t)):
        return "H is not quadratic in p (d2H/dp2 is not constant)"
    if ca.depends_on(ca.substitute(H_p, system.p, ca.DM.zeros(system.n)),
                     ca.vertcat(system.q, system.t)) or \
            not ca.is_equal(ca.simplify(ca.substitute(H_p, system.p, ca.DM.zeros(system.n))),
                            ca.SX.zeros(system.n), 2):
        return "H has a term linear in p"
    return A


def stormer_verlet_step(system: HamiltonianSystem) -> ca.Function:
    """``(z, t, tau, theta) -> z_next`` by Stormer-Verlet; ``InputError`` if ``H`` is not
    separable."""
    def build():
        parts = separable_parts(system)
        if isinstance(parts, str):
            raise InputError(f"method 'stormer_verlet' needs a separable H on {system.name!r}: "
                             f"{parts}")
        T_p, V_q = parts
        n = system.n
        z, t, tau = ca.SX.sym("z", 2 * n), ca.SX.sym("t"), ca.SX.sym("tau")
        q, p = z[:n], z[n:]
        p_half = p - tau / 2 * V_q(q, t, system.theta)
        q_next = q + tau * T_p(p_half, system.theta)
        p_next = p_half - tau / 2 * V_q(q_next, t + tau, system.theta)
        return ca.Function("stormer_verlet", [z, t, tau, system.theta],
                           [ca.vertcat(q_next, p_next)])
    return cached(system, "stormer_verlet_step", build)


def rk4_step(system: HamiltonianSystem) -> ca.Function:
    """``(z, t, tau, theta) -> z_next`` by the classical Runge-Kutta method."""
    def build():
        field = vector_field_function(system)

        def flow(z, t):
            return field(z, t, system.theta)

        z, t, tau = ca.SX.sym("z", 2 * system.n), ca.SX.sym("t"), ca.SX.sym("tau")
        return ca.Function("rk4", [z, t, tau, system.theta], [rk4(flow, z, t, tau)])
    return cached(system, "rk4_step", build)


def _load(function: ca.Function, compiler, cache_dir):
    """``function`` compiled (cached) where a compiler is given, else as it is; and the seconds
    spent compiling."""
    if compiler is None:
        return function, 0.0
    started = time.perf_counter()
    return compile_function(function, compiler, cache_folder(cache_dir)), \
        time.perf_counter() - started


def _solution(t, z, n, status, message, scheme, timing, *, energy_residual=None,
              canonical_residual=None, stats=None):
    return Solution(t=t, q=z[:, :n].copy(), p=z[:, n:].copy(), status=status, message=message,
                    scheme=scheme,
                    energy_residual=np.zeros(0) if energy_residual is None else energy_residual,
                    canonical_residual=(np.zeros(0) if canonical_residual is None
                                        else canonical_residual),
                    timing=timing, stats=stats or {})


def _failure_message(status, k, t, z, n, detail=""):
    return (f"{status.value}: step {k} from t = {t:.10g}, q = {z[:n]}, p = {z[n:]}"
            + (f"; {detail}" if detail else ""))


def fixed_step_run(system: HamiltonianSystem, method: str, q0, p0, *, tau: float, t_end: float,
                   t0: float, theta, compiler, cache_dir=None,
                   time_limit: float | None = None) -> Solution:
    """March ``method`` (``"stormer_verlet"`` or ``"rk4"``) on uniform steps that end on
    ``t_end`` (the step is ``(t_end - t0)/ceil((t_end - t0)/tau)``); ``time_limit`` (seconds)
    is checked between chunks."""
    started = time.perf_counter()
    n = system.n
    total = max(1, math.ceil((t_end - t0) / tau - 1e-9))
    step_length = (t_end - t0) / total
    chunk = chunk_for(total)

    def build():
        step = {"stormer_verlet": stormer_verlet_step, "rk4": rk4_step}[method](system)
        state = ca.SX.sym("state", 1 + 2 * n)
        constants = ca.SX.sym("constants", system.theta.numel() + 2)
        theta, first, h = constants[:-2], constants[-2], constants[-1]
        k, z = state[0], state[1:]
        z_next = step(z, first + k * h, h, theta)
        one = ca.Function(f"{method}_step", [state, constants],
                          [ca.vertcat(k + 1, z_next), ca.vertcat(first + (k + 1) * h, z_next)])
        return _load(one.mapaccum(f"{method}_chunk", chunk), compiler, cache_dir)

    function, compile_s = cached(system, (method, chunk, compiler, str(cache_dir)), build)
    built = time.perf_counter()
    t = np.empty(total + 1)
    z = np.empty((total + 1, 2 * n))
    t[0], z[0] = t0, np.concatenate([q0, p0])
    constants = np.tile(np.concatenate([theta, [t0, step_length]])[:, None], (1, chunk))
    k = 0
    status, message = Status.SUCCESS, f"{Status.SUCCESS.value} = {t_end:.6g} in {total} steps"
    while k < total:
        if time_limit is not None and time.perf_counter() - built > time_limit:
            status = Status.TIME_LIMIT
            message = _failure_message(status, k, t[k], z[k], n, f"time_limit = {time_limit:g} s")
            break
        states, rows = function(np.concatenate([[k], z[k]]), constants)
        rows = np.asarray(rows).T[:min(chunk, total - k)]
        finite = np.all(np.isfinite(rows), axis=1)
        kept = int(np.argmin(finite)) if not finite.all() else rows.shape[0]
        t[k + 1:k + 1 + kept], z[k + 1:k + 1 + kept] = rows[:kept, 0], rows[:kept, 1:]
        k += kept
        if kept < rows.shape[0]:
            status = Status.NON_FINITE
            message = _failure_message(status, k, t[k], z[k], n)
            break
    t, z = t[:k + 1], z[:k + 1]
    if status is Status.SUCCESS:
        t[-1] = t_end  # k*h may differ from t_end by round-off
    solved = time.perf_counter()
    return _solution(t, z, n, status, message, method,
                     {"build_s": built - started, "solve_s": solved - built,
                      "compile_s": compile_s},
                     stats={"path": "vm" if compiler is None else "compiled"})


class _LeeLeftPoint:
    """Step functions of T.D. Lee's original left-point scheme (see the module docstring)."""

    def __init__(self, system: HamiltonianSystem):
        A = quadratic_kinetic_matrix(system)
        if isinstance(A, str):
            raise InputError(f"method 'lee_left' needs H = p.A p/2 + V(q, t) on "
                             f"{system.name!r}: {A}")
        n, theta = system.n, system.theta
        zero = ca.DM.zeros(n)
        potential = ca.Function("V", [system.q, system.t, theta],
                                [ca.substitute(system.H, system.p, zero)])
        A_function = ca.Function("A", [theta], [A])

        def interval_action(t_a, t_b, q_a, q_b):
            tau = t_b - t_a
            v = (q_b - q_a) / tau
            return tau * (ca.dot(v, ca.solve(A_function(theta), v)) / 2
                          - potential(q_a, t_a, theta))

        t0, t1, t2 = ca.SX.sym("t_prev"), ca.SX.sym("t_mid"), ca.SX.sym("t_next")
        q0, q1, q2 = ca.SX.sym("q_prev", n), ca.SX.sym("q_mid", n), ca.SX.sym("q_next", n)
        action = interval_action(t0, t1, q0, q1) + interval_action(t1, t2, q1, q2)
        euler_lagrange = ca.gradient(action, q1)
        energy = ca.gradient(action, t1)
        # Unknowns (v, tau) of the step: q_next = q_mid + tau v keeps both equations O(1) as
        # tau -> 0 (in q_next they carry 1/tau).
        v, tau = ca.SX.sym("v", n), ca.SX.sym("tau")
        x = ca.vertcat(v, tau)
        w = ca.vertcat(t0, t1, q0, q1, theta)
        g = ca.substitute(ca.vertcat(euler_lagrange, energy), ca.vertcat(q2, t2),
                          ca.vertcat(q1 + tau * v, t1 + tau))
        self.residual = ca.Function("lee_left_step", [x, w], [g])
        tau_prev = t1 - t0
        v_prev = (q1 - q0) / tau_prev
        V_q = ca.gradient(potential(q1, t1, theta), q1)
        guess = ca.vertcat(v_prev - tau_prev * ca.mtimes(A_function(theta), V_q), tau_prev)
        self.predict = ca.Function("lee_left_predict", [w], [guess])
        # Momentum at the new node, p_{k+1} = dS_k/dq_{k+1} = A^{-1} v_k.
        self.momentum = ca.Function("lee_left_momentum", [v, theta],
                                    [ca.solve(A_function(theta), v)])
        # First step from (q0, p0): p0 = -d(tau0 L_0)/dq_0, linear in v0, so one Newton step
        # from v0 = 0 solves it.
        p_start, tau0 = ca.SX.sym("p0", n), ca.SX.sym("tau0")
        first = ca.substitute(p_start + ca.gradient(interval_action(t0, t1, q0, q1), q0),
                              ca.vertcat(t1, q1), ca.vertcat(t0 + tau0, q0 + tau0 * v))
        start = ca.vertcat(t0, tau0, q0, p_start, theta)
        self.first_residual = ca.Function("lee_left_first_residual", [v, start], [first])
        v_first = ca.substitute(-ca.solve(ca.jacobian(first, v), first), v, zero)
        self.first_velocity = ca.Function("lee_left_first", [start], [v_first])
        self.node_energy = ca.Function(
            "lee_left_energy", [v, q0, t0, theta],
            [ca.dot(v, ca.solve(A_function(theta), v)) / 2 + potential(q0, t0, theta)])


def lee_left_march(system: HamiltonianSystem, q0, p0, *, tau0: float, t_end: float, t0: float,
                   theta, tol: float = 1e-10, max_steps: int = 10_000_000, compiler=None,
                   cache_dir=None, time_limit: float | None = None) -> Solution:
    """March T.D. Lee's original left-point scheme until the first node at or past ``t_end``."""
    started = time.perf_counter()
    n = system.n
    functions = cached(system, "lee_left", lambda: _LeeLeftPoint(system))
    chunk = chunk_for((t_end - t0) / tau0)

    def build():
        size = 2 + 2 * n
        state = ca.SX.sym("state", size)
        theta_symbol = ca.SX.sym("theta", system.theta.numel())
        w = ca.vertcat(state, theta_symbol)
        newton = ca.rootfinder("lee_left_newton", "fast_newton", functions.residual,
                               FAST_NEWTON_OPTIONS)
        x = newton(functions.predict(w), w)
        v, tau = x[:n], x[n]
        t_mid, q_mid = state[1], state[2 + n:]
        q_next = q_mid + tau * v
        residual = functions.residual(x, w)
        row = ca.vertcat(t_mid + tau, q_next, functions.momentum(v, theta_symbol),
                         ca.norm_inf(residual[:n]), residual[n],
                         ca.norm_inf(q_mid), ca.fabs(functions.node_energy(v, q_mid, t_mid,
                                                                           theta_symbol)))
        one = ca.Function("lee_left_step", [state, theta_symbol],
                          [ca.vertcat(t_mid, t_mid + tau, q_mid, q_next), row])
        return _load(one.mapaccum("lee_left_chunk", chunk), compiler, cache_dir)

    function, compile_s = cached(system, ("lee_left", chunk, compiler, str(cache_dir)), build)
    built = time.perf_counter()
    start = np.concatenate([[t0, tau0], q0, p0, theta])
    v0 = np.asarray(functions.first_velocity(start)).ravel()
    q1 = q0 + tau0 * v0
    p1 = np.asarray(functions.momentum(v0, theta)).ravel()
    first_residual = float(np.max(np.abs(np.asarray(functions.first_residual(v0, start)))))
    t_list = [np.array([t0, t0 + tau0])]
    z_list = [np.array([np.concatenate([q0, p0]), np.concatenate([q1, p1])])]
    euler_lagrange, energy = [np.array([first_residual])], [np.zeros(0)]
    state = np.concatenate([[t0, t0 + tau0], q0, q1])
    thetas = np.tile(np.asarray(theta, float)[:, None], (1, chunk))
    count, status, detail = 1, Status.SUCCESS, ""
    if not np.all(np.isfinite(z_list[0])):
        status = Status.NON_FINITE
    while status is Status.SUCCESS and state[1] < t_end:
        reached = bound_reached(count, max_steps, built, time_limit)
        if reached:
            status, detail = reached
            break
        states, rows = function(state, thetas)
        states, rows = np.asarray(states).T, np.asarray(rows).T
        t_next, z_next = rows[:, 0], rows[:, 1:1 + 2 * n]
        el, en, size, E = (rows[:, 1 + 2 * n + i] for i in range(4))
        t_mid = np.concatenate([[state[1]], t_next[:-1]])
        with np.errstate(invalid="ignore"):
            good = (np.all(np.isfinite(rows), axis=1) & (t_next > t_mid)
                    & (el <= tol * np.maximum(1.0, size)) & (np.abs(en) <= tol * np.maximum(1, E)))
        limit = min(chunk, max_steps - count)
        ends = np.flatnonzero(t_next >= t_end)
        if ends.size:
            limit = min(limit, int(ends[0]) + 1)
        bad = np.flatnonzero(~good[:limit])
        kept = int(bad[0]) if bad.size else limit
        t_list.append(t_next[:kept])
        z_list.append(z_next[:kept])
        euler_lagrange.append(el[:kept])
        energy.append(en[:kept])
        count += kept
        if kept:
            state = states[kept - 1]
        if bad.size:
            i = int(bad[0])
            if not np.all(np.isfinite(rows[i])):
                status, detail = Status.NON_FINITE, ""
            elif t_next[i] <= t_mid[i]:
                status, detail = Status.NO_ADMISSIBLE_STEP, (
                    f"Newton from the previous step found tau = {t_next[i] - t_mid[i]:.6g}")
            else:
                status, detail = Status.NEWTON_FAILED, (
                    f"Euler-Lagrange residual {el[i]:.3e}, energy residual {en[i]:.3e}")
    t = np.concatenate(t_list)
    z = np.concatenate(z_list)
    if status is Status.SUCCESS:
        message = f"{status.value} = {t_end:.6g} in {t.size - 1} steps"
    else:
        message = _failure_message(status, t.size - 1, t[-1], z[-1], n, detail)
    solved = time.perf_counter()
    return _solution(t, z, n, status, message, "lee_left",
                     {"build_s": built - started, "solve_s": solved - built,
                      "compile_s": compile_s},
                     energy_residual=np.concatenate(energy),
                     canonical_residual=np.concatenate(euler_lagrange),
                     stats={"path": "vm" if compiler is None else "compiled"})
