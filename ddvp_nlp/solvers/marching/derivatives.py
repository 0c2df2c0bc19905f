"""Exact forward derivatives of a march's states at fixed physical times (issue 47):
``march(..., output=Output(t_eval=ts), derivatives=("q0", "p0", "params"))``.

What is differentiated: the discrete solution read through its dense output at the fixed
times ``t_eval``, as a function of the inputs ``q0``, ``p0`` and the parameters ``theta``, with
every step length included. A node ``k`` is not a fixed point of the motion (an energy rule's
node times ``t_k`` move with the inputs, and the count of nodes jumps), so no derivative of
"node ``k``" is offered.

The chain (the implicit-function theorem on each accepted step, then the interpolant):

1. The carried derivative ``S_k = d(z_k, t_k)/d(inputs)`` starts at ``S_0``: the identity in
   the initial state's columns, ``dt_0 = 0``.
2. A fixed-length step (the ``fixed`` rule's every step, an energy rule's step 0 of length
   ``tau0``) solves ``F(z_{k+1}; t_k, t_{k+1}, z_k, theta) = 0`` with node times that do not
   move with the inputs: ``dz_{k+1} = -F_x^-1 (F_{z_k} dz_k + F_theta dtheta)``.
3. An energy step solves ``F(z_{k+1}, tau_k; t_{k-1}, t_k, z_{k-1}, z_k, theta) = 0`` (the
   canonical equations of interval ``k`` and the energy row): ``d(z_{k+1}, tau_k) = -F_x^-1
   F_w dw``, ``dw`` gathered from ``S_{k-1}``, ``S_k`` and ``dtheta``; the energy row gives
   ``dtau_k`` exactly, and ``dt_{k+1} = dt_k + dtau_k``. (The drift the march adds to the
   energy row is round-off and is held.)
4. At ``T`` in ``[t_k, t_{k+1}]`` the dense output is the cubic Hermite polynomial
   ``z(T) = h00 z_k + h10 tau f_k + h01 z_{k+1} + h11 tau f_{k+1}`` (``Solution.at``), with
   ``s = (T - t_k) / tau``: ``dz(T) = h00 dz_k + h01 dz_{k+1} + h10 (dtau f_k + tau df_k) +
   h11 (dtau f_{k+1} + tau df_{k+1}) - z'(T) (dt_k + s dtau)``, where ``df_k = f_z dz_k + f_t
   dt_k + f_theta dtheta`` (the vector field's Jacobian) and ``z'(T)`` the interpolant's slope.

The step Jacobians are CasADi functions of the step equations the march solved
(``steps.StepFunctions``, as `StepProblem` uses them), evaluated after the march on the
accepted nodes in mapped calls of ``CHUNK`` steps; the recursion ``S_{k+1} = A_k S_k + B_k``
runs over them and keeps only the nodes the ``t_eval`` intervals read. No step is solved again.
With ``frozen_steps`` every step is differentiated as a fixed-length step on its own interval
(``dtau = 0``): the derivative peers report, which misses the step lengths' share.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...cache import cached
from ...discrete.scheme import Scheme
from ...errors import InputError
from ...physics.hamiltonian import vector_field_function
from ...validation import check_names
from ..compiler import RentedBuffer
from .step_newton import step_jacobian_function
from .velocity_start import refuse_start_names

__all__ = ["DERIVATIVES", "MODES", "DerivativeOptions", "affine_maps", "check_derivatives",
           "check_mode", "choose_mode", "derivative_request", "march_derivatives", "readout",
           "refuse_unsupported"]

# The inputs a march differentiates in, in the order of the derivative's columns; a march from
# v0 takes "v0" in place of "p0" (velocity_start.py).
DERIVATIVES = ("q0", "p0", "params")
INPUTS = ("q0", "p0", "v0", "params")
# Steps whose Jacobians are evaluated in one mapped call (bounds the work arrays' memory).
CHUNK = 4096


@dataclass(frozen=True)
class DerivativeOptions:
    """What ``march(..., derivatives=...)`` differentiates and how: ``inputs``, names from
    ``("q0", "p0", "params")`` (``"v0"`` in place of ``"p0"`` for a march from ``v0``);
    ``mode``: ``"forward"`` (a tangent column per input), ``"reverse"`` (an adjoint sweep per
    output entry, ``adjoint.py``) or ``"auto"`` (reverse where the ``2n len(t_eval)`` outputs
    are fewer than the inputs). Same values either way.
    A plain name or sequence of names is ``DerivativeOptions(inputs=names)``."""

    inputs: tuple = DERIVATIVES
    mode: str = "auto"

    def __post_init__(self):
        object.__setattr__(self, "inputs", check_derivatives(self.inputs))
        check_mode(self.mode)


def derivative_request(derivatives) -> tuple[tuple[str, ...], str]:
    """``derivatives`` (``None``, names, or `DerivativeOptions`) as ``(names, mode)``."""
    if isinstance(derivatives, DerivativeOptions):
        return derivatives.inputs, derivatives.mode
    return check_derivatives(derivatives), "auto"


def check_derivatives(derivatives) -> tuple[str, ...]:
    """``derivatives`` (``None``, a name, or a sequence of names from `INPUTS`) as a tuple
    of distinct names in `INPUTS`' order (`validation.check_names`)."""
    return check_names(derivatives, INPUTS)


def refuse_unsupported(names, *, v0, backward: bool, target_error, output, steps) -> None:
    """Refuse by name what ``derivatives`` does not support yet, before anything is built."""
    if not names:
        return
    if output.t_eval is None and not output.events:
        raise InputError("derivatives are of the states at fixed times or of event times: "
                         "give output=Output(t_eval=...) or Output(events=...)")
    refuse_start_names(names, from_velocity=v0 is not None)
    refusals = (
        (backward, "a backward t_span (t_end < t0)"),
        (target_error is not None, "target_error (its first step is chosen by a pilot march)"),
        (output.thinned, f"thinned output (keep_every={output.keep_every!r}, "
                         f"keep={output.keep!r})"),
        (steps is not None and getattr(steps, "breakdown", None) == "least_squares",
         "steps.breakdown='least_squares' (a replaced step solves no step equations)"))
    for refused, what in refusals:
        if refused:
            raise InputError(f"derivatives are not supported with {what}")


MODES = ("auto", "forward", "reverse")


def check_mode(mode) -> str:
    """``derivatives_mode``: one of `MODES`, else an ``InputError`` naming it."""
    if not isinstance(mode, str) or mode not in MODES:
        raise InputError(f"DerivativeOptions.mode must be one of {', '.join(MODES)}, got {mode!r}")
    return mode


def choose_mode(mode: str, names, system, outputs: int) -> str:
    """``auto``: reverse where the outputs (``2n`` per output time reached) are fewer than the
    inputs (the columns of ``names``), else forward (a sweep per output entry against one
    carried column per input, on the same Jacobians)."""
    if mode != "auto":
        return mode
    widths = {"q0": system.n, "p0": system.n, "v0": system.n, "params": len(system.params)}
    inputs = sum(widths[name] for name in names)
    return "reverse" if 2 * system.n * outputs < inputs else "forward"


def march_derivatives(system, scheme, theta, t, z, t_eval, names=DERIVATIVES, *,
                      frozen_steps: bool = False) -> dict[str, np.ndarray]:
    """``d(q, p)(t_eval) / d(input)`` for each input of ``names`` of the march whose nodes are
    ``t`` (N,), ``z`` (N, 2n) at parameters ``theta`` (module docstring): ``{"q0": (M, 2n, n),
    "p0": (M, 2n, n), "params": (M, 2n, m)}``. ``frozen_steps``: every step length held."""
    scheme = Scheme.coerce(scheme)
    n, m = system.n, np.size(theta)
    theta = np.asarray(theta, float).ravel()
    seed_z, seed_theta, widths = _seeds(n, m, names)
    t_eval = np.asarray(t_eval, float).ravel()
    if t_eval.size == 0:  # a march that stopped before the first output time
        return _split(np.zeros((0, 2 * n, seed_z.shape[1])), names, widths)
    if t.size < 2:
        rows = np.repeat(np.vstack([seed_z])[None], t_eval.size, axis=0)
        return _split(rows, names, widths)
    interval = np.clip(np.searchsorted(t, t_eval, side="right") - 1, 0, t.size - 2)
    needed = np.unique(np.concatenate([interval, interval + 1]))
    carried = _carry(system, scheme, theta, t, z, seed_z, seed_theta, needed, frozen_steps)
    rows = _dense(system, theta, t, z, t_eval, interval, carried, seed_theta)
    return _split(rows, names, widths)


def _seeds(n: int, m: int, names):
    """``dz_0/d(inputs)`` (2n, d), ``dtheta/d(inputs)`` (m, d) and each input's width."""
    widths = {"q0": n, "p0": n, "params": m}
    d = sum(widths[name] for name in names)
    seed_z, seed_theta = np.zeros((2 * n, d)), np.zeros((m, d))
    column = 0
    for name in names:
        width = widths[name]
        block = np.eye(width)
        if name == "q0":
            seed_z[:n, column:column + width] = block
        elif name == "p0":
            seed_z[n:, column:column + width] = block
        else:
            seed_theta[:, column:column + width] = block
        column += width
    return seed_z, seed_theta, widths


def _split(rows: np.ndarray, names, widths) -> dict[str, np.ndarray]:
    """The columns of ``rows`` (M, 2n, d) by input name."""
    out, column = {}, 0
    for name in names:
        out[name] = rows[:, :, column:column + widths[name]].copy()
        column += widths[name]
    return out


def _mapped(function: ca.Function, count: int, *rows) -> list[np.ndarray]:
    """``function`` on ``count`` evaluations, the inputs given as rows ``(count, size)``, each
    output as ``(count, rows, cols)``: one mapped call through numpy buffers (``compiler.py``'s
    `FunctionBuffer`: no DM conversions, which cost more than the Jacobians) of a power-of-two
    width up to ``CHUNK``, the last evaluation repeated to fill it. The map is compiled once its
    calls have cost `RentedBuffer`'s share of CPU (the same arithmetic; the step Jacobians of a
    64-parameter potential took 57 us a step in CasADi's virtual machine, twice the march's
    own step)."""
    width = min(CHUNK, 1 << max(count - 1, 0).bit_length())
    buffer = cached(function, ("derivatives_map", width),
                    lambda: RentedBuffer(function.map(width), "auto", prefix="derivatives"))
    filled = [np.concatenate([value, np.repeat(value[-1:], width - count, 0)])
              for value in (np.asarray(row, float).reshape(count, -1) for row in rows)]
    outputs = buffer(*filled)
    shapes = [function.size_out(i) for i in range(function.n_out())]
    return [value.reshape(width, cols, rows_)[:count].transpose(0, 2, 1).copy()
            for value, (rows_, cols) in zip(outputs, shapes, strict=True)]


def _fixed_gains(system, scheme, theta, t, z, steps: np.ndarray, in_theta: bool = True):
    """For the fixed-length steps ``k`` of ``steps``: ``(dz_{k+1}/dz_k, dz_{k+1}/dtheta)``
    with the node times held, ``(K, 2n, 2n)`` and ``(K, 2n, m)`` (``(K, 2n, 0)`` unless
    ``in_theta``: the solve is then on the state's columns alone)."""
    n2 = z.shape[1]
    w = np.hstack([t[steps, None], t[steps + 1, None], z[steps],
                   np.repeat(theta[None, :], steps.size, 0)])
    J_x, J_w = _mapped(step_jacobian_function(system, scheme, "fixed"), steps.size, z[steps + 1], w)
    gains = -np.linalg.solve(J_x, J_w[:, :, 2:] if in_theta else J_w[:, :, 2:2 + n2])
    return gains[:, :, :n2], gains[:, :, n2:]


def _energy_gains(system, scheme, theta, t, z, steps: np.ndarray, in_theta: bool = True):
    """For the energy steps ``k`` of ``steps`` (``k >= 1``): ``-F_x^-1 F_w``, ``(K, 2n + 1,
    2 + 4n + m)``, columns ``[t_{k-1}, t_k, z_{k-1}, z_k, theta]`` (the drift's dropped; the
    theta columns too unless ``in_theta``)."""
    tau = t[steps + 1] - t[steps]
    x = np.hstack([z[steps + 1], tau[:, None]])
    w = np.hstack([t[steps - 1, None], t[steps, None], z[steps - 1], z[steps],
                   np.repeat(theta[None, :], steps.size, 0), np.zeros((steps.size, 1))])
    J_x, J_w = _mapped(step_jacobian_function(system, scheme, "energy"), steps.size, x, w)
    return -np.linalg.solve(J_x, J_w[:, :, :-1] if in_theta else J_w[:, :, :2 + 2 * z.shape[1]])


def _carry(system, scheme, theta, t, z, seed_z, seed_theta, needed, frozen_steps):
    """``S_k = (dz_k, dt_k)`` (2n + 1, d) at the nodes ``needed`` (sorted), by the recursion
    over every step (module docstring, 2-3), ``CHUNK`` steps' Jacobians at a time. The carried
    state is ``Y_k = [dz_k - dz_{k-1}; dtau_{k-1}; S_k]``, and each step an affine map
    ``Y_{k+1} = M_k Y_k + C_k`` (`affine_maps`), applied a block at a time (`_scan`)."""
    n2, d = seed_z.shape
    energy = scheme.variable_steps and not frozen_steps
    state = np.vstack([np.zeros((n2 + 1, d)), seed_z, np.zeros((1, d))])
    kept = {0: state[n2 + 1:].copy()} if needed[0] == 0 else {}
    last = int(needed[-1])
    for start in range(0, last, CHUNK):
        steps = np.arange(start, min(start + CHUNK, last))
        maps = affine_maps(system, scheme, theta, t, z, steps, seed_theta, energy)
        state = _scan(maps, state, start, needed, kept)
    return kept


def affine_maps(system, scheme, theta, t, z, steps, seed_theta, energy: bool):
    """``(M, C)``, ``(K, 2r, 2r)`` and ``(K, 2r, d)`` (``r = 2n + 1``), of the steps ``steps``
    on the carried ``Y_k = [dz_k - dz_{k-1}; dtau_{k-1}; dz_k; dt_k]``: a fixed-length step
    ``dz_{k+1} = G_z dz_k + G_theta dtheta`` (``dt`` held, ``dtau_k = 0``), an energy step
    ``d(z_{k+1}, tau_k) = G [dt_{k-1}; dt_k; dz_{k-1}; dz_k] + G_theta dtheta`` and ``dt_{k+1} =
    dt_k + dtau_k``.

    Why differences and not ``[S_{k-1}; S_k]``: an energy step reads the previous interval
    through ``(z_k - z_{k-1}) / tau_{k-1}`` and ``t_k - t_{k-1}``, so its gains in ``z_{k-1}``
    and ``z_k`` (and in ``t_{k-1}``, ``t_k``) are large and nearly opposite. Applied one step at
    a time that costs a few digits; composed over a block of steps (`_scan`) the products'
    cancellations lost up to 1.5e-5 of the derivative on a 11000-step Kepler march. On the
    differences ``dz_k - dz_{k-1}``, ``dtau_{k-1}`` the gains are those of the differences and
    ``G_{z_{k-1}} + G_{z_k}`` (``G_{t_{k-1}} + G_{t_k}``), each formed once per step."""
    n2, d = z.shape[1], seed_theta.shape[1]
    r = n2 + 1
    M, C = np.zeros((steps.size, 2 * r, 2 * r)), np.zeros((steps.size, 2 * r, d))
    M[:, 2 * r - 1, 2 * r - 1] = 1.0  # dt_{k+1} = dt_k (+ dtau_k)
    fixed = np.ones(steps.size, bool) if not energy else steps == 0
    moves = bool(np.any(seed_theta))  # else the parameters' columns are left out of the solves
    if fixed.any():
        in_z, in_theta = _fixed_gains(system, scheme, theta, t, z, steps[fixed], moves)
        square = np.ix_(fixed, range(n2), range(r, r + n2))
        M[square] = in_z - np.eye(n2)
        M[np.ix_(fixed, range(r, r + n2), range(r, r + n2))] = in_z
        if moves:
            C[fixed, :n2] = C[fixed, r:r + n2] = in_theta @ seed_theta
    if not fixed.all():
        moving = ~fixed
        gains = _energy_gains(system, scheme, theta, t, z, steps[moving], moves)
        # gains' columns [t_{k-1}, t_k, z_{k-1}, z_k] onto Y's [dz_k - dz_{k-1}, dtau_{k-1},
        # dz_k, dt_k]: dz_{k-1} = dz_k - (dz_k - dz_{k-1}), dt_{k-1} = dt_k - dtau_{k-1}
        G_tp, G_t = gains[:, :, 0], gains[:, :, 1]
        G_zp, G_z = gains[:, :, 2:2 + n2], gains[:, :, 2 + n2:2 + 2 * n2]
        block = np.zeros((gains.shape[0], r, 2 * r))
        block[:, :, :n2], block[:, :, n2] = -G_zp, -G_tp
        block[:, :, r:r + n2], block[:, :, 2 * r - 1] = G_zp + G_z, G_tp + G_t
        offset = gains[:, :, 2 + 2 * n2:] @ seed_theta if moves else 0.0
        first, second = block.copy(), block
        first[:, :n2, r:r + n2] -= np.eye(n2)
        second[:, n2, 2 * r - 1] += 1.0
        M[moving, :r], M[moving, r:] = first, second
        C[moving, :r], C[moving, r:] = offset, offset
    return M, C


# Steps composed per block in `_scan`: the Python loop runs over 2 BLOCK + K / BLOCK steps.
BLOCK = 32


def _scan(maps, state, start: int, needed, kept: dict) -> np.ndarray:
    """``Y`` after the steps of ``maps`` from ``state`` (the steps from ``start``), the
    ``S_{k+1}`` of the nodes ``needed`` put in ``kept``: each block's maps composed (all
    blocks at once), the blocks' starts in order, then the steps again, every block at once."""
    K, r = maps[0].shape[0], maps[0].shape[1] // 2
    M, C, count = in_blocks(*maps)
    whole_M, whole_C = M[:, 0], C[:, 0]
    for j in range(1, BLOCK):
        whole_M, whole_C = M[:, j] @ whole_M, M[:, j] @ whole_C + C[:, j]
    starts = np.empty((count, *state.shape))
    for b in range(count):
        starts[b] = state
        state = whole_M[b] @ state + whole_C[b]
    wanted = needed[(needed > start) & (needed <= start + K)] - start - 1
    if wanted.size:
        blocks = np.unique(wanted // BLOCK)
        Y, wanted = starts[blocks], set(wanted.tolist())
        for j in range(BLOCK):
            Y = M[blocks, j] @ Y + C[blocks, j]
            for i, b in enumerate(blocks):
                if b * BLOCK + j in wanted:
                    kept[start + b * BLOCK + j + 1] = Y[i, r:].copy()
    return state


def in_blocks(M: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """The step maps ``z_{k+1} = M_k z_k + C_k`` (``M``: (K, w, w), ``C``: (K, w, ...)) padded
    with identity steps to whole blocks of `BLOCK` and shaped ``(blocks, BLOCK, ...)``, and the
    number of blocks: the forward recursion and the adjoint sweep compose them a block at a
    time."""
    K, width = M.shape[0], M.shape[1]
    count = -(-K // BLOCK)
    pad = count * BLOCK - K
    if pad:
        M = np.concatenate([M, np.repeat(np.eye(width)[None], pad, 0)])
        C = np.concatenate([C, np.zeros((pad, *C.shape[1:]))])
    return (M.reshape(count, BLOCK, width, width), C.reshape(count, BLOCK, *C.shape[1:]),
            count)


def _field_jacobian_function(system) -> ca.Function:
    """``(z, t, theta) -> (f, df/dz, df/dt, df/dtheta)`` of Hamilton's vector field, cached."""
    def build():
        field = vector_field_function(system)
        z, t, theta = field.sx_in()
        f = field.call([z, t, theta])[0]
        return ca.Function("field_jacobians", [z, t, theta], [
            f, ca.densify(ca.jacobian(f, z)), ca.densify(ca.jacobian(f, t)),
            ca.densify(ca.jacobian(f, theta))])
    return cached(system, "field_jacobians", build)


def readout(system, theta, t, z, t_eval, interval):
    """The dense output's linear map (module docstring, 4): ``dz(T_i) = P_a[i] S_a + P_b[i] S_b
    + R[i] dtheta`` with ``S_a``, ``S_b`` the carried derivatives at the nodes ``k_i``,
    ``k_i + 1`` of ``T_i``'s interval: ``P_a``, ``P_b`` ``(M, 2n, 2n + 1)``, ``R`` ``(M, 2n,
    m)``. Forward mode applies it, reverse mode its transpose (``adjoint.py``)."""
    n2, r = z.shape[1], z.shape[1] + 1
    nodes = np.unique(np.concatenate([interval, interval + 1]))
    f, f_z, f_t, f_theta = _mapped(_field_jacobian_function(system), nodes.size, z[nodes],
                                   t[nodes], np.repeat(theta[None, :], nodes.size, 0))
    at = np.searchsorted(nodes, interval)
    a, b = at, at + 1
    k = interval
    tau = t[k + 1] - t[k]
    s = (t_eval - t[k]) / tau
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, 3 * s**2 - 2 * s**3, \
        s**3 - s**2
    f_a, f_b = f[a, :, 0], f[b, :, 0]
    slope = (((6 * s**2 - 6 * s)[:, None] * z[k] + ((3 * s**2 - 4 * s + 1) * tau)[:, None] * f_a
              + (6 * s - 6 * s**2)[:, None] * z[k + 1]
              + ((3 * s**2 - 2 * s) * tau)[:, None] * f_b) / tau[:, None])
    count, eye = t_eval.size, np.eye(n2)
    P_a, P_b = np.zeros((count, n2, r)), np.zeros((count, n2, r))
    w10, w11 = (h10 * tau)[:, None, None], (h11 * tau)[:, None, None]
    P_a[:, :, :n2] = h00[:, None, None] * eye + w10 * f_z[a]
    P_b[:, :, :n2] = h01[:, None, None] * eye + w11 * f_z[b]
    P_a[:, :, n2] = (-(h10[:, None] * f_a + h11[:, None] * f_b) + w10[:, :, 0] * f_t[a, :, 0]
                     - (1 - s)[:, None] * slope)
    P_b[:, :, n2] = (h10[:, None] * f_a + h11[:, None] * f_b + w11[:, :, 0] * f_t[b, :, 0]
                     - s[:, None] * slope)
    R = w10 * f_theta[a] + w11 * f_theta[b]
    return P_a, P_b, R


def _dense(system, theta, t, z, t_eval, interval, carried, seed_theta) -> np.ndarray:
    """``d z(T)`` (M, 2n, d) through the Hermite interpolant (module docstring, 4)."""
    P_a, P_b, R = readout(system, theta, t, z, t_eval, interval)
    S_a = np.stack([carried[int(k)] for k in interval])
    S_b = np.stack([carried[int(k) + 1] for k in interval])
    return P_a @ S_a + P_b @ S_b + R @ seed_theta
