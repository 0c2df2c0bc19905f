"""The shooting start (``guess="march"``) in other units: the same iterations and the same
momentum, scaled. Its miss was held to ``tol`` as an absolute number and to ``1e-3 max(1,
|q_end|)``, its differences stepped by ``1e-7 max(1, |p_0|)`` and its steps capped at ``max(1,
|p_0|)``: the swing from 0.5 to -0.3 in 10 time units, reached in 15 iterations in lengths of
1, ended short in lengths of ``1e-8`` (3 iterations) and ``1e6`` (30), on another branch
(``p_0`` of the other sign), and the solve failed (measured before the change)."""

import functools

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import HamiltonianSystem, solve_bvp


def swing(length: float):
    def H(q, p, t):
        return length ** 2 * ((p[0] / length) ** 2 / 2 + 1 - ca.cos(q[0] / length))
    return HamiltonianSystem(H, 1, name=f"swing in lengths of {length:g}")


@functools.cache
def shot(length: float):
    return solve_bvp(swing(length), [0.5 * length], [-0.3 * length], (0.0, 10.0), nodes=200,
                     guess="march")


@pytest.mark.slow_when(lambda length: length == 1e6, why="repetition")
@pytest.mark.parametrize("length", [1e-8, 1e6])
def test_shooting_takes_the_same_steps_in_any_units(length):
    base, other = shot(1.0), shot(length)
    assert base.success and other.success, other.message
    first, again = base.ends.stages[0], other.ends.stages[0]
    assert first.name == again.name == "shooting (march)"
    assert again.converged and again.iterations == first.iterations
    assert np.max(np.abs(other.p / length - base.p)) <= 1e-10 * np.ptp(base.p)
