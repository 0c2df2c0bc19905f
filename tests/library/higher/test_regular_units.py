"""`is_regular` judges the Hessian in the highest derivative against its own largest entry, not
against ``max(1, entry)``: a Lagrangian in other units of energy is as regular as in units of 1
(on main, Pais-Uhlenbeck with ``L`` in units 1e13 times larger, so its Hessian 1e-13, was
refused as singular), and a singular one stays singular in every unit."""

import casadi as ca
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import HigherOrderSystem, InputError
from ddvp_nlp.physics.lagrangian import is_regular


def pais_uhlenbeck(unit: float) -> HigherOrderSystem:
    """``L = unit (v2^2 - (w1^2 + w2^2) v1^2 + w1^2 w2^2 q^2) / 2`` with ``w1 = 1, w2 = 2``."""
    def lagrangian(q, v, t):
        return unit * (v[1][0] ** 2 - 5 * v[0][0] ** 2 + 4 * q[0] ** 2) / 2
    return HigherOrderSystem(lagrangian, 1, 2, name="pais_uhlenbeck_in_units")


def test_pais_uhlenbeck_in_small_units_is_regular():
    """Fails on main (refused: its Hessian 1e-13 against max(1, 1e-13) = 1)."""
    assert pais_uhlenbeck(1e-13).n == 1


def _matrix(entries):
    x1, x2, t, theta = ca.SX.sym("x1", 2), ca.SX.sym("x2", 2), ca.SX.sym("t"), ca.SX.sym("p", 0)
    return ca.Function("hessian", [x1, x2, t, theta], [ca.DM(entries)])


@settings(max_examples=8, derandomize=True, deadline=None, database=None)
@given(exponent=st.floats(-30, 30))
def test_regularity_does_not_depend_on_the_units(exponent):
    scale = 10.0 ** exponent
    assert is_regular(_matrix([[2 * scale, scale], [scale, 3 * scale]]), vectors=2, n=2,
                      theta=[])
    assert not is_regular(_matrix([[scale, 2 * scale], [scale, 2 * scale]]), vectors=2, n=2,
                          theta=[])


def test_a_zero_hessian_is_singular():
    assert not is_regular(_matrix([[0.0, 0.0], [0.0, 0.0]]), vectors=2, n=2, theta=[])
    with pytest.raises(InputError, match="is singular in its highest derivative"):
        HigherOrderSystem(lambda q, v, t: q[0] * v[1][0], 1, 2, name="bad")
