"""One step of a constrained march as CasADi functions, and the chunk that repeats it.

The step equations are those of ``discrete/constrained.py``. Unknowns and parameters:

- *fixed-length* step (every step of ``fixed``, step 0 of the energy rules): ``x = [z_b,
  lambda, mu]`` (``2n + 2m``): the ``2n`` interval rows and the ``2m`` node rows at ``b``;
- *energy* step: ``x = [z_{k+1}, lambda_k, mu_k, tau_k]`` (``2n + 2m + 1``): the same rows and
  the energy row at node ``k`` (divided by ``max(tau_{k-1} |E_{k-1}|, |p_k . (q_k - q_{k-1})|)``,
  with the drift of the accepted energy residuals added so that their sum stays at round-off).
  The acceptance test (`ConstrainedChunk`) holds each kind of row under ``tol`` times the
  magnitudes it is computed from, no floor of 1: the interval rows under ``max(|z_a|, |z_b|)``,
  the constraint and hidden rows under `_row_scales`, the energy residual under ``max(|E_k|,
  |p_b . (q_b - q_a)| / tau)`` (twice the kinetic energy, which does not vanish where ``E_k``
  does).

Newton (`newton_function`) runs as a chain of conditional calls (a step pays for the
iterations it takes) and returns the number of updates it made. Each update solves the
Jacobian as a bordered system: the block of ``(z, lambda, mu)`` by a sparse QR (CasADi's
``qr``, whose column order keeps a chain's band), the ``tau`` border by its Schur complement
(two right-hand sides, one factorisation): the cost of a chain of links grows with the links,
not their cube. It stops where the residual is at most ``StepControl.tol / 1e4`` (relative to
``|x|``) or an update at most ``tol / 1e2`` (1e-14 and 1e-12 at the default ``tol``),
read at run time: a study of the energy error against the Newton tolerance sets ``tol``. The
chunk (`ConstrainedChunk`) repeats one step with its predictor (RK4 on the constrained field
with the multipliers by a sparse QR at run time, the previous multipliers) and its acceptance
test ``chunk`` times per call (``mapaccum``), compiled where a C compiler is found; a step that
fails its test freezes the rest of the chunk, and the march (``constrained_march.py``) retries
it from other step guesses.
"""

from __future__ import annotations

import copy
import time

import casadi as ca
import numpy as np

from ...cache import cached
from ...discrete import constrained as equations
from ...discrete.runge_kutta import rk4
from ...physics.constraints import constraint_function
from ..compiler import CompileUnavailable, FunctionBuffer, cache_folder, compile_function, warn_once

__all__ = ["ConstrainedChunk", "constrained_chunk", "newton_function"]

MAX_ITER = 12
ABSTOL = 1e-14  # Newton's residual test, relative to |x| (NEWTON_OPTIONS' abstol)
STEP_TOL = 1e-12  # the update's test, relative to |x|: the next iterate is at round-off
# in a march, the two tests follow the acceptance tolerance ``StepControl.tol`` (a step's
# residuals at most ``tol``): the residual's at ``tol / RESIDUAL_SHARE``, the update's at
# ``tol / UPDATE_SHARE``; at the default ``tol = 1e-10`` they are ABSTOL and STEP_TOL
RESIDUAL_SHARE, UPDATE_SHARE = 1e4, 1e2
# the step's SX functions merge their common subexpressions (the energy row repeats the
# interval momenta and the constraints' Jacobians; the same values, computed once): the
# chunk's C code shrinks by a third and the compiler's time with it
SX_OPTIONS = {"cse": True}
DBL_MIN = float(np.finfo(float).tiny)


def step_residual(system, scheme, kind: str) -> ca.Function:
    """``R(x, w)`` of one step of ``kind`` (module docstring); ``w = [t_prev, t_a, z_prev, z_a,
    lam_prev, mu_prev, theta, drift]`` for an energy step, ``[t_a, t_b, z_a, theta]`` for a
    fixed one."""
    n, m, theta = system.n, system.n_constraints, system.theta
    z_a = ca.SX.sym("z_a", 2 * n)
    z_b = ca.SX.sym("z_b", 2 * n)
    lam, mu = ca.SX.sym("lam", m), ca.SX.sym("mu", m)
    if kind == "fixed":
        t_a, t_b = ca.SX.sym("t_a"), ca.SX.sym("t_b")
        x, w = ca.vertcat(z_b, lam, mu), ca.vertcat(t_a, t_b, z_a, theta)
    else:
        t_prev, t_a, tau = ca.SX.sym("t_prev"), ca.SX.sym("t_a"), ca.SX.sym("tau")
        z_prev, drift = ca.SX.sym("z_prev", 2 * n), ca.SX.sym("drift")
        lam0, mu0 = ca.SX.sym("lam_prev", m), ca.SX.sym("mu_prev", m)
        t_b = t_a + tau
        x = ca.vertcat(z_b, lam, mu, tau)
        w = ca.vertcat(t_prev, t_a, z_prev, z_a, lam0, mu0, theta, drift)
    rows = [equations.interval_expression(system, scheme, t_a, t_b, z_a[:n], z_a[n:], z_b[:n],
                                          z_b[n:], lam, mu, theta),
            equations.node_expression(system, z_b[:n], z_b[n:], t_b, theta)]
    scale = ca.SX(1)
    if kind == "energy":
        energy = equations.energy_expression(
            system, scheme, scheme.rule,
            (t_prev, t_a, t_b, z_prev[:n], z_prev[n:], z_a[:n], z_a[n:], z_b[:n], z_b[n:]),
            (lam0, mu0, lam, mu), theta)
        # the row's round-off is that of the energies (a chain of N links: |H| ~ N^2), and
        # its derivative in tau is O(tau): divided by both, Newton's tests read it like the
        # other rows
        previous = equations.interval_energy_expression(
            system, scheme, t_prev, t_a, z_prev[:n], z_prev[n:], z_a[:n], z_a[n:], lam0, mu0,
            theta)
        # (no floor of 1: |E_{k-1}| joined with |p_k . dq| of the previous interval, tau times
        # twice its kinetic energy, which does not vanish where E does; DBL_MIN only at rest)
        scale = ca.fmax((t_a - t_prev) * ca.fabs(previous),
                        ca.fmax(ca.fabs(ca.dot(z_a[n:], z_a[:n] - z_prev[:n])), DBL_MIN))
        rows.append((energy + drift) / scale)
    return ca.Function(f"constrained_{kind}_residual", [x, w], [ca.vertcat(*rows), scale],
                       SX_OPTIONS)


def newton_function(residual: ca.Function, border: int, *,
                    tolerance_input: bool = False) -> ca.Function:
    """``(x0, w) -> (x, updates)``: Newton on ``residual`` from ``x0``, at most ``MAX_ITER``
    updates, stopping where ``|R|_inf <= ABSTOL |x|_inf`` or an update is below
    ``STEP_TOL |x|_inf``; each update by a sparse QR of the leading block and the Schur
    complement of the last ``border`` unknowns (0 or 1). With ``tolerance_input``: ``(x0, w,
    tol) -> (x, updates)``, the tests at ``tol / RESIDUAL_SHARE`` and ``tol / UPDATE_SHARE``."""
    x, w = residual.sx_in()
    R = residual.call([x, w])[0]
    size = x.numel()
    lead = size - border
    J = ca.jacobian(R, x)
    extra = 1 if tolerance_input else 0
    # the chain below carries [w, tol] (``carried``): each step of it reads w from it
    xm, gm = ca.MX.sym("x", size), ca.MX.sym("g", size)
    carried = ca.MX.sym("w", w.numel() + extra)
    wm = carried[:w.numel()]
    abstol, step_tol = (carried[-1] / RESIDUAL_SHARE, carried[-1] / UPDATE_SHARE) \
        if tolerance_input else (ABSTOL, STEP_TOL)
    # the residual's round-off grows with the size of the unknowns (a chain of 50 links: its
    # far end at 50, its tensions near 25), so the test is relative to it; a call of
    # ``residual`` (its code once in the chunk, shared with the step's check)
    R_m = residual(xm, wm)[0]
    test = ca.Function("test", [xm, carried],
                       [R_m, ca.norm_inf(R_m) <= abstol * ca.norm_inf(xm)])
    if border:
        blocks = ca.Function("blocks", [x, w], [J[:lead, :lead], J[:lead, lead:],
                                                J[lead:, :lead], J[lead:, lead:]],
                             SX_OPTIONS)
        A, b, c, d = blocks(xm, wm)
        solved = ca.solve(A, ca.horzcat(gm[:lead], b), "qr")
        u, v = solved[:, 0], solved[:, 1]
        d_tau = (gm[lead:] - ca.mtimes(c, u)) / (d - ca.mtimes(c, v))
        dx = ca.vertcat(u - v * d_tau, d_tau)
    else:
        jacobian = ca.Function("jacobian", [x, w], [J], SX_OPTIONS)
        dx = ca.solve(jacobian(xm, wm), gm, "qr")
    x_next = xm - dx
    small_step = ca.norm_inf(dx) <= step_tol * ca.norm_inf(xm)
    update = ca.Function("update", [xm, carried, gm], [x_next, small_step])
    level = ca.Function("final", [xm, carried], [xm, MAX_ITER])
    for k in range(MAX_ITER, 0, -1):
        stop_after = ca.Function(f"stop{k}", [xm, carried], [xm, k])
        new, small = update(xm, carried, gm)
        after = ca.Function.if_else(f"after{k}", stop_after, level)
        go_on = ca.Function(f"go_on{k}", [xm, carried, gm], after.call([small, new, carried]))
        done = ca.Function(f"done{k}", [xm, carried, gm], [xm, k - 1])
        branch = ca.Function.if_else(f"branch{k}", done, go_on)
        g_k, converged = test(xm, carried)
        level = ca.Function(f"iteration{k}", [xm, carried],
                            branch.call([converged, xm, carried, g_k]))
    x0, w_in, tol_in = ca.MX.sym("x0", size), ca.MX.sym("w", w.numel()), ca.MX.sym("tol")
    inputs = [x0, w_in, tol_in] if tolerance_input else [x0, w_in]
    solved, updates = level.call([x0, ca.vertcat(w_in, tol_in) if tolerance_input else w_in])
    return ca.Function("constrained_newton", inputs, [solved, updates],
                       {"never_inline": True})


class ConstrainedChunk:
    """``chunk`` steps of one kind per call (module docstring), compiled with ``compiler``
    (a path, or ``None``: CasADi's virtual machine).

    Energy kind: state ``[t_prev, t_a, z_prev, z_a, lam_prev, mu_prev, drift, alive]``,
    constants ``[theta, tol, tau_factor]``. Fixed kind: state ``[k, z_a, lam_prev, mu_prev,
    alive]``, constants ``[t0, h, t_end, total, theta, tol]``. Each step's output row:
    ``[t_b, z_b, lam, mu, tau, updates, canonical, constraint, hidden, energy, H_k, size,
    good]``."""

    def __init__(self, system, scheme, kind: str, *, chunk: int, compiler, cache_dir):
        started = time.perf_counter()
        self.n, self.m, self.kind = system.n, system.n_constraints, kind
        residual = step_residual(system, scheme, kind)
        self.newton = self._build_newton(system, scheme, kind, residual)
        self.check = self._check(system, scheme, kind, residual)
        self.field = equations.constrained_field_sparse_function(system)
        step = self._step(system, kind)
        self.step = step
        self.width = step.numel_out(1)
        function = step.mapaccum("constrained_chunk", chunk)
        self.chunk, self.path, self.compile_s = chunk, "vm", 0.0
        if compiler is not None:
            compiled_at = time.perf_counter()
            try:
                function = compile_function(function, compiler, cache_folder(cache_dir),
                                            prefix="constrained")
                self.path = "compiled"
            except CompileUnavailable as exc:
                warn_once(exc)
            self.compile_s = time.perf_counter() - compiled_at
        self.function = function
        self._buffer = FunctionBuffer(function)
        self.build_s = time.perf_counter() - started

    def _build_newton(self, system, scheme, kind, residual) -> ca.Function:
        """The step's Newton (`newton_function` on the multiplier form; the null-space form,
        ``null_space_steps.py``, builds its own)."""
        return newton_function(residual, 1 if kind == "energy" else 0, tolerance_input=True)

    def _solve(self, x0, w, tol, kind):
        """``(x, updates)``: the step's unknowns ``[z_b, lam, mu(, tau)]`` from the guess
        ``x0`` (the null-space form solves its reduced rows and recovers them)."""
        return self.newton(x0, w, tol)

    @staticmethod
    def _check(system, scheme, kind, residual) -> ca.Function:
        """``(x, w) -> (canonical, constraint, hidden, energy, H_k, size)``: the step's
        unscaled residuals (the energy row without its scaling and drift) and the scales;
        ``residual`` is called, not copied (its code once in the chunk)."""
        n, m, theta = system.n, system.n_constraints, system.theta
        x, w = residual.sx_in()
        if kind == "fixed":
            t_a, t_b, z_a = w[0], w[1], w[2:2 + 2 * n]
        else:
            t_a, z_a = w[1], w[2 + 2 * n:2 + 4 * n]
            t_b = t_a + x[-1]
        z_b, lam, mu = x[:2 * n], x[2 * n:2 * n + m], x[2 * n + m:2 * n + 2 * m]
        H_k = equations.interval_energy_expression(system, scheme, t_a, t_b, z_a[:n], z_a[n:],
                                                   z_b[:n], z_b[n:], lam, mu, theta)
        energy_scale = ca.Function("interval_energy", [x, w], [
            ca.fabs(H_k), ca.fmax(ca.norm_inf(z_a), ca.norm_inf(z_b))], SX_OPTIONS)
        xm, wm = ca.MX.sym("x", x.numel()), ca.MX.sym("w", w.numel())
        R, scale = residual(xm, wm)
        energy = R[-1] * scale - wm[-1] if kind == "energy" else ca.MX(0)
        return ca.Function("check", [xm, wm], [
            ca.norm_inf(R[:2 * n]), ca.norm_inf(R[2 * n:2 * n + m]),
            ca.norm_inf(R[2 * n + m:2 * n + 2 * m]), energy, *energy_scale(xm, wm)])

    def _step(self, system, kind) -> ca.Function:
        n, m = self.n, self.m
        p = system.theta.numel()
        theta = ca.MX.sym("theta", p)
        if kind == "energy":
            state = ca.MX.sym("state", 4 * n + 2 * m + 4)
            t_prev, t_a = state[0], state[1]
            z_prev, z_a = state[2:2 + 2 * n], state[2 + 2 * n:2 + 4 * n]
            lam0 = state[2 + 4 * n:2 + 4 * n + m]
            mu0 = state[2 + 4 * n + m:2 + 4 * n + 2 * m]
            drift, alive = state[-2], state[-1]
            constants = ca.MX.sym("constants", p + 2)
            theta, tol, factor = constants[:p], constants[p], constants[p + 1]
            tau_guess = factor * (t_a - t_prev)
            z_guess = rk4(lambda z, t: self.field(z, t, theta), z_a, t_a, tau_guess)
            w = ca.vertcat(t_prev, t_a, z_prev, z_a, lam0, mu0, theta, drift)
            x, updates = self._solve(ca.vertcat(z_guess, lam0, mu0, tau_guess), w, tol, kind)
            tau = x[-1]
            t_b = t_a + tau
        else:
            state = ca.MX.sym("state", 2 * n + 2 * m + 2)
            k, z_a = state[0], state[1:1 + 2 * n]
            lam0, mu0 = state[1 + 2 * n:1 + 2 * n + m], state[1 + 2 * n + m:1 + 2 * n + 2 * m]
            alive = state[-1]
            constants = ca.MX.sym("constants", p + 5)
            t0, h, t_end, total = constants[0], constants[1], constants[2], constants[3]
            theta, tol = constants[4:4 + p], constants[4 + p]
            t_a = t0 + k * h
            t_b = ca.if_else(k + 1 >= total, t_end, t0 + (k + 1) * h)
            tau = t_b - t_a
            z_guess = rk4(lambda z, t: self.field(z, t, theta), z_a, t_a, tau)
            w = ca.vertcat(t_a, t_b, z_a, theta)
            x, updates = self._solve(ca.vertcat(z_guess, lam0, mu0), w, tol, kind)
        z_b, lam, mu = x[:2 * n], x[2 * n:2 * n + m], x[2 * n + m:2 * n + 2 * m]
        canonical, constraint, hidden, energy, H_k, size = self.check(x, w)
        scale = size  # max(|z_a|, |z_b|): the step's own state, its motion included
        constraint_scale, hidden_scale = _row_scales(system, z_a, z_b, t_b, tau, theta)
        # |sum| <= DBL_MAX is false for a NaN or an infinity anywhere in x
        finite = ca.fabs(ca.sum1(x)) <= np.finfo(float).max
        good = ca.logic_and(alive, finite)
        good = ca.logic_and(good, tau > 0)
        good = ca.logic_and(good, canonical <= tol * scale)
        good = ca.logic_and(good, constraint <= tol * constraint_scale)
        good = ca.logic_and(good, hidden <= tol * hidden_scale)
        kinetic = ca.fabs(ca.dot(z_b[n:], z_b[:n] - z_a[:n]) / tau)  # |p . H_p|: 2T
        good = ca.logic_and(good, ca.fabs(energy) <= tol * ca.fmax(H_k, kinetic))
        if kind == "energy":
            after = ca.vertcat(t_a, t_b, z_a, z_b, lam, mu, drift + energy, 1)
        else:
            after = ca.vertcat(k + 1, z_b, lam, mu, 1)
        frozen = ca.vertcat(state[:-1], 0)
        out = ca.vertcat(t_b, z_b, lam, mu, tau, updates, canonical, constraint, hidden,
                         energy, H_k, size, good)
        return ca.Function(f"constrained_{kind}_step", [state, constants],
                           [ca.if_else(good, after, frozen), out])

    def __call__(self, state: np.ndarray, constants: np.ndarray) -> np.ndarray:
        """The output rows ``(chunk, width)`` of one call from ``state``; the rows after the
        first bad one are not steps."""
        try:
            outputs = self._buffer(state, np.tile(constants, self.chunk))
        except RuntimeError:  # a linear solve inside a step failed: no row is a step
            return np.tile(self._no_step(), (self.chunk, 1))
        return outputs[1].reshape(self.chunk, self.width).copy()

    def one(self, state: np.ndarray, constants: np.ndarray) -> np.ndarray:
        """One step on the virtual machine (a retry, a first step)."""
        try:
            return np.asarray(self.step(state, constants)[1], float).ravel()
        except RuntimeError:  # e.g. the null-space form's QR solves on a NaN iterate
            return self._no_step()

    def _no_step(self) -> np.ndarray:
        """The row of a step whose evaluation failed (a linear solve on non-finite or
        singular input raises where the multiplier form's gives NaN): non-finite, not good,
        so the march retries it, then ends with the non-finite status."""
        row = np.full(self.width, np.nan)
        row[-1] = 0.0
        return row


def _row_scales(system, z_a, z_b, t_b, tau, theta):
    """The magnitudes the constraint rows at ``b`` are computed from (no floor of 1 in the units
    of the state): ``g``'s against ``max_i sum_j |G_ij q_j|`` (for ``|q|^2 - L^2`` that is
    ``2 |q|^2``; it grows with a translation whose round-off ``g`` carries), the hidden rows
    ``G H_p + g_t`` (a velocity) against ``max_i sum_j |G_ij v_j| + |g_t,i|`` with ``v`` the
    step's mean velocity ``(q_b - q_a) / tau``."""
    n = system.n
    _, G, g_t = constraint_function(system)(z_b[:n], t_b, theta)
    velocity = (z_b[:n] - z_a[:n]) / tau
    terms = ca.mtimes(ca.fabs(G), ca.fabs(z_b[:n]))
    motion = ca.mtimes(ca.fabs(G), ca.fabs(velocity)) + ca.fabs(g_t)
    return ca.mmax(terms), ca.mmax(motion)


def constrained_chunk(system, scheme, kind: str, *, chunk: int, compiler, cache_dir,
                      chunk_class=ConstrainedChunk) -> ConstrainedChunk:
    """The ``chunk_class`` chunk of ``kind``, built once per system, scheme, size, compiler and
    cache folder: a later march of the same system reuses it (at 128 links a march had spent
    about 20 s CPU rebuilding its chunks, against 0.6 s for 1000 steps). A reused chunk
    reports no build or compile time (a shallow copy with them at 0)."""
    fresh = []

    def build():
        fresh.append(True)
        return chunk_class(system, scheme, kind, chunk=chunk, compiler=compiler,
                           cache_dir=cache_dir)
    found = cached(system, ("constrained_chunk", chunk_class.__name__, scheme, kind, chunk,
                            compiler, str(cache_dir)), build)
    if fresh:
        return found
    reused = copy.copy(found)
    reused.build_s = reused.compile_s = 0.0
    return reused
