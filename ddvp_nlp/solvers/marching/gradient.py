"""``gradient(sol, cotangent)``: reverse mode of any solution's derivatives (issue 47).

For a march: the sweep of ``adjoint.py`` on its kept nodes, with its own check
(``derivative_check.py``: the march run again from two perturbed starts, which is why this
module sits above `march`). The cotangent is on the states at ``t_eval`` and, with the march's
event derivatives, on the crossing times: ``dt* = w . D(t*)`` (``event_derivatives.py``), so a
cotangent ``c`` on ``t*`` is the cotangent ``c w`` on the states at the fixed time ``t*``, and
one sweep takes both. A march from ``v0`` is differentiated in ``v0`` (``velocity_start.py``).

For a grid solution (fixed ends, a transfer at an energy, a periodic orbit): the family's own
reverse mode (``bvp_gradient``, ``transfer_gradient``, ``orbit_gradient``: one transposed solve).
This package may not import those families (docs/architecture.md), so each registers its reverse
mode here from its own ``__init__`` (`register_gradient`, as `INTEGRATORS` and `MONITORS` are
filled): a solution of a family exists only once the family is imported, so its entry is there.
"""

from __future__ import annotations

import numpy as np

from ...discrete.scheme import Scheme
from ...errors import InputError
from ...solution import Solution
from ..options import StepControl, coerce
from .adjoint import check_cotangent, check_solution, reverse_sweep
from .derivative_check import DerivativeCheck, check_record, conditioning, remarch_function
from .initial_value import march
from .velocity_start import start_jacobians, velocity_gradient

__all__ = ["GRID_GRADIENTS", "Gradient", "gradient", "register_gradient"]

# A grid solution's record (the `Solution` field that is set) -> (its reverse mode, the
# keyword arguments it takes, what to call it in a message); filled by the families.
GRID_GRADIENTS: dict[str, tuple] = {}
# The keyword arguments of a march's gradient.
MARCH_OPTIONS = ("check", "steps", "compilation")


def register_gradient(record: str, function, options: tuple, what: str) -> None:
    """``gradient(sol, ...)`` of a solution whose ``sol.<record>`` is set calls ``function(sol,
    cotangent, **options)`` (``options``: the keyword names it takes)."""
    GRID_GRADIENTS[record] = (function, tuple(options), what)


class Gradient(dict):
    """``gradient``'s answer for a march: ``{"q0": (n,), "p0": (n,), "params": (m,)}`` (``"v0"``
    in place of ``"p0"`` for a march from ``v0``) with its `DerivativeCheck` (``check``;
    ``None`` where not asked for)."""

    def __init__(self, values, check=None):
        super().__init__(values)
        self.check = check


def gradient(sol, cotangent, **options):
    """Reverse mode: the gradient of the scalar ``L = cotangent . outputs`` of the discrete
    solution ``sol`` in its inputs, step lengths included (module docstring).

    Args:
        sol: a `Solution` of `march` (with ``t_eval`` or events), of ``solve_bvp`` (fixed
            ends, or a transfer ``AtEnergy``) or of ``solve_periodic``.
        cotangent: what ``L`` weighs. A march: ``(len(sol.t_eval), 2n)`` on the states at
            ``t_eval`` (rows ``(q, p)``), or a mapping with ``"states"`` (that array) and/or
            ``"event_times"`` (one ``(len(sol.t_events[j]),)`` array per event function; needs
            ``march(..., output=Output(events=...), derivatives=...)``, whose record keeps
            what the sweep needs). A grid solution: the mapping its family's gradient reads
            (``bvp_gradient``, ``transfer_gradient``, ``orbit_gradient``).
        options: a march's: ``check`` (default ``True``: the gradient's own check, ``L`` along
            a random direction by a central difference of two marches again, with ``sol``'s
            scheme, first step, parameters and ``t_end``, and ``steps``, ``compilation``: a
            `Solution` does not keep the ones it was marched with, give them if not the
            defaults). A fixed-end solution or a transfer: ``compilation``. A periodic orbit:
            ``system`` (required), ``params``, ``integrals``, those of the solve.

    Returns:
        A march: a `Gradient`, ``{"q0": (n,), "p0": (n,), "params": (m,)}`` (params in
        ``system.params`` order; ``"v0"`` in place of ``"p0"`` for a march from ``v0``),
        ``.check`` its `DerivativeCheck`. A grid solution: its family's ``GridGradient``.
    """
    if isinstance(sol, Solution):
        for record, (function, accepted, what) in GRID_GRADIENTS.items():
            if getattr(sol, record, None) is not None:
                _refuse_options(options, accepted, what)
                return function(sol, cotangent, **options)
    _refuse_options(options, MARCH_OPTIONS, "a march")
    return _march_gradient(sol, cotangent, **options)


def _refuse_options(options: dict, accepted: tuple, what: str) -> None:
    for name in options:
        if name not in accepted:
            raise InputError(f"gradient of {what} takes {', '.join(accepted) or 'no option'}, "
                             f"got {name}={options[name]!r:.60}")


def _march_gradient(sol, cotangent, *, check: bool = True, steps=None,
                    compilation=None) -> Gradient:
    """``gradient`` of a march (module docstring)."""
    states, event_times = _split_cotangent(sol, cotangent)
    check_solution(sol, needs_times=states is not None)
    if steps is not None:
        steps = coerce(steps, StepControl, "steps")
    n = sol.system.n
    times, rows, refused = _sweep_rows(sol, states, event_times)
    theta = np.asarray(sol.march.theta, float).ravel()
    g_z, g_theta = reverse_sweep(sol.system, sol.scheme, theta, sol.t,
                                 np.hstack([sol.q, sol.p]), times, rows[:, :, None])
    found = {"q0": g_z[:n, 0].copy(), "p0": g_z[n:, 0].copy(), "params": g_theta[:, 0].copy()}
    start = sol.march.start_velocity
    if start is not None:
        found = velocity_gradient(found, start_jacobians(
            sol.system, sol.scheme, sol.q[0], start["v0"], sol.p[0], t0=float(sol.t[0]),
            tau0=start["tau0"], theta=theta))
    if refused:
        found = {name: np.full_like(value, np.nan) for name, value in found.items()}
        return Gradient(found, DerivativeCheck(
            "not checked", np.nan, np.nan, 0.0, {}, True, np.nan, refused) if check else None)
    return Gradient(found, _check(sol, states, event_times, found, steps, compilation)
                    if check else None)


def _split_cotangent(sol, cotangent):
    """``(states (M, 2n) or None, event_times [K_j] or None)``, each checked by name."""
    if not hasattr(cotangent, "items"):
        return cotangent, None
    unknown = [name for name in cotangent if name not in ("states", "event_times")]
    if unknown or not cotangent:
        raise InputError(f"cotangent of a march: a (len(t_eval), 2n) array or a mapping with "
                         f"'states' and/or 'event_times', got keys {list(cotangent)!r}")
    return cotangent.get("states"), cotangent.get("event_times")


def _sweep_rows(sol, states, event_times):
    """The sweep's output times ``(M',)`` and cotangent rows ``(M', 2n)``: the states' at
    ``t_eval``, then ``c w`` at each crossing (module docstring); and a reason where a
    cotangent falls on a crossing refused at a tangency, else ``""``."""
    n2 = 2 * sol.system.n
    times, rows = [np.zeros(0)], [np.zeros((0, n2))]
    if states is not None:
        times.append(np.asarray(sol.t_eval, float))
        rows.append(check_cotangent(states, sol.t_eval.size, n2))
    refused = ""
    if event_times is not None:
        for j, (t_j, c_j, record) in enumerate(zip(*_event_rows(sol, event_times),
                                                   strict=True)):
            hit = (c_j != 0) & ~np.isfinite(record.weights).all(axis=1)
            if hit.any() and not refused:
                refused = (f"cotangent['event_times'][{j}] weighs crossing "
                           f"{int(np.flatnonzero(hit)[0])}, at a tangency: its time has no "
                           f"derivative (EventDerivatives.transversality)")
            weights = np.where(np.isfinite(record.weights), record.weights, 0.0)
            times.append(t_j)
            rows.append(c_j[:, None] * weights)
    return np.concatenate(times), np.concatenate(rows), refused


def _event_rows(sol, event_times):
    """``(crossing times, cotangents, records)`` per event function, checked by name."""
    derivatives = getattr(sol, "derivatives", None)
    records = getattr(derivatives, "events", None)
    if sol.t_events is None or records is None:
        raise InputError("cotangent['event_times'] needs the march's event derivatives: "
                         "march with output=Output(events=...) and derivatives=...")
    if not isinstance(event_times, (list, tuple)) or len(event_times) != len(sol.t_events):
        raise InputError(f"cotangent['event_times'] must be a list of {len(sol.t_events)} "
                         f"arrays, one per event function, got {event_times!r:.80}")
    values = []
    for j, value in enumerate(event_times):
        count = np.size(sol.t_events[j])
        name = f"cotangent['event_times'][{j}]"
        try:
            array = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"{name} must be {count} real numbers (one per crossing of event "
                             f"{j}), got {value!r:.60}") from None
        if array.shape != (count,):
            raise InputError(f"{name} must have shape ({count},) (one entry per crossing of "
                             f"event {j}), got shape {array.shape}")
        bad = np.flatnonzero(~np.isfinite(array))
        if bad.size:
            raise InputError(f"{name} must be finite, got {float(array[bad[0]])!r} at "
                             f"[{int(bad[0])}]")
        values.append(array)
    return [np.asarray(t, float) for t in sol.t_events], values, records


def _check(sol, states, event_times, found, steps, compilation):
    """The gradient's `DerivativeCheck` (``derivative_check.py``)."""
    t = sol.t
    t_eval = sol.t_eval if states is not None else np.zeros(0)
    reads = np.concatenate([t_eval, *(sol.t_events if event_times is not None else [])])
    interval = np.clip(np.searchsorted(t, reads, side="right") - 1, 0, max(t.size - 2, 0))
    last = int(interval.max()) + 1 if reads.size and t.size > 1 else 0
    conditioned = conditioning(sol.solvability, last, sol.march.solvability_warning)
    if reads.size == 0 or t.size < 2:
        return DerivativeCheck("not checked", np.nan, np.nan, 0.0, {}, *conditioned,
                               "no step before the output times")
    t_end = sol.t_end if sol.t_end is not None else t[-1]
    scheme, start = Scheme.coerce(sol.scheme), sol.march.start_velocity
    tau0 = float(t[1] - t[0]) if start is None else start["tau0"]
    if start is None and not scheme.variable_steps:  # the fixed rule's count
        tau0 = (t_end - t[0]) / (round((t_end - t[0]) / tau0) - 0.5)
    events = None if event_times is None else sol.derivatives.event_functions
    run = remarch_function(march, sol.system, scheme, (float(t[0]), t_end), tau0,
                           steps or StepControl(), compilation, t_eval, events)
    c_states = check_cotangent(states, sol.t_eval.size, 2 * sol.system.n) \
        if states is not None else None
    c_events = None if event_times is None else _event_rows(sol, event_times)[1]
    theta = np.asarray(sol.march.theta, float)
    base = {"q0": sol.q[0], **({"p0": sol.p[0]} if start is None else {"v0": start["v0"]}),
            "params": theta}
    return check_record(
        lambda inputs: _scalar(run(inputs), c_states, c_events, t_eval.size),
        base, tuple(base), lambda v: sum(float(found[name] @ v[name]) for name in v),
        sol.q[:last + 1], sol.p[:last + 1], theta, last + 1, conditioned,
        reduce=lambda value: value, t=None if start is None else t[:last + 1])


def _scalar(found, c_states, c_events, count: int):
    """``L`` of a perturbed march, or ``None`` where it misses an output time or a crossing."""
    z, t_events = found if c_events is not None else (found, None)
    total = 0.0
    if c_states is not None:
        if z is None or z.shape[0] != count:
            return None
        total += float(np.sum(c_states * z))
    for j, c_j in enumerate(c_events or ()):
        if np.size(t_events[j]) != c_j.size:
            return None
        total += float(c_j @ np.asarray(t_events[j], float))
    return total
