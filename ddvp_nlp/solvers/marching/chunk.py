"""The fast march path: many steps per call inside compiled CasADi code.

One march step (predictor, Newton on the step equations, its check) is one CasADi ``Function``
built from the public step functions of the careful path (``steps.StepFunctions``), with
CasADi's ``fast_newton`` in place of ``newton`` because it can be code-generated. ``mapaccum``
repeats it ``chunk`` times per call. Where a C compiler is present the chunk is generated as C
(its entry a plain loop over the step, ``compiler.looped_mapaccum``), compiled and cached;
elsewhere CasADi's virtual machine runs the same function. An energy step hands the next one
the vector field at the node it made (`carried_layout`), the first stage of the next step's RK4
predictor, computed beside that node's ``H`` and ``w``.

``fast_newton`` never raises and never says whether it converged, so every step of a chunk is
checked (finite values, ``tau > 0``, its unscaled residuals against the tolerance, the step
bounds: ``acceptance.Acceptance``'s test, computed in the chunk as each step's ``good`` flag);
the first step that fails it is redone by the careful path from the last good state, so the
fast path never changes what is accepted.

What goes into a chunk and what comes out of it is named in one place, the layouts below: the
chunk's ``vertcat`` is built from named parts and its output matrix is read back by the same
names (`ChunkSteps`).

Compiled chunks are cached in ``cache_dir`` (argument, else ``$DDVP_NLP_CACHE``, else
``~/.cache/ddvp_nlp``) under a hash of the generated function, the compiler and its flags. Each
build compiles to a temporary file and renames it into place, so two processes building the same
entry at once both end with a complete library.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from types import MappingProxyType

import casadi as ca
import numpy as np

from ...blocks import use_compiler
from ...discrete.runge_kutta import rk4
from ...physics.hamiltonian import vector_field_function
from ..compiler import (
    CompileUnavailable,
    FunctionBuffer,
    cache_folder,
    compile_function,
    warn_once,
)
from .chain_newton import chain_newton
from .step_newton import NEWTON_OPTIONS, unrolled_newton
from .steps import EnergyCheck, FixedCheck, StepFunctions

# fast_newton's iterations written out as straight-line code (``step_newton.unrolled_newton``); the
# rest of its loop runs only where these did not stop.
# Small systems (at most SMALL_NEWTON unknowns: n <= 2): three iterations, then the fourth's
# residual test alone, all inlined with common subexpressions merged. From the RK4 predictor
# fast_newton stops at that test on every step of the paper's example and after two or three
# updates on Henon-Heiles (measured). Up to MEDIUM_NEWTON unknowns (fpu, n = 6, needs the fourth
# update on 80% of its steps): four iterations and the fifth's test, inlined. Both solve each
# update by elimination without pivoting (``step_newton.DenseLU``) instead of fast_newton's QR:
# the chunk with the accuracy check cost 0.77 against 0.92 us per step on the paper's example,
# 0.79 against 1.27 on Henon-Heiles, 3.3 against 6.8 on fpu (side by side; fpu's QR inlined took
# 4-6 s to compile, the elimination 1.3 s). Larger systems: fast_newton's loop as a chain of
# conditional calls with a sparse elimination (``chain_newton.py``).
SMALL_NEWTON = 5
SMALL_UNROLL = MappingProxyType({"iterations": 3, "check_after": True, "inline": True,
                                 "linear": "lu"})
MEDIUM_NEWTON = 13
MEDIUM_UNROLL = MappingProxyType({"iterations": 4, "check_after": True, "inline": True,
                                  "linear": "lu"})


def step_options(unknowns: int) -> dict:
    """Options of a chunk's step function: small systems merge common subexpressions across
    the predictor, the check and the accuracy estimates too (Henon-Heiles: the chunk 6% cheaper,
    1.36 -> 1.28 us per step side by side; the same bits; the paper's example 1%)."""
    return {"cse": unknowns <= SMALL_NEWTON}


def unroll_options(unknowns: int) -> dict:
    """How the chunk's Newton of ``unknowns`` unknowns is built (see ``SMALL_NEWTON``): the
    options of `unrolled_newton`, or ``{"chain": True}`` above ``MEDIUM_NEWTON`` for
    `chain_newton` (``chain_newton.py``: the unrolled QR's code grows like ``n^3``)."""
    if unknowns <= SMALL_NEWTON:
        return dict(SMALL_UNROLL)
    if unknowns <= MEDIUM_NEWTON:
        return dict(MEDIUM_UNROLL)
    return {"chain": True}


def step_newton(name: str, residual: ca.Function, at_root: ca.Function, *,
                border: int) -> ca.Function:
    """The chunk's Newton on ``residual`` (``border``: the unknowns `chain_newton` eliminates
    last), chosen by `unroll_options` from its number of unknowns."""
    options = unroll_options(residual.numel_in(0))
    if options.pop("chain", False):
        return chain_newton(name, residual, NEWTON_OPTIONS, at_root=at_root, border=border)
    return unrolled_newton(name, residual, NEWTON_OPTIONS, at_root=at_root, border=border,
                           **options)


class ChunkLayout:
    """A column vector made of named parts of given widths, in order.

    The same object stacks the parts (symbolic, `stack`; numeric, `pack`), splits a
    symbolic vector into them (`split`) and reads them back as columns of a matrix with
    one row per step (`columns`): a part of width 1 is a vector, wider parts a matrix."""

    def __init__(self, *parts: tuple[str, int]):
        self.names = tuple(name for name, _ in parts)
        self.slices = {}
        start = 0
        for name, width in parts:
            self.slices[name] = start if width == 1 else slice(start, start + width)
            start += width
        self.size = start

    def _ordered(self, parts: dict) -> list:
        if set(parts) != set(self.names):
            raise ValueError(f"layout needs {self.names}, got {tuple(parts)}")
        return [parts[name] for name in self.names]

    def stack(self, **parts) -> ca.SX:
        return ca.vertcat(*self._ordered(parts))

    def pack(self, **parts) -> np.ndarray:
        return np.concatenate([np.atleast_1d(part) for part in self._ordered(parts)])

    def split(self, vector) -> dict:
        return {name: vector[self.slices[name]] for name in self.names}

    def columns(self, matrix: np.ndarray) -> dict:
        return {name: matrix[:, self.slices[name]] for name in self.names}


def _step_length() -> ca.Function:
    """``t_b - t_a`` as a call of its own: inline, CasADi would simplify
    ``(t_mid + tau) - t_mid`` to ``tau``, which differs from the difference of the node times
    (what the acceptance test is given) by round-off."""
    t_b, t_a = ca.SX.sym("t_b"), ca.SX.sym("t_a")
    return ca.Function("step_length", [t_b, t_a], [t_b - t_a], {"never_inline": True})


_STEP_LENGTH = _step_length()


# The acceptance test's numbers (``acceptance.Acceptance``), a parameter of every chunk call: the
# chunk computes each step's verdict (``good``) itself. A bound that is not set is infinite.
LIMITS = ChunkLayout(("tol", 1), ("tau_min", 1), ("tau_max", 1), ("max_step_ratio", 1),
                     ("z_scale", 1), ("H_scale", 1))


def limits(acceptance) -> np.ndarray:
    """``LIMITS`` of an `Acceptance`."""
    def bound(value, missing):
        return missing if value is None else value
    return LIMITS.pack(tol=acceptance.tol, tau_min=bound(acceptance.tau_min, -np.inf),
                       tau_max=bound(acceptance.tau_max, np.inf),
                       max_step_ratio=bound(acceptance.max_step_ratio, np.inf),
                       z_scale=acceptance.z_scale, H_scale=acceptance.H_scale)


def energy_layouts(n2: int) -> tuple[ChunkLayout, ChunkLayout]:
    """State and per-step output of a chunk of energy steps (``n2 = 2n``)."""
    state = ChunkLayout(("t_prev", 1), ("t_mid", 1), ("z_prev", n2), ("z_mid", n2), ("drift", 1))
    output = ChunkLayout(("t_next", 1), ("z_next", n2),
                    *((name, 1) for name in EnergyCheck._fields), ("good", 1))
    return state, output


def carried_layout(state: ChunkLayout, n2: int) -> ChunkLayout:
    """The state a chunk of energy steps carries from step to step: ``state`` and the vector
    field at the newest node, ``field = f(z_mid, t_mid)`` (`FastChunk.steps` appends it to a
    state given by its nodes)."""
    return ChunkLayout(*((name, _width(state, name)) for name in state.names), ("field", n2))


def _width(layout: ChunkLayout, name: str) -> int:
    part = layout.slices[name]
    return 1 if isinstance(part, int) else part.stop - part.start


def fixed_layouts(n2: int) -> tuple[ChunkLayout, ChunkLayout, ChunkLayout]:
    """State, constants and per-step output of a chunk of fixed-length steps."""
    state = ChunkLayout(("k", 1), ("z", n2))
    constants = ChunkLayout(("t0", 1), ("tau", 1), ("t_end", 1), ("total", 1))
    output = ChunkLayout(("t_next", 1), ("z_next", n2), *((name, 1) for name in FixedCheck._fields),
                    ("good", 1))
    return state, constants, output


@dataclass
class ChunkSteps:
    """The ``chunk`` steps of one call, by name; one entry (row) per step.

    ``t_next`` ``(chunk,)``, ``z_next`` ``(chunk, 2n)``, the check of each step (``canonical``,
    ``size``, ``H_node``, ``w_node``; energy steps also ``energy``, ``H_interval`` and ``drift``,
    the compensated sum after the step; see ``steps.EnergyCheck``) and ``good``: the
    acceptance test's verdict on the step, computed in the chunk (`step_verdict`): every
    output finite, ``tau > 0``, the residuals against ``tol`` and the step bounds. A diverged
    step is NaN and fails it. The accuracy check is made afterwards, on the whole run
    (``accuracy/``): the chunk computes nothing for it, so it is the same chunk with the check
    on or off."""

    t_next: np.ndarray
    z_next: np.ndarray
    canonical: np.ndarray
    size: np.ndarray
    H_node: np.ndarray
    w_node: np.ndarray
    good: np.ndarray
    energy: np.ndarray | None = None
    H_interval: np.ndarray | None = None
    drift: np.ndarray | None = None


_LARGEST = float(np.finfo(float).max)


def _finite(values) -> ca.SX:
    """Whether every value is finite: ``|v| <= DBL_MAX`` is false for NaN and infinities (an
    expression CasADi does not simplify away, unlike ``v - v == 0``)."""
    verdict = ca.SX(1)
    for value in values:
        verdict = ca.logic_and(verdict, ca.fabs(value) <= _LARGEST)
    return verdict


def step_verdict(outputs: list, check, limit: dict, *, tau=None, tau_prev=None) -> ca.SX:
    """``Acceptance``'s test of one step as an expression, the same arithmetic as its numpy
    predicates (``acceptance.py``): ``outputs`` (the step's own outputs) finite, the residuals
    against ``tol``; for energy steps also ``tau > 0`` and the bounds on ``tau`` and on
    ``max(tau / tau_prev, tau_prev / tau)``. ``1`` where the step is accepted, else ``0``."""
    verdict = ca.logic_and(_finite(outputs),
                           check.canonical <= limit["tol"] * ca.fmax(limit["z_scale"], check.size))
    if tau is None:
        return verdict
    verdict = ca.logic_and(verdict, ca.fabs(check.energy)
                           <= limit["tol"] * ca.fmax(limit["H_scale"], check.H_interval))
    ratio = ca.fmax(tau / tau_prev, tau_prev / tau)
    for test in (tau > 0, tau >= limit["tau_min"], tau <= limit["tau_max"],
                 ratio <= limit["max_step_ratio"]):
        verdict = ca.logic_and(verdict, test)
    return verdict


def _residuals(check: ca.Function) -> ca.Function:
    """A step check (``StepFunctions.energy_check`` or ``fixed_check``) without its last two
    outputs, ``H`` and ``w`` of the new node: the residuals and their scales."""
    x, w = ca.SX.sym("x", check.sparsity_in(0)), ca.SX.sym("w", check.sparsity_in(1))
    return ca.Function(check.name() + "_residuals", [x, w], check(x, w)[:-2])


class FastChunk:
    """``chunk`` march steps per call, compiled or on the virtual machine.

    Energy rules: `energy_state` packs ``energy_layouts``' first layout from the nodes
    (``entry``), ``(t_prev, t_mid, z_prev, z_mid, drift)``; the chunk carries
    `carried_layout`'s (the vector field at the newest node too), which `steps` completes;
    `energy_steps` runs from the nodes. Fixed rule: state ``[k, z]`` and constants
    ``[t0, tau, t_end, total]``; `fixed_steps` runs from node ``k``. Either way the
    parameters end with the acceptance test's numbers (``LIMITS``): each step's verdict comes
    out of the chunk. ``H_node`` and the
    site-density weight ``w_node`` are those of each new node (energy guard, solvability monitor).

    ``functions`` are the careful path's `StepFunctions`;
    ``compiler`` is already resolved (``find_compiler``): a path, or ``None`` for the virtual
    machine.
    """

    def __init__(self, system, scheme, functions: StepFunctions, *, chunk: int, compiler,
                 cache_dir):
        started = time.perf_counter()
        n2 = 2 * system.n
        theta = ca.SX.sym("theta", system.theta.numel())
        self.variable = scheme.variable_steps
        self.n2, self.ntheta = n2, system.theta.numel()
        self.field = vector_field_function(system)
        self._field = FunctionBuffer(self.field)  # a carried state's field, from its nodes
        if self.variable:
            self.state, self.output = energy_layouts(n2)
            self.entry = self.state  # the state from the nodes (energy_state)
            self.carries = False  # whether the state carries the field (_energy_step)
            step = self._energy_step(functions, theta)
        else:
            self.state, self.constants, self.output = fixed_layouts(n2)
            step = self._fixed_step(functions, theta)
        self.chunk = chunk
        function = step.mapaccum("chunk", chunk)
        self.path = "vm"
        self.compile_s = 0.0
        self.compile = None
        if compiler is not None:
            compiled_at = time.perf_counter()
            folder = cache_folder(cache_dir)
            try:
                function = compile_function(function, compiler, folder, steps=chunk)
                self.compile = lambda f: _compiled_or_vm(f, compiler, folder)
                use_compiler(system, self.compile)
                self.path = "compiled"
            except CompileUnavailable as exc:
                warn_once(exc)  # the virtual machine runs the same function, slower
            self.compile_s = time.perf_counter() - compiled_at
        self.function = function
        self._buffer = FunctionBuffer(function)
        self.build_s = time.perf_counter() - started

    def _energy_step(self, functions, theta):
        """The chunk's energy step: `energy_step` of the state that carries the vector field
        at the newest node (`carried_layout`); `energy_state` still packs the state from the
        nodes alone (``entry``), and `steps` adds the field to it."""
        self.entry, self.state = self.state, carried_layout(self.state, self.n2)
        self.carries = True
        return self.energy_step(functions, theta, carried=True)

    def energy_step(self, functions, theta, *, carried: bool = False) -> ca.Function:
        """One energy step ``(state, [theta, limits]) -> (state after, output)`` of
        `energy_layouts`' state, or with ``carried`` of `carried_layout`'s (what
        ``chaos.tangent.TangentChunk`` extends is the first). The predictor is
        ``StepFunctions.energy_predict``'s RK4 over the previous step; carried, its first
        stage is the state's ``field``, computed where the step before made the node, beside
        that node's ``H`` and ``w`` (whose sines and cosines it shares: paper_pendulum two
        sines a step fewer), and the field at the new node goes into the state after. The same
        numbers either way (the field of the same node from the same expression)."""
        layout = carried_layout(self.entry, self.n2) if carried else self.entry
        state = ca.SX.sym("state", layout.size)
        s = layout.split(state)
        limit = ca.SX.sym("limits", LIMITS.size)
        w = ca.vertcat(s["t_prev"], s["t_mid"], s["z_prev"], s["z_mid"], theta, s["drift"])
        # the step's residuals come out of the Newton, where they share the last residual
        # test's terms
        newton = step_newton("fast_energy_step", functions.energy_newton_residual,
                             _residuals(functions.energy_check), border=1)
        tau_guess = s["t_mid"] - s["t_prev"]
        if carried:
            guess = ca.vertcat(rk4(lambda z, t: self.field(z, t, theta), s["z_mid"], s["t_mid"],
                                   tau_guess, k1=s["field"]), tau_guess)
        else:
            guess = functions.energy_predict(w, tau_guess)
        x, *residuals = newton(guess, w)
        t_next = s["t_mid"] + x[-1]
        check = EnergyCheck(*residuals, *functions.node_monitor(x[:-1], t_next, theta))
        moved = dict(t_prev=s["t_mid"], t_mid=t_next, z_prev=s["z_mid"], z_mid=x[:-1],
                     drift=s["drift"] + check.energy)
        if carried:
            moved["field"] = self.field(x[:-1], t_next, theta)
        after = layout.stack(**moved)
        # the step lengths as the march computes them from the node times
        good = step_verdict([t_next, *ca.vertsplit(x[:-1]), *check], check, LIMITS.split(limit),
                            tau=_STEP_LENGTH(t_next, s["t_mid"]),
                            tau_prev=_STEP_LENGTH(s["t_mid"], s["t_prev"]))
        outputs = self.output.stack(t_next=t_next, z_next=x[:-1], **check._asdict(),
                                    good=good)
        return ca.Function("step", [state, ca.vertcat(theta, limit)], [after, outputs],
                           step_options(functions.energy_residual.numel_in(0)))

    def _fixed_step(self, functions, theta):
        state = ca.SX.sym("state", self.state.size)
        constants = ca.SX.sym("constants", self.constants.size)
        limit = ca.SX.sym("limits", LIMITS.size)
        s, c = self.state.split(state), self.constants.split(constants)
        k = s["k"]
        t_a = ca.if_else(k == 0, c["t0"], c["t0"] + k * c["tau"])
        t_b = ca.if_else(k + 1 == c["total"], c["t_end"], c["t0"] + (k + 1) * c["tau"])
        w = ca.vertcat(t_a, t_b, s["z"], theta)
        newton = step_newton("fast_fixed_step", functions.fixed_newton_residual,
                             _residuals(functions.fixed_check), border=0)
        z_b, *residuals = newton(functions.fixed_predict(w), w)
        check = FixedCheck(*residuals, *functions.node_monitor(z_b, t_b, theta))
        good = step_verdict([t_b, *ca.vertsplit(z_b), *check], check, LIMITS.split(limit))
        outputs = self.output.stack(t_next=t_b, z_next=z_b, **check._asdict(), good=good)
        return ca.Function("step", [state, ca.vertcat(theta, constants, limit)],
                           [self.state.stack(k=k + 1, z=z_b), outputs],
                           step_options(functions.fixed_residual.numel_in(0)))

    def _call(self, state: np.ndarray, parameters: np.ndarray):
        """One call through a `FunctionBuffer` (numpy arrays
        in place of DM). Returns ``(states, outputs)``, one row per step, overwritten by the
        next call."""
        tiled = np.broadcast_to(parameters, (self.chunk, parameters.size))
        return self._buffer(state, tiled)

    def _carried(self, states: np.ndarray) -> dict:
        """The state's columns a `ChunkSteps` keeps (the drift after each energy step), views
        of ``states``."""
        carried = self.state.columns(states)
        return {name: carried[name] for name in ("drift",) if name in carried}

    def _decode(self, outputs: np.ndarray, extra: dict, *, copy=True) -> ChunkSteps:
        if copy:  # the buffers are overwritten by the next call
            outputs = outputs.copy()
            extra = {name: value.copy() for name, value in extra.items()}
        columns = self.output.columns(outputs)
        columns["good"] = columns["good"] != 0
        return ChunkSteps(**columns, **extra)

    def energy_state(self, t_prev, t_mid, z_prev, z_mid, drift) -> np.ndarray:
        """The state of energy steps from nodes ``k - 1`` (``t_prev``, ``z_prev``) and ``k``
        (`energy_layouts`' state; `steps` adds what the chunk carries)."""
        return self.entry.pack(t_prev=t_prev, t_mid=t_mid, z_prev=z_prev, z_mid=z_mid,
                               drift=drift)

    def _carrying(self, state: np.ndarray, parameters: np.ndarray) -> np.ndarray:
        """``state`` as the chunk carries it: a state from the nodes (`energy_state`) with the
        vector field at its newest node appended (computed on the virtual machine: the numbers
        the compiled step computes, tested); a carried state as it is."""
        if not (self.variable and self.carries) or state.size == self.state.size:
            return state
        parts = self.entry.split(state)
        field = self._field(parts["z_mid"], parts["t_mid"], parameters[:self.ntheta])[0]
        return np.concatenate([state, field.ravel()])

    def fixed_state(self, k: int, z) -> np.ndarray:
        """The state of fixed-length steps from node ``k`` (state ``z``)."""
        return self.state.pack(k=k, z=z)

    def energy_parameters(self, theta, acceptance) -> np.ndarray:
        """``theta`` and the acceptance test's numbers (``LIMITS``)."""
        return np.concatenate([theta, limits(acceptance)])

    def fixed_parameters(self, theta, acceptance, *, t0, tau, t_end, total) -> np.ndarray:
        """``theta``, the grid (``total`` steps of ``tau`` from ``t0`` that end on ``t_end``)
        and the acceptance test's numbers."""
        return np.concatenate([theta, self.constants.pack(t0=t0, tau=tau, t_end=t_end,
                                                          total=total), limits(acceptance)])

    def steps(self, state: np.ndarray, parameters: np.ndarray, calls: int = 1) -> ChunkSteps:
        """``calls * chunk`` steps from ``state`` (`energy_state`, `fixed_state`):
        ``calls`` calls, each from the state the previous one ended in, which is the state the
        march builds from the nodes for its next call when it kept every step (the same
        numbers: the node times, states and drift are outputs of the chunk)."""
        state = self._carrying(state, parameters)
        if calls == 1:
            after, outputs = self._call(state, parameters)
            return self._decode(outputs, self._carried(after))
        c = self.chunk
        outputs = np.empty((calls * c, self.output.size))
        extra = {name: np.empty((calls * c, *np.shape(value)[1:]))
                 for name, value in self._carried(np.empty((1, self.state.size))).items()}
        for i in range(calls):
            # the parameters stay in the buffer from the first call (no tiling and copy again)
            after, out = self._call(state, parameters) if i == 0 else self._buffer(state, None)
            outputs[i * c:(i + 1) * c] = out
            for name, value in self._carried(after).items():  # only what is kept is copied
                extra[name][i * c:(i + 1) * c] = value
            state = after[c - 1]  # copied into the input buffer at the start of the next call
        return self._decode(outputs, extra, copy=False)

    def energy_steps(self, t_prev, t_mid, z_prev, z_mid, drift, theta,
                     acceptance) -> ChunkSteps:
        """``chunk`` energy steps of one orbit (`energy_state`), judged by
        ``acceptance``."""
        return self.steps(self.energy_state(t_prev, t_mid, z_prev, z_mid, drift),
                          self.energy_parameters(theta, acceptance))

    def fixed_steps(self, k: int, z, theta, acceptance, *, t0, tau, t_end,
                    total) -> ChunkSteps:
        """``chunk`` fixed-length steps of one orbit from node ``k`` (state ``z``) of a uniform
        grid of ``total`` steps of ``tau`` from ``t0`` that ends on ``t_end``."""
        parameters = self.fixed_parameters(theta, acceptance, t0=t0, tau=tau, t_end=t_end,
                                           total=total)
        return self.steps(self.fixed_state(k, z), parameters)


def _compiled_or_vm(function, compiler, folder):
    """``function`` compiled, or itself (on the virtual machine) if it cannot be."""
    try:
        return compile_function(function, compiler, folder)
    except CompileUnavailable as exc:
        warn_once(exc)
        return function
