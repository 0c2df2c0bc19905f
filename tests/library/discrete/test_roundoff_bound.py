"""The running error bound of an expression's evaluation (``physics/roundoff.py``) bounds the
round-off it has, judged against exact arithmetic, and scales with the expression's units.

Random rational expressions (sums, differences, products, quotients and squares of inputs and
constants) are evaluated by CasADi in double precision and by Python's ``Fraction`` exactly on
the same double inputs; the error must be within ``eps`` times the bound (a first-order bound:
a factor 2 covers the second-order terms at these depths)."""

from __future__ import annotations

from fractions import Fraction

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp.physics.roundoff import roundoff_bound

EPS = np.finfo(float).eps
N_INPUTS = 3

finite = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False, allow_infinity=False)


@st.composite
def programs(draw):
    """A list of instructions ``(op, i, j)`` on a growing list of values (the inputs first)."""
    count = draw(st.integers(1, 12))
    steps = []
    for k in range(count):
        size = N_INPUTS + 1 + k  # the inputs, one constant, then each result
        steps.append((draw(st.sampled_from(["add", "sub", "mul", "div", "sq"])),
                      draw(st.integers(0, size - 1)), draw(st.integers(0, size - 1))))
    return steps


_OPS = {"add": lambda a, b: a + b, "sub": lambda a, b: a - b, "mul": lambda a, b: a * b,
        "div": lambda a, b: a / (1 + b * b), "sq": lambda a, b: a * a}


def _run(steps, values, constant):
    values = list(values) + [constant]
    for op, i, j in steps:
        a, b = values[i], values[j]
        # a quotient by 1 + b^2, never by 0, the same in both arithmetics
        values.append(_OPS[op](a, b))
    return values[-1]


@settings(max_examples=200, derandomize=True, deadline=None, database=None)
@given(programs(), st.lists(finite, min_size=N_INPUTS, max_size=N_INPUTS), finite)
def test_the_bound_bounds_the_round_off_against_exact_arithmetic(steps, inputs, constant):
    x = ca.SX.sym("x", N_INPUTS)
    expression = _run(steps, [x[i] for i in range(N_INPUTS)], ca.SX(constant))
    function = ca.Function("f", [x], [expression])
    bound = float(roundoff_bound(function, (0,))(inputs))
    value = float(function(inputs))
    exact = _run(steps, [Fraction(v) for v in inputs], Fraction(constant))
    if not (np.isfinite(value) and np.isfinite(bound) and bound < 1e300):
        return  # an overflow: no round-off to bound
    assert abs(value - float(exact)) <= 2 * EPS * bound + 1e-300


def test_one_minus_cos_carries_the_round_off_of_its_terms():
    q = ca.SX.sym("q")
    function = ca.Function("V", [q], [1 - ca.cos(q)])
    for amplitude in (1e-3, 1e-6):
        bound = float(roundoff_bound(function, (0,))(amplitude))
        assert 0.99 <= bound <= 1.01  # eps of cos q's size 1, not of q^2/2
        exact = 2 * np.sin(amplitude / 2) ** 2
        assert abs(float(function(amplitude)) - exact) <= EPS * bound


def test_the_bound_scales_with_the_units_and_grows_with_an_offset():
    q, p = ca.SX.sym("q", 2), ca.SX.sym("p", 2)
    kepler = ca.Function("H", [q, p], [ca.dot(p, p) / 2 - 1 / ca.norm_2(q)])
    bound = roundoff_bound(kepler, (0, 1))
    q0, p0 = np.array([0.7, 0.2]), np.array([-0.3, 1.1])
    one = float(bound(q0, p0))
    # lengths by 2^-30 and momenta by 2^15 (H by 2^30, exactly): the bound by the same factor
    scaled = float(bound(q0 * 2.0 ** -30, p0 * 2.0 ** 15))
    assert scaled == one * 2.0 ** 30
    offset = ca.Function("H", [q, p], [kepler(q, p) + 1e6])
    assert float(roundoff_bound(offset, (0, 1))(q0, p0)) >= 1e6
    # a relabelled coordinate (q1 <-> q2 with p1 <-> p2) does not change the bound
    assert float(bound(q0[::-1], p0[::-1])) == one


def test_parameters_and_constants_carry_no_round_off_of_their_own():
    q, c = ca.SX.sym("q"), ca.SX.sym("c")
    function = ca.Function("f", [q, c], [q + c])
    assert float(roundoff_bound(function, (0,))(0.0, 1e9)) == 1e9  # the sum's own rounding
    assert float(roundoff_bound(ca.Function("g", [q, c], [c * 3.0]), (0,))(0.0, 2.0)) == 6.0


def _bound_of(expression, inputs) -> float:
    x = _SYMBOLS
    return float(roundoff_bound(ca.Function("f", [x], [expression]), (0,))(inputs))


_SYMBOLS = ca.SX.sym("x", 3)


def test_each_rule_gives_the_bound_written_out_by_hand():
    """The bound's value, not only its being a bound (the comparison with exact arithmetic above
    is loose: a dropped partial or a halved rule still bounds it): each operation on inputs of
    both signs, ``e(x_i) = |x_i|``, ``e(v) = |v| + |dv/da| e(a) + |dv/db| e(b)`` by hand."""
    x = _SYMBOLS
    a, b, c = -3.0, -2.0, 5.0
    written = {
        "a + b": (x[0] + x[1], abs(a + b) + abs(a) + abs(b)),
        "a - b": (x[0] - x[1], abs(a - b) + abs(a) + abs(b)),
        "a * b": (x[0] * x[1], abs(a * b) + abs(b) * abs(a) + abs(a) * abs(b)),
        "a / b": (x[0] / x[1], abs(a / b) + abs(1 / b) * abs(a) + abs(a / b**2) * abs(b)),
        "a^2": (x[0] ** 2, a * a + 2 * abs(a) * abs(a)),
        "sin a": (ca.sin(x[0]), abs(np.sin(a)) + abs(np.cos(a)) * abs(a)),
        "exp a": (ca.exp(x[0]), np.exp(a) + np.exp(a) * abs(a)),
        "a * b + c": (x[0] * x[1] + x[2],
                      abs(a * b + c) + (abs(a * b) + 2 * abs(a * b)) + abs(c)),
    }
    for name, (expression, expected) in written.items():
        assert _bound_of(expression, [a, b, c]) == pytest.approx(expected, rel=4 * EPS), name
    # a power with both arguments unknown, on a positive base: |b a^(b-1)| e(a) + |v ln a| e(b)
    base, power = 2.0, -3.0
    value = base ** power
    expected = value + abs(power * base ** (power - 1)) * base + abs(value * np.log(base)) * 3
    assert _bound_of(x[0] ** x[1], [base, power, c]) == pytest.approx(expected, rel=4 * EPS)
