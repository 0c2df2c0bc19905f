"""The classical fourth-order Runge-Kutta step, written once.

The march uses it as the predictor of each implicit step; ``solvers/baselines/fixed_step.py``
runs it as an integrator of its own."""

from __future__ import annotations


def rk4(flow, z, t, tau, k1=None):
    """``z + tau/6 (k1 + 2 k2 + 2 k3 + k4)`` for ``z' = flow(z, t)`` (any CasADi expressions);
    ``k1``: ``flow(z, t)`` where the caller has it already."""
    k1 = flow(z, t) if k1 is None else k1
    k2 = flow(z + tau / 2 * k1, t + tau / 2)
    k3 = flow(z + tau / 2 * k2, t + tau / 2)
    k4 = flow(z + tau * k3, t + tau)
    return z + tau / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
