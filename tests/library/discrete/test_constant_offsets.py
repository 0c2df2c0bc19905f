"""A constant added to ``H`` (or ``L``) changes nothing of the motion, so it must change
nothing of the steps or of the verdict's energy tests (issue 45: with ``H + 1e6`` the ``vddvp``
node times of a Stormer orbit moved by up to 0.22 time units and at ``H + 1e12`` the march took
a hundred times more steps, because the energy equation is a difference of two values of the
offset's size).

The discrete energy equation and the verdict's nodal energies are formed from ``H`` without the
terms that depend on none of ``q``, ``p``, ``t`` (`varying_part`), on the symbols; the level
test, which compares values of the whole ``H``, states its round-off floor.
"""

import functools

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import Compilation, HamiltonianSystem, LagrangianSystem, Tolerance, march
from ddvp_nlp.physics.hamiltonian import varying_part

VM = Compilation(compiler=None, fast=False)


@functools.cache  # one system per offset: a march's functions are built once per system
def stormer(c, k=1.0):
    def H(q, p, t, k):
        r = ca.sqrt(q[0] ** 2 + q[1] ** 2)
        return (p[0] ** 2 + p[1] ** 2) / 2 + k * (1 / q[0] - q[0] / r ** 3) ** 2 / 2 + c
    return HamiltonianSystem(H, 2, {"k": k}, name="stormer")


def test_the_varying_part_leaves_out_constant_and_parameter_only_terms():
    q, t, a = ca.SX.sym("q"), ca.SX.sym("t"), ca.SX.sym("a")
    symbols = ca.vertcat(q, t)
    assert str(varying_part(q ** 2 + 1e12, symbols)) == "sq(q)"
    assert str(varying_part((ca.cos(q) - 3.0) + a ** 2 + t, symbols)) == "(cos(q)+t)"
    assert str(varying_part(5.0 - (q + 2.0), symbols)) == "(-q)"
    expression = q * (q + 1e6)  # a constant inside a product is part of the motion's H
    assert varying_part(expression, symbols) is expression
    plain = ca.sin(q) + t * q
    assert varying_part(plain, symbols) is plain  # no such term: the same object


@pytest.mark.parametrize("scheme", ["vddvp", "lee"])
def test_an_offset_of_h_gives_the_same_steps_and_energy_tests(scheme):
    runs = [march(stormer(c), [0.8, 0.0], [0.05, 0.1], (0.0, 20.0), tau0=0.01, scheme=scheme,
                  compilation=VM, accuracy=Tolerance(stop=False))
            for c in (0.0, 1e6, 5e7, 1e12)]
    base = runs[0]
    for run in runs[1:]:
        assert run.t.size == base.t.size
        # the same equations, evaluated on the same expression: the Newton lands on the same
        # root; 1e-12 of the span is far below any step's own tolerance
        assert np.max(np.abs(run.t - base.t)) <= 1e-12 * 20.0
        assert run.verdict.name == base.verdict.name
        assert run.verdict.energy_drift == pytest.approx(base.verdict.energy_drift, rel=1e-9)
        # the energy residual is measured, not swallowed by the round-off of the offset
        assert np.max(np.abs(run.energy_residual)) == pytest.approx(
            np.max(np.abs(base.energy_residual)), rel=0.5, abs=1e-15)
    huge = runs[-1].verdict
    # the level test compares values of the whole H: at 1e12 it can only say its floor
    assert huge.level_round_off > 1e-4
    assert huge.level_error <= huge.level_round_off or \
        huge.level_error == pytest.approx(base.verdict.level_error, rel=0.1)


def test_an_offset_of_l_gives_the_same_steps():
    def lagrangian(c):
        return LagrangianSystem(lambda q, v, t: v[0] ** 2 / 2 + ca.cos(q[0]) + c, 1)
    runs = [march(lagrangian(c), [1.0], None, (0.0, 10.0), v0=[0.3], tau0=0.05,
                  compilation=VM, accuracy=None) for c in (0.0, 1e9)]
    assert runs[1].t.size == runs[0].t.size
    assert np.max(np.abs(runs[1].t - runs[0].t)) <= 1e-12 * 10.0


# six drawn offsets, steps and speeds (twelve before: two careful-path marches each); the
# offsets of every size up to 1e12 are test_an_offset_of_h_gives_the_same_steps_and_energy_tests
@settings(max_examples=6, derandomize=True, deadline=None, database=None)
@given(offset=st.floats(-1e10, 1e10).filter(lambda c: abs(c) > 1.0),
       tau0=st.floats(0.005, 0.05), speed=st.floats(0.02, 0.2))
def test_any_offset_gives_the_steps_of_the_plain_h(offset, tau0, speed):
    start = ([0.8, 0.05], [speed, 0.1])
    plain, shifted = (march(stormer(c), *start, (0.0, 3.0), tau0=tau0, compilation=VM,
                            accuracy=None) for c in (0.0, offset))
    assert shifted.status == plain.status
    assert shifted.t.size == plain.t.size
    assert np.max(np.abs(shifted.t - plain.t)) <= 1e-12 * 3.0


def test_the_varying_part_of_a_long_chain_of_sums_is_found_without_recursion():
    """A lattice's H is a chain of thousands of additions: the first version recursed once per
    addition and ended in RecursionError at 2048 sites. 2500 additions are still more than
    twice Python's default recursion limit (1000): a recursive walk of this chain raises
    RecursionError (tried), and building and walking it costs half of the 5000 once used."""
    q = ca.SX.sym("q", 2500)
    chain = 0
    for i in range(2500):
        chain = chain + q[i] ** 2
    expression = chain + 7.0
    stripped = varying_part(expression, q)
    probe = np.linspace(-1.0, 1.0, 2500)
    value = float(ca.Function("f", [q], [stripped])(probe))
    assert value == pytest.approx(float(np.sum(probe ** 2)), rel=1e-12)
    assert varying_part(chain, q) is chain
