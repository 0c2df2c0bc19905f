"""The discrete equations of one interval and one node, as CasADi functions every solver uses.

The march stacks them for one step, the fixed-endpoint solver maps them over the whole grid, and
the checks evaluate them on results (``grid_residuals``, ``interval_energies``). Each comes from
the interval action of the system's form (``action.py``): the form is looked up once, in
``FORMS``, and no equation depends on it otherwise. Adding a form of system means one action
class and one line of ``FORMS``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..blocks import copied, evaluate_columns, evaluate_in_blocks
from ..cache import cached
from ..physics.hamiltonian import HamiltonianSystem
from ..physics.lagrangian import LagrangianSystem
from .action import IntervalAction
from .hamiltonian_action import HamiltonianAction
from .lagrangian_action import LagrangianAction
from .scheme import Scheme

CANONICAL_INPUTS = ["t_a", "t_b", "q_a", "p_a", "q_b", "p_b", "theta"]
# System forms and their interval actions, most specific first (a LagrangianSystem is also a
# HamiltonianSystem: it carries H by the Legendre transform for the monitors).
FORMS = ((LagrangianSystem, LagrangianAction), (HamiltonianSystem, HamiltonianAction))
ENERGY_INPUTS = ["t_prev", "t_mid", "t_next", "q_prev", "p_prev", "q_mid", "p_mid",
                 "q_next", "p_next", "theta"]


def _node_symbols(system: HamiltonianSystem, suffix: str):
    return (ca.SX.sym(f"t_{suffix}"), ca.SX.sym(f"q_{suffix}", system.n),
            ca.SX.sym(f"p_{suffix}", system.n))


def action_for(system, scheme: Scheme) -> IntervalAction:
    """The interval action of ``system``'s form (the first entry of ``FORMS`` it is an instance
    of)."""
    for form, action in FORMS:
        if isinstance(system, form):
            return action(system, scheme)
    raise TypeError(f"no discrete action for a {type(system).__name__}")


def interval_action_expression(system, scheme, t_a, t_b, q_a, p_a, q_b, p_b, theta):
    """``S_k`` of one interval (``hamiltonian.py``, ``lagrangian.py``)."""
    return action_for(system, scheme).action(t_a, t_b, q_a, p_a, q_b, p_b, theta)


def canonical_expression(system, scheme, t_a, t_b, q_a, p_a, q_b, p_b, theta):
    """The ``2n`` interval equations of one interval: the increment-form canonical equations
    (``q`` rows first), or for a Lagrangian system its discrete Legendre transform."""
    return action_for(system, scheme).interval_equations(t_a, t_b, q_a, p_a, q_b, p_b, theta)


def energy_expression(system, scheme, rule, t_prev, t_mid, t_next, q_prev, p_prev, q_mid, p_mid,
                      q_next, p_next, theta):
    """Energy equation at the node between interval ``k-1`` (prev, mid) and ``k`` (mid, next)."""
    return action_for(system, scheme).energy_equation(rule, t_prev, t_mid, t_next, q_prev,
                                                      p_prev, q_mid, p_mid, q_next, p_next,
                                                      theta)


def diagnostic_rule(scheme: Scheme) -> str:
    """The energy equation reported for a scheme: its own, or for ``fixed`` steps the ``lee``
    balance ``dS_D/dt_k`` that fixed steps do not enforce (for autonomous ``H`` it is the change
    of the midpoint energy, the same as ``vddvp``)."""
    return scheme.rule if scheme.variable_steps else "lee"


def canonical_function(system: HamiltonianSystem, scheme: Scheme) -> ca.Function:
    """``canonical(t_a, t_b, q_a, p_a, q_b, p_b, theta) -> residual (2n,)``."""
    def build():
        t_a, q_a, p_a = _node_symbols(system, "a")
        t_b, q_b, p_b = _node_symbols(system, "b")
        r = canonical_expression(system, scheme, t_a, t_b, q_a, p_a, q_b, p_b, system.theta)
        return ca.Function("canonical", [t_a, t_b, q_a, p_a, q_b, p_b, system.theta], [r],
                           CANONICAL_INPUTS, ["residual"])
    return cached(system, ("canonical", scheme), build)


def energy_function(system: HamiltonianSystem, scheme: Scheme, rule: str | None = None):
    """``energy(t_prev, t_mid, t_next, q_prev, p_prev, q_mid, p_mid, q_next, p_next, theta)``."""
    rule = rule or diagnostic_rule(scheme)

    def build():
        t0, q0, p0 = _node_symbols(system, "prev")
        t1, q1, p1 = _node_symbols(system, "mid")
        t2, q2, p2 = _node_symbols(system, "next")
        r = energy_expression(system, scheme, rule, t0, t1, t2, q0, p0, q1, p1, q2, p2,
                              system.theta)
        return ca.Function(f"energy_{rule}", [t0, t1, t2, q0, p0, q1, p1, q2, p2, system.theta],
                           [r], ENERGY_INPUTS, ["residual"])
    return cached(system, ("energy", rule, scheme), build)


def midpoint_energy_function(system: HamiltonianSystem, scheme: Scheme) -> ca.Function:
    """``E_k`` of one interval at its own clock (``H(Q_k, P_k, s_k)`` for a Hamiltonian): the
    energy the scheme conserves."""
    def build():
        t_a, q_a, p_a = _node_symbols(system, "a")
        t_b, q_b, p_b = _node_symbols(system, "b")
        energy = action_for(system, scheme).interval_energy(t_a, t_b, q_a, p_a, q_b, p_b,
                                                            system.theta)
        return ca.Function("interval_energy", [t_a, t_b, q_a, p_a, q_b, p_b, system.theta],
                           [energy], CANONICAL_INPUTS, ["H"])
    return cached(system, ("interval_energy", scheme), build)


def grid_residuals(system: HamiltonianSystem, scheme: Scheme, t, q, p, theta, *,
                   compile=None, block=None, block_width: int = 0):
    """All equations of a grid: canonical residuals ``(N-1, 2n)`` and energy residuals ``(N-2,)``
    of the scheme's diagnostic rule, unscaled. ``compile`` (``Function -> Function``, e.g. a
    C compiler's) runs the block-mapped equations compiled; see `evaluate_columns`.

    ``block``: the same equations of ``block_width`` intervals in one function, ``(T (W + 2),
    Z (W + 2, 2n)) -> (canonical (W, 2n), energy (W, 1))`` (the canonical equations of the
    intervals from the first ``W`` nodes, the energy equations at the ``W`` nodes after the
    first; ``solvers/marching/recheck.py`` compiles it), called block by block in place of
    the mapped functions for a grid of 3 nodes or more; its parameters are the caller's to set."""
    t = np.asarray(t, float)
    q = np.asarray(q, float)
    p = np.asarray(p, float)
    N = t.size
    if block is not None and N >= 3:
        z = np.column_stack([q.reshape(N, -1), p.reshape(N, -1)])
        canonical, energy = np.empty((N - 1, 2 * system.n)), np.empty(N - 2)
        # block k reads nodes k W .. k W + W + 1 (the last block's missing nodes: the last node
        # repeated; their residuals are not kept)
        evaluate_in_blocks(copied(block), [t, z], [canonical, energy], count=N - 1,
                           width=block_width, halo=2)
        return canonical, energy
    theta = np.asarray(theta, float)
    canonical = np.zeros((max(N - 1, 0), 2 * system.n))
    energy = np.zeros(max(N - 2, 0))
    if N >= 2:
        f = canonical_function(system, scheme)
        canonical = evaluate_columns(system, f, [t[None, :-1], t[None, 1:], q[:-1].T, p[:-1].T,
                                                 q[1:].T, p[1:].T], theta, compile=compile).T
    if N >= 3:
        g = energy_function(system, scheme)
        energy = evaluate_columns(system, g, [t[None, :-2], t[None, 1:-1], t[None, 2:],
                                              q[:-2].T, p[:-2].T, q[1:-1].T, p[1:-1].T,
                                              q[2:].T, p[2:].T], theta, compile=compile).ravel()
    return canonical, energy


def interval_energies(system: HamiltonianSystem, scheme: Scheme, t, q, p, theta):
    """``H(Q_k, P_k, s_k)`` for every interval, shape ``(N-1,)``."""
    t = np.asarray(t, float)
    q = np.asarray(q, float)
    p = np.asarray(p, float)
    if t.size < 2:
        return np.zeros(0)
    f = midpoint_energy_function(system, scheme)
    return evaluate_columns(system, f, [t[None, :-1], t[None, 1:], q[:-1].T, p[:-1].T,
                                        q[1:].T, p[1:].T], theta).ravel()
