"""The chaos indicators do not depend on the units of a coordinate or of time, nor on where the
origin is: the tangent's norm is ``|W dz|``, a symplectic scaling of each pair ``(q_i, p_i)``
read off the flow at the start. With the plain norm ``|dz|`` a Henon-Heiles orbit's FLI was
2.76 in time units of 1 and 13.5 in time units of ``1e5`` (``ln 1e5`` more), its MEGNO 1.58
and 2.06 (a torus's 2 crossed), its largest exponent five times larger (measured before)."""

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import Compilation, HamiltonianSystem
from ddvp_nlp.solvers import chaos_indicators, lyapunov_spectrum

START = (0.0, -0.1, 0.49, 0.0)
# CasADi's virtual machine: every unit system is a system of its own, and gcc would compile
# each one's chunk (3-5 s) for a march of 0.2 s
VM = Compilation(compiler=None)


def henon_heiles(length: float, time: float, centre: float = 0.0, ratio: float = 1.0):
    """Henon-Heiles in lengths of ``length`` (``q_2`` in ``ratio`` times that), time units of
    ``time``, the origin at ``centre`` lengths."""
    def H(q, p, t):
        x, y = q[0] / length - centre, q[1] / (ratio * length)
        u, v = p[0] * time / length, p[1] * time * ratio / length
        return (length / time) ** 2 * ((u ** 2 + v ** 2) / 2 + (x ** 2 + y ** 2) / 2
                                       + x ** 2 * y - y ** 3 / 3)
    return HamiltonianSystem(H, 2, name=f"hh {length:g} {time:g} {centre:g} {ratio:g}")


def indicators(length=1.0, time=1.0, centre=0.0, ratio=1.0, t_end=100.0, spectrum=False):
    x, y, u, v = START
    q0 = [(x + centre) * length, y * ratio * length]
    p0 = [u * length / time, v * length / (time * ratio)]
    system = henon_heiles(length, time, centre, ratio)
    if spectrum:
        return lyapunov_spectrum(system, q0, p0, (0.0, t_end * time), tau0=0.05 * time,
                                 compilation=VM)
    return chaos_indicators(system, q0, p0, (0.0, t_end * time), tau0=0.05 * time,
                            compilation=VM)


@functools.cache
def reference():
    return indicators()


def assert_same(other, time: float, digits: float = 1e-4):
    """The same to the march's round-off in other units, which the orbit's divergence
    amplifies (6e-6 of the largest exponent by t = 200, measured); the plain norm was off by
    ``ln(1e5) / t`` in time units of 1e5, 0.12 at t = 100."""
    base = reference()
    assert other.status.code == base.status.code == "success"
    assert other.steps == base.steps
    assert other.megno == pytest.approx(base.megno, rel=digits)
    assert other.fli == pytest.approx(base.fli, rel=digits)
    assert other.lyapunov * time == pytest.approx(base.lyapunov, rel=digits)


@pytest.mark.parametrize("length, time, ratio", [(1.0, 1e5, 1.0), (1e-8, 1.0, 1.0),
                                                 (1.0, 1.0, 1e3)])
def test_units_of_length_time_or_one_coordinate_leave_the_indicators(length, time, ratio):
    assert_same(indicators(length, time, ratio=ratio), time)


def test_an_offset_origin_leaves_the_indicators():
    assert_same(indicators(centre=1e4), 1.0, digits=1e-3)


@settings(max_examples=2, deadline=None, derandomize=True)
@given(length=st.floats(-6, 6), time=st.floats(-3, 3))
def test_drawn_units(length, time):
    assert_same(indicators(10.0 ** length, 10.0 ** time), 10.0 ** time)


def test_the_spectrum_still_pairs_and_follows_the_time_unit():
    base, other = indicators(spectrum=True), indicators(time=1e4, spectrum=True)
    assert np.max(np.abs(other.pair_sums * 1e4)) < 1e-9
    assert np.allclose(other.exponents * 1e4, base.exponents, rtol=1e-6, atol=1e-9)
