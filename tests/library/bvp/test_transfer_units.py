"""A transfer at a prescribed energy, and its derivatives, in other units and with offsets: the
same transfer, the same derivatives (in their units), every check agreeing. Measured before the
change: in lengths of ``1e-8`` the transfer was ``inaccurate`` (its Newton targets and the
secant's stop were ``max(1, |x|, |E|)`` round-offs, so the prescribed energy was never
reached); in time units of ``1e5`` its time was ``4e-9`` off; in lengths of ``1e6`` and time
units of ``1e-3`` no duration was guessed (momenta sought in ``(0, 1000]``), and given one,
``dT/dE`` was 0 (the energy's column ``F(E + 1) - F(E)`` at ``E = 1e18``); ends at ``q = 1e4``
or a constant ``1e4`` added to ``H`` made the derivative checks say "disagrees" (their steps
were ``1e-5 |q|`` and ``1e-5 |E|``)."""

import functools

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import AtEnergy, HamiltonianSystem, solve_bvp
from ddvp_nlp.solvers import transfer_derivatives

NODES = 41
START, END, ENERGY = 0.1, 0.5, 1.0


def swing(length: float, time: float, centre: float = 0.0, constant: float = 0.0):
    """The pendulum ``x = (q - centre) / length`` in time units of ``time``, ``H`` plus a
    constant: ``q`` times ``length``, ``p`` times ``length / time``, ``H`` times ``(length /
    time)^2``."""
    def H(q, p, t, w):
        x, v = (q[0] - centre) / length, p[0] * time / length
        return (length / time) ** 2 * (v ** 2 / 2 + w ** 2 * (1 - ca.cos(x))) + constant
    return HamiltonianSystem(H, 1, {"w": 1.0}, name=f"swing {length:g} {time:g} {centre:g}")


def transfer(length=1.0, time=1.0, centre=0.0, constant=0.0):
    energy = (length / time) ** 2 * ENERGY + constant
    return solve_bvp(swing(length, time, centre, constant), [START * length + centre],
                     [END * length + centre], AtEnergy(energy), nodes=NODES)


@functools.cache
def reference():
    run = transfer()
    return run, transfer_derivatives(run)


def in_units(D, length: float, time: float) -> np.ndarray:
    """``dT/dq_start``, ``dT/dq_end``, ``dT/dE``, ``dT/dw`` in the units of 1."""
    T = D["transfer_time"]
    return np.array([T["q_start"][0] * length / time, T["q_end"][0] * length / time,
                     T["energy"][0] * (length / time) ** 2 / time, T["params"][0] / time])


def assert_same(length=1.0, time=1.0, centre=0.0, constant=0.0, digits=1e-9):
    base, base_D = reference()
    run = transfer(length, time, centre, constant)
    assert run.success, run.message
    assert run.verdict.name == base.verdict.name == "accurate"
    assert abs(run.transfer.transfer_time / time - base.transfer.transfer_time) \
        <= digits * base.transfer.transfer_time
    assert np.max(np.abs((run.q - centre) / length - base.q)) <= digits
    D = transfer_derivatives(run)
    assert {name: check["verdict"] for name, check in D["checks"].items()} == \
        dict.fromkeys(("q_start", "q_end", "energy", "params"), "agrees")
    expected = in_units(base_D, 1.0, 1.0)
    assert np.max(np.abs(in_units(D, length, time) - expected) / np.abs(expected)) <= 1e3 * digits


@pytest.mark.slow_when(lambda length, time: (length, time) != (1e-8, 1.0), why="repetition")
@pytest.mark.parametrize("length, time", [(1e-8, 1.0), (1.0, 1e5), (1e6, 1e-3)])
def test_other_units_give_the_same_transfer_and_derivatives(length, time):
    assert_same(length, time)


@pytest.mark.parametrize("centre, constant", [(1e4, 0.0), (0.0, 1e4)])
def test_an_offset_origin_or_energy_gives_the_same_transfer_and_checks(centre, constant):
    """The offsets' own round-off (``1e4`` eps, amplified by the grid's conditioning) bounds
    the agreement."""
    assert_same(centre=centre, constant=constant, digits=1e-8)


@settings(max_examples=2, deadline=None, derandomize=True)
@given(length=st.floats(-9, 9), time=st.floats(-4, 4))
def test_drawn_units(length, time):
    assert_same(10.0 ** length, 10.0 ** time)


def test_the_energy_column_is_exact_where_e_plus_one_is_e():
    """At ``E = 1e18`` (``E + 1 == E`` in floating point) the transfer time's derivative in
    the energy is that of units of 1, scaled."""
    _, base_D = reference()
    run = transfer(1e6, 1e-3)
    D = transfer_derivatives(run, ("energy",))
    scaled = D["transfer_time"]["energy"][0] * (1e6 / 1e-3) ** 2 / 1e-3
    assert scaled == pytest.approx(base_D["transfer_time"]["energy"][0], rel=1e-8)
