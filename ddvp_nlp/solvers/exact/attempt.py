"""One attempted step of adaptive DOP853, written once as a CasADi expression: the stages,
Hairer's error estimate (the 5th- and 3rd-order embedded pair), the step-size controller
(scipy's constants) and the coefficients of the 7th-order continuous extension.

The state may carry a tangent matrix ``Y`` (d x m) beside ``z`` (d = 2n): ``w = (z, vec Y)``
with ``w' = (f(z, t), Df(z, t) Y)``, ``Df Y`` by forward differentiation (``jtimes``, m
directions). The error norm controls ``z`` alone (see ``AttemptLayout.control``).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from .tableau import dop853

SAFETY = 0.9
MIN_FACTOR = 0.2
MAX_FACTOR = 10.0
EXPONENT = -1.0 / 8.0  # -1 / (error estimator order + 1), as scipy and Hairer
EPS = float(np.finfo(float).eps)
POWER = 7  # rows of the dense-output coefficients F

RUNNING, DONE, FAILED = 0.0, 1.0, 2.0


@dataclass(frozen=True)
class AttemptLayout:
    """Sizes and offsets of the vectors a slot reads and writes.

    state (accumulated):  [t, h, flag, rejected, w (D), f(w) (D)]
    params (per slot):    [t_end, h_max, rtol, atol (d), theta (p)]
    record (per slot):    [accepted, t_old, h, err, w_old (D), F (POWER*D, if dense)]

    ``h`` in the state is the signed step the next attempt tries; ``flag`` is RUNNING, DONE
    (t reached t_end) or FAILED (the step fell below 10 ulp of t); ``rejected``: the last
    attempt was rejected (the next accepted step may not grow, as in scipy and Hairer).
    ``F`` holds the rows F_0..F_6 of the dense output, each of length D, row after row.
    """

    d: int  # size of z
    m: int  # columns of Y (0: no variational equations)
    p: int  # size of theta
    dense: bool
    tangent_control: bool = False  # the error norm sees Y too (see `control`)

    @property
    def D(self) -> int:
        return self.d * (1 + self.m)

    @property
    def state_size(self) -> int:
        return 4 + 2 * self.D

    @property
    def param_size(self) -> int:
        return 3 + self.d + self.p

    @property
    def record_size(self) -> int:
        return 4 + self.D + (POWER * self.D if self.dense else 0)

    @property
    def control(self) -> slice:
        """The components of ``w`` the error norm sees: ``z`` alone (default), or all of ``w``
        with ``tangent_control``. ``Y`` obeys a linear equation whose coefficients come from
        ``z``: steps that resolve ``z`` resolve ``Y`` to the same relative order (measured while
        building it), a tangent run takes exactly the steps of the plain run (same
        ``z``, bit for bit), and a growing ``Y`` (a chaotic orbit's) cannot shorten them."""
        return slice(0, self.D if self.tangent_control else self.d)

    # slices of the state
    w = property(lambda self: slice(4, 4 + self.D))
    f = property(lambda self: slice(4 + self.D, 4 + 2 * self.D))


def augmented_field(field: ca.Function, m: int) -> ca.Function:
    """``(w, t, theta) -> w'`` for ``w = (z, vec Y)``, ``Y`` d x m (column-major):
    ``(f(z, t), Df(z, t) Y)``. With ``m = 0``, ``field`` itself."""
    if m == 0:
        return field
    d = field.size1_in(0)
    p = field.size1_in(2)
    w = ca.SX.sym("w", d * (1 + m))
    t, theta = ca.SX.sym("t"), ca.SX.sym("theta", p)
    z = w[:d]
    Y = ca.reshape(w[d:], d, m)
    f = field(z, t, theta)
    fY = ca.jtimes(f, z, Y)
    return ca.Function("field_tangent", [w, t, theta], [ca.vertcat(f, ca.vec(fY))],
                       ["w", "t", "theta"], ["dw"])


def combination(stages, coefficients):
    """``sum_j c_j K_j`` over the nonzero coefficients (an SX or MX expression)."""
    terms = [float(c) * stages[j] for j, c in enumerate(coefficients) if c != 0]
    total = terms[0]
    for term in terms[1:]:
        total = total + term
    return total


def dop853_step(rhs, w, f0, t, h, project=None):
    """The order-8 step from ``w`` (with ``f0 = rhs(w, t)``): ``(w_new, K)``, ``K`` the 13
    stages (``K[12] = rhs(w_new, t + h)``, the next step's first stage). ``project(w, t)``, if
    given, maps the order-8 result onto a manifold before ``K[12]`` is taken there (the
    constrained flow, ``constrained.py``)."""
    tab = dop853()
    K = [f0]
    for s in range(1, tab.stages):
        K.append(rhs(w + h * combination(K, tab.A[s, :s]), t + float(tab.C[s]) * h))
    w_new = w + h * combination(K, tab.B)
    if project is not None:
        w_new = project(w_new, t + h)
    K.append(rhs(w_new, t + h))
    return w_new, K


def error_norm(K, h, w, w_new, rtol, atol, control: slice):
    """Hairer's DOP853 estimate (as scipy's ``_estimate_error_norm``): with
    ``e5 = sum E5_j K_j / sc``, ``e3 = sum E3_j K_j / sc``, ``sc = atol + rtol max(|w|, |w_new|)``:
    ``|h| |e5|^2 / sqrt((|e5|^2 + 0.01 |e3|^2) n)``; 0 where both vanish. ``atol`` covers
    ``z``; tangent components (``control`` past ``z``) get its largest entry."""
    tab = dop853()
    size = w[control].numel()
    if size > atol.numel():
        atol = ca.vertcat(atol, ca.repmat(ca.mmax(atol), size - atol.numel(), 1))
    sc = atol + rtol * ca.fmax(ca.fabs(w[control]), ca.fabs(w_new[control]))
    e5 = combination([k[control] for k in K], tab.E5) / sc
    e3 = combination([k[control] for k in K], tab.E3) / sc
    n5, n3 = ca.sumsqr(e5), ca.sumsqr(e3)
    denominator = ca.sqrt((n5 + 0.01 * n3) * size)
    # == 0, not > 0: a NaN estimate must stay NaN (and be rejected), not become 0 (accepted)
    return ca.if_else(denominator == 0, 0.0, ca.fabs(h) * n5 / denominator)


def dense_coefficients(rhs, K, w, w_new, t, h):
    """The rows ``F_0..F_6`` of the continuous extension over the step (three extra stages):
    ``w(t + x h) = w + x(F0 + (1-x)(F1 + x(F2 + (1-x)(F3 + x(F4 + (1-x)(F5 + x F6))))))``."""
    tab = dop853()
    K = list(K)
    for row, c in zip(tab.A_EXTRA, tab.C_EXTRA, strict=True):
        s = len(K)
        K.append(rhs(w + h * combination(K, row[:s]), t + float(c) * h))
    delta = w_new - w
    F = [delta, h * K[0] - delta, 2 * delta - h * (K[12] + K[0])]
    F += [h * combination(K, row) for row in tab.D]
    return F


def slot_function(field: ca.Function, layout: AttemptLayout, *, inline: bool = True,
                  project: ca.Function | None = None) -> ca.Function:
    """``(state, params) -> (state_next, record)``: one attempt of adaptive DOP853 (module
    docstring; ``AttemptLayout`` for the vectors). No-op handling of finished slots is left to the
    caller (`chunk_function`); this function always attempts.

    ``inline``: one SX expression with the 16 evaluations of the (augmented) field written
    out (fastest for small fields); else an MX graph that calls the field function 16 times
    and combines the stages with vector operations (generated code of the field's size, not
    16 times it: for large systems with tangents, where the inlined code reaches megabytes
    and gcc minutes). ``project`` ``(z, t, theta) -> z``: every attempted step's result
    projected (`dop853_step`) before its error is estimated and its dense output built."""
    L = layout
    rhs_function = augmented_field(field, L.m)
    kind = ca.SX if inline else ca.MX
    state = kind.sym("state", L.state_size)
    params = kind.sym("params", L.param_size)
    t, h_proposed, rejected = state[0], state[1], state[3]
    w, f0 = state[L.w], state[L.f]
    t_end, h_max, rtol = params[0], params[1], params[2]
    atol = params[3:3 + L.d]
    theta = params[3 + L.d:]

    def rhs(x, time):
        return rhs_function(x, time, theta)

    direction = ca.sign(t_end - t)
    # 10 ulp of the times involved (scipy: of t alone; at t = 0 that is 1e-322 and a field
    # that is NaN at the start would shrink h to zero, then accept zero-length steps forever)
    min_step = 10 * EPS * ca.fmax(ca.fabs(t), ca.fabs(t_end))
    h_abs = ca.fmax(ca.fmin(ca.fabs(h_proposed), h_max), min_step)
    t_try = t + direction * h_abs
    t_new = ca.if_else(direction * (t_try - t_end) > 0, t_end, t_try)  # land on t_end exactly
    h = t_new - t
    h_abs = ca.fabs(h)

    onto = None if project is None else (lambda x, time: project(x, time, theta))
    w_new, K = dop853_step(rhs, w, f0, t, h, onto)
    err = error_norm(K, h, w, w_new, rtol, atol, L.control)
    finite = ca.sum1(ca.fabs(w_new[L.control])) < np.inf  # false for inf and NaN
    err = ca.if_else(finite, err, np.inf)  # NaN or inf -> inf: rejected, shrinks, then fails
    accepted = err < 1
    growth = SAFETY * err ** EXPONENT  # inf at err = 0, capped below
    grow = ca.fmin(MAX_FACTOR, growth)
    grow = ca.if_else(rejected, ca.fmin(1.0, grow), grow)
    shrink = ca.fmax(MIN_FACTOR, growth)
    h_next = ca.if_else(accepted, h_abs * grow, h_abs * shrink)
    flag = ca.if_else(accepted, ca.if_else(t_new == t_end, DONE, RUNNING),
                      ca.if_else(h_next < min_step, FAILED, RUNNING))
    next_state = ca.vertcat(
        ca.if_else(accepted, t_new, t), direction * h_next, flag,
        ca.if_else(accepted, 0.0, 1.0),
        ca.if_else(accepted, w_new, w), ca.if_else(accepted, K[12], f0))
    record = [accepted, t, h, err, w]
    if L.dense:
        record += dense_coefficients(rhs, K, w, w_new, t, h)
    return ca.Function("dop853_slot", [state, params], [next_state, ca.vertcat(*record)],
                       ["state", "params"], ["state_next", "record"], {"cse": True})


def skip_function(layout: AttemptLayout) -> ca.Function:
    """``(state, params) -> (state, 0)``: a finished (or failed) slot."""
    state = ca.SX.sym("state", layout.state_size)
    params = ca.SX.sym("params", layout.param_size)
    return ca.Function("dop853_skip", [state, params],
                       [state, ca.SX.zeros(layout.record_size)],
                       ["state", "params"], ["state_next", "record"])


def chunk_function(field: ca.Function, layout: AttemptLayout, slots: int, *,
                   skip: bool = True, inline: bool = True,
                   project: ca.Function | None = None) -> ca.Function:
    """``(state, params[P x slots]) -> (states[S x slots], records[R x slots])``: ``slots``
    attempts in a row (``mapaccum``), each `slot_function`. With ``skip``, a slot whose
    state is DONE or FAILED runs `skip_function` instead (an MX switch: only one branch is
    evaluated, so the slots after t_end cost a copy, not a step)."""
    slot = slot_function(field, layout, inline=inline, project=project)
    if skip:
        state = ca.MX.sym("state", layout.state_size)
        params = ca.MX.sym("params", layout.param_size)
        switch = ca.Function.conditional("dop853_switch", [slot], skip_function(layout))
        # index 0 (RUNNING) -> the step; anything else -> the default, the skip
        out = switch(state[2], state, params)
        slot = ca.Function("dop853_guarded", [state, params], out,
                           ["state", "params"], ["state_next", "record"])
    return slot.mapaccum(f"dop853_chunk_{slots}", slots, [0], [0])
