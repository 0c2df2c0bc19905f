"""The exact flow over each of many short intervals, each from its own state (the local error
of every step of a trajectory): one DOP853 step per interval with its embedded error estimate,
compiled as a CasADi ``map`` over blocks of intervals; only the intervals whose estimate
passes the caller's budget are done again with 2, 4, ... substeps (step doubling)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ...blocks import evaluate_in_blocks
from ...cache import cached
from ..columns import row_max_ratio
from ..compiler import RentedBuffer
from .attempt import combination, dop853_step
from .flow import flow_field
from .tableau import dop853

BLOCK = 4096  # intervals per call (the last block padded: blocks.py)
MAX_SUBSTEPS = 256
# The embedded estimate is no bound of the order-8 result's error: on the pendulum (H = 0.25
# and 1.999), Kepler e = 0.9 and Henon-Heiles' chaotic orbit with steps 0.05 .. 1 the error
# reached 15 times the estimate (inf-norms; median 1/6 .. 1/20). A step passes on one step
# only when this many estimates fit in its budget.
EMBEDDED_MARGIN = 100.0
# Round-off of a step, added to every bound per substep (relative to the state's largest
# component): the estimates see truncation only (measured: 8e-16 errors under 4e-22 estimates).
ROUND_OFF = 16 * float(np.finfo(float).eps)


def local_step_function(field: ca.Function) -> ca.Function:
    """``(z, t, h, theta) -> (z_new, estimate)``: one order-8 step and the per-component
    estimate of its error, DOP853's ``h e5 |e5| / sqrt(e5^2 + 0.01 e3^2)`` (scipy's
    ``_estimate_error``), the error of the embedded lower-order pair: on resolved steps it
    is far above the order-8 result's own error (a bound, not a sharp estimate)."""
    d, p = field.size1_in(0), field.size1_in(2)
    z, t, h = ca.SX.sym("z", d), ca.SX.sym("t"), ca.SX.sym("h")
    theta = ca.SX.sym("theta", p)

    def rhs(x, time):
        return field(x, time, theta)

    z_new, K = dop853_step(rhs, z, rhs(z, t), t, h)
    tab = dop853()
    e5, e3 = combination(K, tab.E5), combination(K, tab.E3)
    denominator = ca.sqrt(e5 ** 2 + 0.01 * e3 ** 2)
    estimate = ca.fabs(h) * ca.if_else(denominator == 0, 0.0, e5 ** 2 / denominator)  # NaN stays
    return ca.Function("local_step", [z, t, h, theta], [z_new, estimate],
                       ["z", "t", "h", "theta"], ["z_new", "estimate"], {"cse": True})


class LocalFlows:
    """``Phi_tau_k(z_k)`` for many ``(t_k, z_k, tau_k)`` at once (module docstring)."""

    def __init__(self, field: ca.Function, *, block: int = BLOCK,
                 compiler: str | None = "auto", cache_dir=None):
        self.block = int(block)
        single = local_step_function(field)
        mapped = single.map(f"local_steps_{self.block}", "serial", self.block, [3], [])
        self._buffer = RentedBuffer(mapped, compiler, cache_dir, prefix="exact")
        self.d = field.size1_in(0)

    def steps(self, t, z, h, theta, substeps: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """``substeps`` equal steps over each ``[t_k, t_k + h_k]``: the ends (M, d) and the sum of
        the substeps' estimates (M, d)."""
        t, h = np.asarray(t, float), np.asarray(h, float) / substeps
        out, bound = np.array(z, float, copy=True), np.zeros((t.size, self.d))
        self._buffer.inputs[3][:] = np.asarray(theta, float)

        def evaluate(inputs, outputs):
            state, start, step = inputs
            end, total = outputs
            total[...] = 0.0
            for j in range(substeps):
                state, estimate = self._buffer(state, start + j * step, step, None)
                total += estimate
            end[...] = state
        evaluate_in_blocks(evaluate, [out, t, h], [out, bound], count=t.size, width=self.block)
        return out, bound

    def __call__(self, t, z, tau, theta, budget, max_substeps: int = MAX_SUBSTEPS):
        """The flow over each interval with a bound of its error held below ``budget`` (per
        component, broadcast to (M, d)) where ``max_substeps`` allow: ``(phi, bound,
        substeps)``; ``substeps`` (M,) is how many substeps each result used (0: the bound
        still passes the budget at ``max_substeps``).

        Bounds are weighted norms, never single components: ``bound = r * budget`` with ``r``
        the largest ratio over the components of an estimate to its budget (a component of
        an error estimate can vanish where that component's error does not: measured on both
        estimates below). First one step for every interval, ``r`` from ``EMBEDDED_MARGIN``
        times the embedded estimate. Where ``r > 1``, step doubling: the result with ``2m``
        substeps, ``r`` from ``|Phi_m - Phi_2m|`` (for an order-8 method about 255 times the
        error of ``Phi_2m`` on resolved steps; measured error / bound <= 0.04). Both add
        ``ROUND_OFF`` per substep."""
        with np.errstate(invalid="ignore", over="ignore"):  # non-finite flows: NaN ratios, kept
            return self._within(np.asarray(t, float), np.asarray(z, float),
                                np.asarray(tau, float), theta, budget, max_substeps)

    def _within(self, t, z, tau, theta, budget, max_substeps):
        budget = np.broadcast_to(np.asarray(budget, float), z.shape)
        phi, estimate = self.steps(t, z, tau, theta)
        size = row_max_ratio(np.maximum(np.abs(z), np.abs(phi)), np.ones((1, self.d)))[:, None]
        ratio = row_max_ratio(EMBEDDED_MARGIN * estimate + ROUND_OFF * size, budget)
        used = np.ones(t.size, int)
        todo = np.flatnonzero(~(ratio <= 1))
        m = 1
        while todo.size and 2 * m <= max_substeps:
            finer, _ = self.steps(t[todo], z[todo], tau[todo], theta, 2 * m)
            ratio[todo] = row_max_ratio(np.abs(finer - phi[todo]) + 2 * m * ROUND_OFF * size[todo],
                                 budget[todo])
            phi[todo] = finer
            used[todo] = 2 * m
            todo = todo[~(ratio[todo] <= 1)]
            m *= 2
        used[todo] = 0
        return phi, ratio[:, None] * budget, used


def short_flows(system, *, compiler: str | None = "auto", cache_dir=None) -> LocalFlows:
    """The `LocalFlows` of ``system``'s exact flow, built once per system and compiler."""
    return cached(system, ("short_flows", compiler, str(cache_dir)), lambda: LocalFlows(
        flow_field(system)[0], compiler=compiler, cache_dir=cache_dir))
