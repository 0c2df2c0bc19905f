"""`march_higher` in other units and with an offset origin: the same nodes. Its step's Newton
stopped at ``1e-13`` in the rows' units and ``1e-15`` in the unknowns' (absolute), and the
step's check read the Euler-Lagrange rows as positions whatever the units of ``L``: the fixed
steps of Pais-Uhlenbeck, 400 in units of 1, stopped at the fourth node in lengths of ``1e-8``
or time units of ``1e5`` (``residual_too_large``), and in lengths of ``1e6`` and time units of
``1e-3`` reached the end ``1e2`` of the motion off (measured before the change)."""

import functools

import numpy as np
import pytest

from ddvp_nlp import HigherOrderSystem
from ddvp_nlp.solvers.higher.stepping import march_higher

T_INIT = np.array([0.0, 0.05, 0.1, 0.15])


def pais_uhlenbeck(length: float, time: float, centre: float = 0.0):
    def lagrangian(q, v, t):
        x = q[0] / length - centre
        v1, v2 = v[0][0] * time / length, v[1][0] * time ** 2 / length
        return (v2 ** 2 - 5 * v1 ** 2 + 4 * x ** 2) / 2
    return HigherOrderSystem(lagrangian, 1, 2, name=f"pu {length:g} {time:g} {centre:g}")


def marched(length=1.0, time=1.0, centre=0.0, scheme="fixed", t_end=20.0):
    return march_higher(pais_uhlenbeck(length, time, centre), T_INIT * time,
                        (length * (np.cos(T_INIT) + centre))[:, None], t_end * time,
                        scheme=scheme)


@functools.cache
def reference(scheme: str = "fixed", t_end: float = 20.0):
    return marched(scheme=scheme, t_end=t_end)


@pytest.mark.slow_when(lambda length, time: (length, time) == (1.0, 1e5), why="repetition")
@pytest.mark.parametrize("length, time", [(1e-8, 1.0), (1.0, 1e5), (1e6, 1e-3)])
def test_fixed_steps_in_other_units_are_the_same_march(length, time):
    base, other = reference(), marched(length, time)
    assert base.success and other.success, other.message
    assert other.t.size == base.t.size and other.verdict.name == base.verdict.name
    assert np.max(np.abs(other.t / time - base.t)) <= 1e-12 * base.t[-1]
    assert np.max(np.abs(other.q / length - base.q)) <= 1e-10


def test_an_offset_origin_is_the_same_march():
    base, other = reference(), marched(centre=1e4)
    assert other.success and other.t.size == base.t.size
    assert np.max(np.abs(other.q - 1e4 - base.q)) <= 1e-6  # 1e4 eps, through 400 steps


def test_the_energy_rule_in_small_units_steps_as_in_units_of_one():
    """Released steps: the same nodes while both run (the march ends where its Newton loses
    the root, about t = 3, in any units)."""
    base, other = reference("vddvp", 3.0), marched(1e-8, scheme="vddvp", t_end=3.0)
    count = min(base.t.size, other.t.size)
    assert count > 40 and abs(other.t.size - base.t.size) <= 5
    assert np.max(np.abs(other.t[:count] - base.t[:count])) <= 1e-8
    assert np.max(np.abs(other.q[:count] / 1e-8 - base.q[:count])) <= 1e-8
