"""The exact flow ``z' = f(z, t)`` over a whole span by adaptive DOP853 (``attempt.py``), with
error control and dense output: ``slots`` attempted steps per call of one compiled CasADi
Function; Python calls it until ``t_end``, once per chunk of attempts, never once per step or
per node, so its work follows the motion, not the number of nodes it is read at.

The vector field is Hamilton's ``(H_p, -H_q)`` for a system with ``H`` (or a first-order
``L``), the Euler-Lagrange equation in Ostrogradsky's variables for a higher-order ``L``
(`flow_field`); a flow is built once per system, compiler and shape (`exact_flow`, cached on
the system), and compiled when that pays: loaded at once from the compiled-code cache, else run
by CasADi's virtual machine until its calls have cost about half a compile, summed over the
processes that ran it (a short check of a new system never waits for gcc; once short checks
together have paid that much, the next one compiles it; ``compiler.RentedBuffer``).

Measured against scipy's DOP853 (the same tableau, estimator and controller, in Python) at
``rtol`` 1e-10: the same steps, 114 (Kepler), 218 (Henon-Heiles) and 275 (the paper's pendulum
to t = 10^4) times less CPU; CasADi's virtual machine, where there is no compiler, is 5 to 13
times slower than the compiled chunk and computes the same steps bit for bit.
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from ...cache import cached
from ...physics import HigherOrderSystem, euler_lagrange_field, vector_field_function
from ..compiler import FunctionBuffer, RentedBuffer
from .attempt import DONE, FAILED, POWER, RUNNING, AttemptLayout, augmented_field, chunk_function
from .kernel import kernel as check_kernel
from .trajectory import Trajectory

SLOTS = 1024  # attempted steps per call (a finished chunk's slots cost a copy each)
MAX_ATTEMPTS = 10_000_000
# Largest field (with its tangent columns; CasADi instructions) whose 16 evaluations are written
# out in one SX expression (measured: FPU m = 3 with its 12 tangent columns, 881 instructions,
# inlined: 1.4 MB of C, gcc 14.6 s, 72 us an attempt; called from MX: 156 kB, 3.1 s, 60 us).
# A larger one is called as a function from an MX step.
INLINE_LIMIT = 500
# A run likely to end within this share of a call's slots makes its last attempts in calls of a
# flow with fewer slots, where it has one (`AdaptiveFlow.run`'s ``tail``). Measured: a call of 64
# costs about 4 us besides its attempts, a slot past the run's end in a call of 1024 0.12 us
# (Henon-Heiles) to 0.7 us (16-site lattice): the small calls pay from about 650 attempts left
# on Henon-Heiles, from about 950 on the lattice.
TAIL_SHARE = 0.6


def flow_field(system) -> tuple[ca.Function, int]:
    """The exact flow's vector field ``(z, t, theta) -> z'`` and the size of ``z``: Hamilton's
    equations ``(H_p, -H_q)`` for a system with ``H`` (or a first-order ``L``), the
    Euler-Lagrange equation in Ostrogradsky's variables for a higher-order ``L``."""
    if isinstance(system, HigherOrderSystem):
        return euler_lagrange_field(system), 2 * system.order * system.n
    if getattr(system, "n_constraints", 0) > 0:  # index-reduced, with its constraint forces
        from .constrained_flow import constrained_field
        return constrained_field(system), 2 * system.n
    return vector_field_function(system), 2 * system.n


class AdaptiveFlow:
    """The exact flow of ``field(z, t, theta) -> z'`` (a CasADi Function of SX) by adaptive
    DOP853, optionally with ``tangent`` columns of the variational equations and the dense
    output (module docstring)."""

    def __init__(self, field: ca.Function, *, tangent: int = 0, dense: bool = True,
                 slots: int = SLOTS, compiler: str | None = "auto", cache_dir=None,
                 inline: bool | None = None, tangent_control: bool = False,
                 project: ca.Function | None = None):
        self.field = field
        d, p = field.size1_in(0), field.size1_in(2)
        self.layout = AttemptLayout(d=d, m=int(tangent), p=p, dense=dense,
                             tangent_control=tangent_control)
        self.slots = int(slots)
        self.compiler, self.cache_dir = compiler, cache_dir
        self._kernel = None  # the compiled reading of the dense output, once found
        started = time.perf_counter()
        if inline is None:  # write the stages out unless the field with its tangents is large
            inline = augmented_field(field, self.layout.m).n_instructions() <= INLINE_LIMIT
        if project is not None and tangent:
            raise ValueError("a projected flow carries no tangent columns")
        symbolic = chunk_function(field, self.layout, self.slots, inline=inline,
                                  project=project)
        self.build_s = time.perf_counter() - started
        # compiled when in the cache, else once its calls have cost a compile (RentedBuffer)
        self._buffer = RentedBuffer(symbolic, compiler, cache_dir, prefix="exact")
        self._field_buffer = FunctionBuffer(field)
        self._tangent_buffer = FunctionBuffer(augmented_field(field, self.layout.m))

    @property
    def compiled(self) -> bool:
        """Whether the chunk runs compiled now (it may start in the virtual machine)."""
        return self._buffer.compiled

    @property
    def chunk(self) -> RentedBuffer:
        """The compiled call of ``slots`` attempts (a `RentedBuffer`)."""
        return self._buffer

    def buy(self) -> None:
        """Compile the chunk now (a flow of the same system has paid the rent)."""
        self._buffer.buy()

    def kernel(self):
        """The compiled reading of the dense output (``kernel.py``) for the runs of this flow:
        loaded from the cache, or built once this flow's chunk is compiled (its rent paid by
        the runs before); ``None`` until then, and without a compiler (numpy: the same
        numbers)."""
        if self._kernel is None and self.layout.dense:
            self._kernel = check_kernel(self.compiler, self.cache_dir, build=self.compiled)
        return self._kernel

    def initial_step(self, z0, t0, t_end, theta, rtol, atol) -> float:
        """Hairer's starting step (scipy's ``select_initial_step``, order 7), on ``z``."""
        def f(z, t):
            return self._field_buffer(z, t, theta)[0][0].copy()
        interval = abs(t_end - t0)
        direction = np.sign(t_end - t0)
        f0 = f(z0, t0)
        scale = atol + np.abs(z0) * rtol
        d0, d1 = _rms(z0 / scale), _rms(f0 / scale)
        h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        h0 = min(h0, interval)
        if not h0 > 0:  # a scale of zero somewhere: start small, the controller grows it
            return 1e-6 * interval
        f1 = f(z0 + h0 * direction * f0, t0 + h0 * direction)
        d2 = _rms((f1 - f0) / scale) / h0
        h1 = max(1e-6, h0 * 1e-3) if d1 <= 1e-15 and d2 <= 1e-15 else \
            (0.01 / max(d1, d2)) ** (1 / 8)
        return min(100 * h0, h1, interval)

    def run(self, z0, t0: float, t_end: float, theta=(), *, rtol: float = 1e-10,
            atol=None, Y0=None, h0: float | None = None, h_max: float = np.inf,
            max_attempts: int = MAX_ATTEMPTS, tail: AdaptiveFlow | None = None) -> Trajectory:
        """The flow from ``z0`` at ``t0`` to ``t_end`` (either direction). ``atol`` (scalar or
        per component of ``z``; default ``rtol``) and ``rtol`` bound each step's error
        estimate as in scipy. ``Y0`` (d x m): the tangent's start (default the identity's
        first m columns). ``tail``: the same flow with fewer slots a call (a divisor of
        ``slots``), whose calls make the run's last attempts once it is likely to end within
        `TAIL_SHARE` of a call (`_ends_soon`): a call of ``slots`` costs every slot after the
        run's end (0.12 us each on Henon-Heiles, 0.7 on a 16-site lattice). The same attempts,
        bit for bit (a run is the same attempts whatever the calls it is cut into), and as
        many: the run stops after ``max_attempts`` rounded up to whole calls of ``slots``, as
        without it."""
        L = self.layout
        z0 = np.asarray(z0, float).reshape(L.d)
        theta = np.asarray(theta, float).reshape(L.p)
        atol = np.broadcast_to(np.asarray(rtol if atol is None else atol, float), (L.d,))
        if L.m:
            Y0 = np.eye(L.d)[:, :L.m] if Y0 is None else np.asarray(Y0, float).reshape(L.d, L.m)
            w0 = np.concatenate([z0, Y0.ravel(order="F")])
        else:
            w0 = z0
        t0, t_end = float(t0), float(t_end)
        if t0 == t_end:
            return self._empty(t0, w0)
        with np.errstate(all="ignore"):  # a start where f is not finite fails in the chunk
            if h0 is None:
                h0 = self.initial_step(z0, t0, t_end, theta, rtol, atol)
            if not np.isfinite(h0) or h0 <= 0:
                h0 = abs(t_end - t0)
        f0 = self._tangent_buffer(w0, t0, theta)[0][0].copy()
        state = np.concatenate([[t0, np.sign(t_end - t0) * h0, RUNNING, 0.0], w0, f0])
        params = np.concatenate([[t_end, h_max, rtol], atol, theta])
        self._buffer.inputs[1][:] = params  # every slot's column of parameters: once a run
        if tail is not None and (tail.slots >= self.slots or self.slots % tail.slots or
                                 tail.layout != L):
            tail = None
        # the attempts the calls of `slots` would stop after (a whole number of calls)
        limit = -(-max_attempts // self.slots) * self.slots
        records, attempts, calls = [], 0, 0
        buffer, slots = self._buffer, self.slots
        while True:
            if tail is not None and buffer is self._buffer and \
                    _ends_soon(state, t_end, self.slots):
                # from here on in calls of the tail's slots (never back: the stop after
                # `limit` attempts is then reached exactly, a multiple of its slots)
                buffer, slots = tail.chunk, tail.slots
                buffer.inputs[1][:] = params
            states, record = buffer(state, None)
            calls += 1
            state = states[-1].copy()
            accepted = record[:, 0] == 1.0
            records.append(record[accepted])  # a copy: the arrays are the next call's
            attempts += self._attempts(states, state, slots)
            if state[2] != RUNNING or attempts >= limit:
                break
        status = {DONE: "done", FAILED: "the step fell below 10 ulp of t"}.get(
            state[2], "attempt limit reached")
        rows = records[0] if len(records) == 1 else np.vstack(records)
        D = L.D
        F = None
        if L.dense:  # views of the records' rows (each step's F_0 .. F_6 side by side)
            F = rows[:, 4 + D:].reshape(-1, POWER, D).transpose(1, 0, 2)
        return Trajectory(t0=t0, t_end=t_end, t_old=rows[:, 1].copy(), h=rows[:, 2].copy(),
                          w_old=rows[:, 4:4 + D], F=F, w_end=state[L.w].copy(),
                          d=L.d, attempts=attempts, calls=calls, status=status,
                          t_reached=float(state[0]), kernel=self.kernel())

    @staticmethod
    def _attempts(states, last, slots: int) -> int:
        """Attempts made in the last chunk (of ``slots``): every slot up to the one that
        finished."""
        if last[2] == RUNNING:
            return slots
        finished = np.flatnonzero(states[:, 2] != RUNNING)
        return int(finished[0]) + 1

    def _empty(self, t0, w0) -> Trajectory:
        D = self.layout.D
        return Trajectory(t0=t0, t_end=t0, t_old=np.zeros(0), h=np.zeros(0),
                          w_old=np.zeros((0, D)),
                          F=np.zeros((POWER, 0, D)) if self.layout.dense else None,
                          w_end=w0, d=self.layout.d, t_reached=t0)


def _ends_soon(state, t_end: float, slots: int) -> bool:
    """Whether the run from ``state`` (``t``, the signed step ``h`` next tried, ...) is likely
    to reach ``t_end`` within `TAIL_SHARE` of ``slots`` attempts at its present step (an
    estimate: it decides only which calls make the same attempts)."""
    h = abs(float(state[1]))
    return h > 0 and abs(t_end - float(state[0])) < TAIL_SHARE * slots * h


def _rms(x) -> float:
    return float(np.linalg.norm(x) / np.sqrt(x.size))


def exact_flow(system, *, tangent: int = 0, dense: bool = True, slots: int = SLOTS,
               compiler: str | None = "auto", cache_dir=None) -> AdaptiveFlow:
    """The `AdaptiveFlow` of ``system``'s exact flow (`flow_field`), built and compiled once
    per system, shape and compiler and kept with the system."""
    key = ("exact_flow", int(tangent), bool(dense), int(slots), compiler, str(cache_dir))
    project = None
    if getattr(system, "n_constraints", 0) > 0 and not tangent:  # onto g = 0 every step
        from .constrained_flow import projection_function
        project = projection_function(system)
    return cached(system, key, lambda: AdaptiveFlow(
        flow_field(system)[0], tangent=tangent, dense=dense, slots=slots, compiler=compiler,
        cache_dir=cache_dir, project=project))
