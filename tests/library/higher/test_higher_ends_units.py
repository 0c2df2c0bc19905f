"""A higher-order fixed-endpoint problem in other units is the same discrete solution: Newton's
round-off targets use the data's magnitude without a floor of 1, and the verification's limits
are ``tol`` times how far each row moves when the unknowns move by their sizes in the data.
Measured before the change: Pais-Uhlenbeck in lengths of ``1e-8`` on released times stopped
``3.5e-6`` of its time span and ``8.7e-7`` of its motion off the solution in units of 1, and
passed."""

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import GridOptions, HigherOrderSystem
from ddvp_nlp.solvers.higher.stepping import solve_bvp_higher

T_START, T_STOP = np.array([0.0, 0.1]), np.array([3.0, 3.1])


def pais_uhlenbeck(length: float, time: float, energy: float = 1.0, centre: float = 0.0):
    """``L = energy (x''^2 - 5 x'^2 + 4 x^2) / 2`` of ``x = (q - centre) / length`` in time
    units of ``time``; ``x = cos t`` solves it."""
    def lagrangian(q, v, t):
        x = (q[0] - centre) / length
        v1, v2 = v[0][0] * time / length, v[1][0] * time ** 2 / length
        return energy * (v2 ** 2 - 5 * v1 ** 2 + 4 * x ** 2) / 2
    return HigherOrderSystem(lagrangian, 1, 2, name=f"pu {length:g} {time:g} {energy:g}")


def solved(scheme: str, length=1.0, time=1.0, energy=1.0, centre=0.0):
    return solve_bvp_higher(pais_uhlenbeck(length, time, energy, centre), T_START * time,
                            (centre + length * np.cos(T_START))[:, None], T_STOP * time,
                            (centre + length * np.cos(T_STOP))[:, None], nodes=41,
                            scheme=scheme)


@functools.cache
def reference(scheme: str):
    return solved(scheme)


def assert_same(scheme, length=1.0, time=1.0, energy=1.0, centre=0.0, digits=1e-10):
    base, other = reference(scheme), solved(scheme, length, time, energy, centre)
    assert other.status is base.status, other.message
    assert other.verdict.name == base.verdict.name
    assert np.max(np.abs(other.t / time - base.t)) <= digits * T_STOP[-1]
    assert np.max(np.abs((other.q - centre) / length - base.q)) <= digits


@pytest.mark.slow_when(lambda length, time, **_: (length, time) != (1e-8, 1.0), why="repetition")
@pytest.mark.parametrize("scheme", ["fixed", "vddvp"])
@pytest.mark.parametrize("length, time", [(1e-8, 1.0), (1.0, 1e5), (1e8, 1.0)])
def test_other_units_give_the_same_nodes(scheme, length, time):
    assert_same(scheme, length, time)


def test_a_lagrangian_in_other_units_of_energy_and_an_offset_origin():
    assert_same("vddvp", energy=1e-12)
    assert_same("vddvp", centre=1e4, digits=1e-8)


@settings(max_examples=3, deadline=None, derandomize=True)
@given(length=st.floats(-9, 9), time=st.floats(-3, 3))
def test_drawn_units(length, time):
    assert_same("vddvp", 10.0 ** length, 10.0 ** time)


def solved_by_ipopt(scheme: str, length=1.0, time=1.0):
    return solve_bvp_higher(pais_uhlenbeck(length, time), T_START * time,
                            (length * np.cos(T_START))[:, None], T_STOP * time,
                            (length * np.cos(T_STOP))[:, None], nodes=41, scheme=scheme,
                            options=GridOptions(solver="ipopt"))


@pytest.mark.parametrize("scheme, length, time", [("fixed", 1e6, 1e-3), ("vddvp", 1e-8, 1.0)])
def test_ipopt_finds_the_same_grid_in_other_units(scheme, length, time):
    """IPOPT on the unknowns and rows divided by their sizes (``window_nlp._sizes``). On the
    raw rows the fixed-step problem was ``not_verified`` in lengths of ``1e6`` with time units
    of ``1e-3`` and the energy rule ``solver_failed`` in lengths of ``1e-8``; units of 1 solve
    both (the energy rule's grid at 41 nodes is ``inaccurate``, in every unit system alike)."""
    base, other = solved_by_ipopt(scheme), solved_by_ipopt(scheme, length, time)
    assert other.status is base.status, other.message
    assert other.verdict.name == base.verdict.name
    assert np.max(np.abs(other.t / time - base.t)) <= 1e-10 * T_STOP[-1]
    assert np.max(np.abs(other.q / length - base.q)) <= 1e-10
