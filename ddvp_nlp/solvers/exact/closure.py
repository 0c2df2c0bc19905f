"""The exact flow's side of a periodic orbit: its monodromy and the exact orbit near a discrete
one, both from the variational equations integrated by the one exact flow (``variational.py``,
compiled DOP853 with the tangent carried along; no equation of the scheme is used here).
The product of the segments' ``Y`` on a periodic orbit is its monodromy matrix.

Closing the exact flow (`close_exact`): Newton's method on the multiple-shooting equations, on
``S`` segments cut at fractions ``0 = s_0 < .. < s_S = 1`` of the period where the flow has grown
(``segments.py``; ``S = 1`` on an orbit whose flow never stretches anything ``GROWTH`` times)::

    phi_{(s_{j+1} - s_j) T}(z_j; u) - z_{j+1} = 0   (j < S - 1),
    phi_{(1 - s_{S-1}) T}(z_{S-1}; u) - z_0 - shift = 0          (S 2n)
    H(z_0) - E = 0,  z_0[section] - value = 0,  g_i . (z_0 - z_ref) = 0   (2 + r)

in ``(z_0, .., z_{S-1}, T, u)`` (``S 2n + 2 + r`` unknowns; the Jacobian holds each segment's
``Y_j`` and ``-I`` beside it, the period's column ``(s_{j+1} - s_j) f`` at each segment's end,
and the unfolding's): the unfolding parameters make the count square as they do for the
discrete orbit (``periodic/orbit.py``), and come out at the integrator's accuracy on an orbit of
the Hamiltonian flow. The same Newton (``flow_newton.py``) on a larger system: on one segment
it is single shooting, whose start must be within about ``1/mu`` of the orbit (``mu`` the
largest multiplier); each segment's linearisation is good over a growth of ``GROWTH`` only, so
an orbit of any instability closes (Hill's Lyapunov orbit run twice, ``mu = 3.9e6``: 8 segments,
2 iterations; single shooting diverges). Started from a discrete orbit's node 0 and period (and
its nodes at the cuts), its convergence shows that an exact orbit is there; the distance
between the two is the discrete orbit's error at node 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ...cache import cached
from .flow_newton import exact_newton
from .segments import GROWTH, exact_path, growth_cuts, starts_from_path
from .tolerance import EXACT_TOLERANCE
from .variational import RTOL, flow_scales, flow_with_derivatives

# Newton on the shooting equations: iterations, and the closure it stops at (relative to the
# orbit's size, a few hundred of DOP853's rtol).
MAX_SHOOTING_ITERATIONS = 12
CLOSURE_TARGET = EXACT_TOLERANCE.newton_tol


@dataclass
class ExactOrbit:
    """The exact flow's periodic orbit found by `close_exact`: node 0, period, unfolding
    parameters, its monodromy, and how the shooting went (``converged``, ``closure`` = the
    largest ``|phi_T(z_0) - z_0 - shift|`` relative to the orbit's size, ``iterations``);
    ``start_return`` is the same measure of the start (the discrete orbit's node 0 after its
    own period), ``distance`` the largest ``|z_0 - z_0(start)|``, ``period_derivative`` the
    exact family's ``dT/dE``, ``error_bound`` Newton's bound of its own error (its last step,
    relative to each coordinate's size, the period (or the energy's size) and the unfolding's
    size, `_Shooting.unfolding_scale`)."""

    z0: np.ndarray
    period: float
    unfolding: np.ndarray
    monodromy: np.ndarray
    field: np.ndarray
    converged: bool
    closure: float
    iterations: int
    start_return: float
    distance: float
    energy: float
    period_derivative: float
    history: list = field(default_factory=list)
    error_bound: float = np.inf
    cuts: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0]))
    starts: np.ndarray | None = None
    sizes: np.ndarray | None = None  # each coordinate's size (`variational.flow_scales`)

    def states(self, system, theta, times, rtol: float = RTOL) -> np.ndarray:
        """The exact orbit at ``times`` (from node 0's time, up to a little past the period),
        rows ``(q, p)``, from its segments' starts."""
        starts = self.z0[None, :] if self.starts is None else self.starts
        return exact_path(system, theta, starts, self.cuts, self.period, times, rtol=rtol,
                          sizes=self.sizes)

    def as_dict(self) -> dict:
        return {"converged": self.converged, "period": self.period, "energy": self.energy,
                "closure": self.closure,
                "iterations": self.iterations, "start_return": self.start_return,
                "distance": self.distance, "period_derivative": self.period_derivative,
                "unfolding": self.unfolding.tolist(),
                "z0": self.z0.tolist()}


def close_exact(system, theta, z0, period: float, *, energy: float, section_index: int,
                section_value: float, integrals=(), shift=0.0, rtol: float = RTOL,
                fixed_period: bool = False, path=None, growth: float = GROWTH) -> ExactOrbit:
    """The exact periodic orbit near ``(z_0, T)`` by Newton on the shooting equations (module
    docstring; the one Newton on the exact flow, ``flow_newton.py``, undamped), on segments cut
    where the flow grows (``segments.py``: one segment, single shooting, on an orbit whose flow
    never stretches anything ``GROWTH`` times). ``path = (t, z)``: the discrete orbit's nodes,
    read at the cuts for the segments' starts (default: the pilot run's states there);
    ``growth``: the flow's growth at which a segment ends (``inf``: single shooting).
    ``section_index`` counts ``t`` as 0 (as the discrete layouts do), so
    ``z_0[section_index - 1]`` is fixed; the integrals' phase conditions are taken at the
    start's ``z_0``. It stops where every segment's continuity and the energy equation are
    within ``CLOSURE_TARGET`` of their scales, or where the flow fails: each coordinate's size
    (`variational.flow_scales`, which also sets the flow's absolute tolerances) and the energy
    ``H`` changes by over those sizes, ``|grad H(z_0)| . sizes``; the unfolding is an orbit of
    the Hamiltonian flow's where its effect on the flow, ``|Y_u u|``, is within ``1e3 rtol`` of
    the sizes. No scale is 1 or ``|z_0|``: the same orbit to the same share of its size in any
    units and with the origin moved. The orbit's ``period_derivative`` (``dT/dE`` along the
    exact family, at fixed section and phases) comes from the last Newton matrix. With
    ``fixed_period`` the period is held and the energy is the unknown (``energy`` its start):
    regular through a fold in ``E``, where ``dT/dE`` passes infinity and ``dE/dT`` zero."""
    integrals = tuple(integrals)
    k, r = 2 * system.n, len(integrals)
    reference = np.array(z0, float)
    shift = np.broadcast_to(np.asarray(shift, float), (k,))
    gradient = _gradients_function(system, integrals)
    generators = _generators(np.asarray(gradient(reference, theta))[:, 1:]) if r else \
        np.zeros((0, k))
    sizes = flow_scales(system, theta, reference, period)
    cuts = growth_cuts(system, theta, reference, period, integrals=integrals, rtol=rtol,
                       growth=growth, sizes=sizes)
    S = cuts.size - 1
    starts = starts_from_path(*path, cuts) if path is not None and S > 1 else \
        _pilot_starts(system, theta, reference, period, cuts, rtol, sizes)
    shooting = _Shooting(system, theta, integrals, gradient, generators, cuts, shift,
                         section_index, section_value, reference, rtol, fixed_period, sizes)
    level0 = energy if fixed_period else period
    level_scale = shooting.energy_size(reference) if fixed_period else abs(float(period))
    tiled = np.tile(sizes, S)
    result = exact_newton(
        lambda x: shooting.evaluate(x, period, energy),
        lambda _x, F, payload: np.linalg.solve(payload[1], -F),
        np.concatenate([starts.ravel(), [level0], np.zeros(1 + r)]),
        size=lambda F: float(np.max(np.abs(F[:S * k]) / tiled)),
        converged=lambda _F, payload: payload[2], max_iterations=MAX_SHOOTING_ITERATIONS,
        step_size=lambda dx: float(np.max(np.abs(dx) / np.r_[tiled, level_scale,
                                                                 shooting.u_scale])))
    flows, rows, _ = result.payload
    z, u = result.x[:k], result.x[S * k + 1:]
    monodromy = np.eye(k)
    for flow in flows:
        monodromy = flow.monodromy @ monodromy
    success = all(flow.success for flow in flows)
    if fixed_period:  # dE/dT: the closures' derivative in T is each segment's end field
        T, energy = float(period), result.x[S * k]
        derivative = np.linalg.solve(rows, -np.r_[shooting.period_column(flows),
                                                  np.zeros(2 + r)])
        period_derivative = 1.0 / derivative[S * k] if derivative[S * k] != 0 else np.inf
    else:
        T = result.x[S * k] if result.iterations else float(period)
        energy_row = np.zeros(S * k + 2 + r)
        energy_row[S * k] = 1.0
        period_derivative = float(np.linalg.solve(rows, energy_row)[S * k])
    # an orbit of the Hamiltonian flow: the unfolding's effect at the integrator's accuracy
    converged = bool(result.converged and success
                     and np.max(np.abs(u) / shooting.u_scale) <= 1e3 * rtol)
    history = shooting.history
    return ExactOrbit(z0=z, period=T, unfolding=u, monodromy=monodromy, field=flows[-1].field,
                      converged=converged, closure=history[-1], iterations=len(history) - 1,
                      start_return=history[0], distance=float(np.max(np.abs(z - z0))),
                      energy=float(energy), period_derivative=float(period_derivative),
                      history=history, error_bound=result.error_bound, cuts=cuts,
                      starts=result.x[:S * k].reshape(S, k).copy(), sizes=sizes)


def _pilot_starts(system, theta, z0, period, cuts, rtol, sizes) -> np.ndarray:
    """The segments' starts from one run of the flow from ``z0`` (row 0 is ``z0``)."""
    if cuts.size == 2:
        return np.asarray(z0, float)[None, :]
    return exact_path(system, theta, np.asarray(z0, float)[None, :], np.array([0.0, 1.0]),
                      period, cuts[:-1] * period, rtol=rtol, sizes=sizes)


class _Shooting:
    """The multiple-shooting equations of `close_exact` and their Jacobian, in ``x = (z_0, ..,
    z_{S-1}, T or E, u)``; ``history``: every evaluation's largest continuity defect relative to
    the orbit's size."""

    def __init__(self, system, theta, integrals, gradient, generators, cuts, shift,
                 section_index, section_value, reference, rtol, fixed_period, sizes):
        self.system, self.theta, self.integrals = system, theta, integrals
        self.gradient, self.generators, self.cuts = gradient, generators, cuts
        self.fractions = np.diff(cuts)
        self.shift, self.section_index, self.section_value = shift, section_index, section_value
        self.reference, self.rtol, self.fixed_period = reference, rtol, fixed_period
        self.sizes = np.asarray(sizes, float)
        self.k = 2 * system.n
        self.history = []
        # each unfolding parameter's size: the value whose effect on the flow over the period
        # is each coordinate's size (`unfolding_scale`, set by every evaluation)
        self.u_scale = np.ones(1 + len(integrals))

    def energy_size(self, z) -> float:
        """What ``H`` changes by over the sizes at ``z``: ``|grad H(z)| . sizes``."""
        grad = np.asarray(self.gradient(z, self.theta), float)[:, 0]
        return max(float(np.abs(grad) @ self.sizes), np.finfo(float).tiny)

    def unfolding_scale(self, flows) -> np.ndarray:
        """Each unfolding parameter's size: ``1 / max_i |(Y_u)_i| / sizes_i`` over the
        segments (``Y_u``: the flow's derivative in the parameter)."""
        effect = np.max([np.max(np.abs(flow.unfolding) / self.sizes[:, None], axis=0)
                         for flow in flows], axis=0)
        with np.errstate(divide="ignore"):
            scale = np.where(effect > 0, 1.0 / effect, np.inf)
        return np.where(np.isfinite(scale), scale, self.u_scale)

    def evaluate(self, x, period, energy):
        k, S = self.k, self.fractions.size
        starts, u = x[:S * k].reshape(S, k), x[S * k + 1:]
        T, level = (period, x[S * k]) if self.fixed_period else (x[S * k], energy)
        flows = [flow_with_derivatives(self.system, self.theta, starts[j],
                                       self.fractions[j] * T, integrals=self.integrals,
                                       unfolding=u, rtol=self.rtol, sizes=self.sizes)
                 for j in range(S)]
        following = np.vstack([starts[1:], starts[:1] + self.shift])
        closing = np.concatenate([flows[j].z - following[j] for j in range(S)])
        z = starts[0]
        n = k // 2
        H = float(self.system.energy(z[None, :n], z[None, n:], [0.0], self.theta)[0])
        F = np.concatenate([closing, [H - level, z[self.section_index - 1] - self.section_value],
                            self.generators @ (z - self.reference)])
        self.history.append(float(np.max(np.abs(closing) / np.tile(self.sizes, S))))
        rows = self.matrix(flows, np.asarray(self.gradient(z, self.theta))[:, 0], T)
        closed = self.history[-1] <= CLOSURE_TARGET and \
            abs(F[S * k]) <= CLOSURE_TARGET * self.energy_size(z)
        failed = not all(f.success for f in flows) or not np.all(np.isfinite(F))
        if not failed:
            self.u_scale = self.unfolding_scale(flows)
        return (None if failed and not closed else F), (flows, rows, closed)

    def period_column(self, flows) -> np.ndarray:
        """The closures' derivative in ``T``: each segment's end field times its fraction."""
        return np.concatenate([flow.field * s for flow, s in zip(flows, self.fractions,
                                                                strict=True)])

    def matrix(self, flows, energy_gradient, T):
        """The Jacobian (module docstring): block ``j`` of the continuity rows holds ``Y_j`` in
        its own start's columns and ``-I`` in the next one's (segment ``S-1``: node 0's), the
        period's column and the unfolding's; then the energy, section and phase rows on
        ``z_0``. With ``fixed_period`` the column of ``E`` instead of ``T``'s."""
        k, S, r = self.k, self.fractions.size, self.generators.shape[0]
        size = S * k + 2 + r
        rows = np.zeros((size, size))
        for j, flow in enumerate(flows):
            block = slice(j * k, (j + 1) * k)
            rows[block, block] += flow.monodromy
            following = (j + 1) % S
            rows[block, following * k:(following + 1) * k] -= np.eye(k)
            rows[block, S * k + 1:] = flow.unfolding
        if self.fixed_period:
            rows[S * k, S * k] = -1.0
        else:
            rows[:S * k, S * k] = self.period_column(flows)
        rows[S * k, :k] = energy_gradient
        rows[S * k + 1, self.section_index - 1] = 1.0
        rows[S * k + 2:, :k] = self.generators
        return rows


def _gradients_function(system, integrals) -> ca.Function:
    """``(z, theta) -> [grad H, grad I_1, ...]`` (``2n x (1 + r)``)."""
    def build():
        z = ca.vertcat(system.q, system.p)
        columns = [ca.gradient(system.H, z)] + [
            ca.gradient(integral(system.q, system.p), z) for integral in integrals]
        return ca.Function("exact_gradients", [z, system.theta], [ca.horzcat(*columns)])
    return cached(system, ("exact_gradients", tuple(integrals)), build)


def _generators(gradients: np.ndarray) -> np.ndarray:
    """``J grad I_i`` as rows, from the gradients as columns ``(2n, r)``."""
    n = gradients.shape[0] // 2
    return np.vstack([gradients[n:], -gradients[:n]]).T


def exact_field_directions(system, theta, z0, integrals=()) -> np.ndarray:
    """The directions the exact monodromy fixes at ``z_0``: the flow ``f(z_0) = J grad H`` and
    each symmetry's generator ``J grad I_i``, as columns ``(2n, 1 + r)``."""
    gradients = np.asarray(_gradients_function(system, tuple(integrals))(
        np.asarray(z0, float), np.asarray(theta, float)))
    return _generators(gradients).T


def nearest_exact_orbit(system, theta, t, z, *, energy: float, section_index: int,
                        section_value: float, integrals=(), shift=0.0) -> ExactOrbit:
    """The exact periodic orbit nearest a discrete one (nodes ``t``, ``z``: one period, the
    last node the first shifted by ``shift``) by `close_exact` from its node 0 and period, the
    segments' starts read from its nodes: whether the discrete orbit is near an orbit of the
    flow however unstable (``ExactOrbit.states`` reads the exact one at its times)."""
    t, z = np.asarray(t, float), np.asarray(z, float)
    return close_exact(system, theta, z[0], float(t[-1] - t[0]), energy=energy,
                       section_index=section_index, section_value=section_value,
                       integrals=integrals, shift=shift, path=(t, z))
