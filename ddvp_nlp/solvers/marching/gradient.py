"""``gradient(sol, cotangent)``: reverse mode of a march's derivatives (issue 47), the sweep
of ``adjoint.py`` on a march's kept nodes, with its own check (``derivative_check.py``: the
march run again from two perturbed starts, which is why this module sits above `march`)."""

from __future__ import annotations

import numpy as np

from ...discrete.scheme import Scheme
from ..options import StepControl, coerce
from .adjoint import check_cotangent, check_solution, reverse_sweep
from .derivative_check import DerivativeCheck, check_record, conditioning, remarch_function
from .initial_value import march

__all__ = ["Gradient", "gradient"]


class Gradient(dict):
    """``gradient``'s answer: ``{"q0": (n,), "p0": (n,), "params": (m,)}`` with its
    `DerivativeCheck` (``check``; ``None`` where not asked for)."""

    def __init__(self, values, check=None):
        super().__init__(values)
        self.check = check


def gradient(sol, cotangent, *, check: bool = True, steps=None, compilation=None) -> Gradient:
    """Reverse mode: ``dL/d(q0, p0, params)`` of ``L = sum_i cotangent[i] . (q, p)(t_eval[i])``
    of the discrete solution ``sol`` (a `march` with ``output=Output(t_eval=...)``, with or
    without ``derivatives=``), step lengths included (module docstring).

    Args:
        sol: the march's `Solution`; its accepted nodes are the whole input (a thinned,
            backward, least-squares or ``target_error`` march is refused by name; a march
            started from ``v0`` is differentiated as the march from its ``p0 = sol.p[0]``).
        cotangent: ``(len(sol.t_eval), 2n)``, finite, rows ``(q, p)``.
        check: the gradient's own check (``derivative_check.py``): ``L`` along a random
            direction by a central difference of two marches again from the perturbed
            inputs, with ``sol``'s scheme, first step ``t_1 - t_0`` (the fixed rule: its
            step count), parameters and ``t_end``, and ``steps`` and ``compilation`` (a
            `Solution` does not keep the ones it was marched with: give them if not the
            defaults).

    Returns:
        A `Gradient`: ``{"q0": (n,), "p0": (n,), "params": (m,)}`` (params in
        ``system.params`` order), ``.check`` its `DerivativeCheck`.
    """
    check_solution(sol)
    n = sol.system.n
    c = check_cotangent(cotangent, sol.t_eval.size, 2 * n)
    if steps is not None:
        steps = coerce(steps, StepControl, "steps")
    theta = np.asarray(sol.march.theta, float).ravel()
    z = np.hstack([sol.q, sol.p])
    g_z, g_theta = reverse_sweep(sol.system, sol.scheme, theta, sol.t, z, sol.t_eval,
                                 c[:, :, None])
    found = {"q0": g_z[:n, 0].copy(), "p0": g_z[n:, 0].copy(), "params": g_theta[:, 0].copy()}
    return Gradient(found, _check(sol, c, found, steps, compilation) if check else None)


def _check(sol, c, found, steps, compilation):
    """The gradient's `DerivativeCheck` (``derivative_check.py``)."""
    t = sol.t
    interval = np.clip(np.searchsorted(t, sol.t_eval, side="right") - 1, 0, max(t.size - 2, 0))
    last = int(interval.max()) + 1 if sol.t_eval.size and t.size > 1 else 0
    conditioned = conditioning(sol.solvability, last, sol.march.solvability_warning)
    if sol.t_eval.size == 0 or t.size < 2:
        return DerivativeCheck("not checked", np.nan, np.nan, 0.0, {}, *conditioned,
                               "no step before the output times")
    t_end = sol.t_end if sol.t_end is not None else t[-1]
    scheme = Scheme.coerce(sol.scheme)
    tau0 = float(t[1] - t[0])
    if not scheme.variable_steps:  # the fixed rule's count: ceil((t_end - t0) / tau0)
        tau0 = (t_end - t[0]) / (round((t_end - t[0]) / tau0) - 0.5)
    remarch = remarch_function(march, sol.system, scheme, (float(t[0]), t_end), tau0,
                               steps or StepControl(), compilation, sol.t_eval)
    base = {"q0": sol.q[0], "p0": sol.p[0], "params": np.asarray(sol.march.theta, float)}
    return check_record(
        remarch, base, ("q0", "p0", "params"),
        lambda v: sum(float(found[name] @ v[name]) for name in v),
        sol.q[:last + 1], sol.p[:last + 1], base["params"], last + 1, conditioned,
        reduce=lambda z_eval: float(np.sum(c * z_eval)))
