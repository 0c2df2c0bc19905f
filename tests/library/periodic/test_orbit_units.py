"""A periodic orbit is the same orbit in any units, wherever the origin and whatever constant
is added to ``H``.

The same swing, ``H = (L/T)^2 ((p T/L)^2 / 2 + 1 - cos((q - c)/L)) + C`` at the energy
``(L/T)^2 / 2 + C``, is solved in lengths ``L``, times ``T``, with the origin moved by ``c`` and
``H`` offset by ``C``; in units of the first system its period and nodes must be the same discrete
orbit (Newton's targets and the verification's limits are read off the rows, not a floor of 1).
Before, the start's march took its first step from ``|z| / |f(z)|`` with floors and Newton's
targets from ``max(1, |x|, |E|)``: lengths of ``1e-8`` and times of ``1e-4`` or ``1e5`` ended
``solver_failed`` with periods 300-10000 times the swing's, and with the start fixed alone the
period in lengths of ``1e-8`` was still ``1e-7`` off.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import ddvp_nlp as dn

NODES = 61
# Two solutions of the same discrete equations, each to its rows' round-off: their periods and
# nodes agree to the conditioning of the closed grid (about 1e3 round-offs on this swing).
AGREE = 1e-11


def swing(length=1.0, time=1.0, centre=0.0, offset=0.0):
    def H(q, p, t=None):
        u = length / time
        return u ** 2 * ((p[0] / u) ** 2 / 2 + 1 - ca.cos((q[0] - centre) / length)) + offset
    return dn.HamiltonianSystem(H, 1, name="swing"), 0.5 * (length / time) ** 2 + offset


def solved(length=1.0, time=1.0, centre=0.0, offset=0.0, solver="newton"):
    system, energy = swing(length, time, centre, offset)
    solution = dn.solve_periodic(system, energy=energy, nodes=NODES, section="p1=0",
                                 options=dn.GridOptions(solver=solver))
    assert solution.status is dn.Status.SUCCESS, solution.message
    # back to the first system's units, the angle about the well of the swing found (the
    # potential repeats every 2 pi: the well nearest the section's point is another copy)
    angle = (solution.q[:, 0] - centre) / length
    return (solution.t / time, angle - 2 * np.pi * np.round(np.mean(angle) / (2 * np.pi)),
            solution.p[:, 0] * time / length)


@pytest.fixture(scope="module")
def reference():
    return solved()


def _same(found, reference):
    t, q, p = found
    t0, q0, p0 = reference
    assert abs(t[-1] - t0[-1]) <= AGREE * t0[-1]
    np.testing.assert_allclose(t, t0, rtol=0, atol=AGREE * t0[-1])
    np.testing.assert_allclose(q, q0, rtol=0, atol=AGREE * np.ptp(q0))
    np.testing.assert_allclose(p, p0, rtol=0, atol=AGREE * np.ptp(p0))


@pytest.mark.slow_when(lambda length, time, **_: (length, time) not in ((1e-8, 1.0), (1.0, 1e5)),
                       why="repetition")
@pytest.mark.parametrize("length, time", [(1e-8, 1.0), (1e8, 1.0), (1.0, 1e-4), (1.0, 1e5),
                                          (1e-6, 1e3)])
def test_units(reference, length, time):
    _same(solved(length, time), reference)


@pytest.mark.parametrize("centre, offset", [(1e4, 0.0), (0.0, 1e4), (-3e3, -50.0)])
def test_origin_and_energy_offset(reference, centre, offset):
    """A moved origin or a constant in ``H`` costs digits (the rows' round-off grows with
    ``|q|`` and ``|H|``): the limits follow, and the orbit is the same to that round-off. The
    section's first point along the ray may be the other turning point (the ray starts at the
    old origin), so the orbit is compared by its period and its extent."""
    t, q, p = solved(centre=centre, offset=offset)
    t0, q0, p0 = reference
    energy = 0.5  # the swing's, in the first system's units
    lost = 1e3 * np.finfo(float).eps * max(abs(centre) / np.ptp(q0), abs(offset) / energy, 1.0)
    assert abs(t[-1] - t0[-1]) <= lost * t0[-1]
    for found, expected in ((q, q0), (p, p0)):
        np.testing.assert_allclose([found.min(), found.max()], [expected.min(), expected.max()],
                                   rtol=0, atol=lost * np.ptp(expected))


def test_ipopt_in_small_units(reference):
    _same(solved(1e-8, 1e3, solver="ipopt"), reference)


@settings(max_examples=5, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.floats(-7, 7), st.floats(-4, 4))
def test_drawn_units(reference, length_digits, time_digits):
    _same(solved(10.0 ** length_digits, 10.0 ** time_digits), reference)


def test_swapped_coordinates():
    """A relabelled coordinate: the same 2-dof orbit with ``q1`` and ``q2`` swapped, its
    section relabelled with it, has the same period and nodes."""
    def H(q, p, swap):
        a, b = (1, 0) if swap else (0, 1)
        return (p[a] ** 2 + 2 * p[b] ** 2) / 2 + (1 - ca.cos(q[a])) + 0.5 * q[b] ** 2 \
            + 0.1 * q[a] * q[b]

    found = []
    for swap in (False, True):
        system = dn.HamiltonianSystem(lambda q, p, t=None, s=swap: H(q, p, s), 2, name="pair")
        solution = dn.solve_periodic(system, energy=0.4, nodes=NODES,
                                     section="p2=0" if swap else "p1=0",
                                     start=([0.3, 0.0], [0.0, 0.0]) if not swap
                                     else ([0.0, 0.3], [0.0, 0.0]))
        assert solution.status is dn.Status.SUCCESS, solution.message
        z = np.hstack([solution.q, solution.p])
        found.append((solution.t, z[:, [1, 0, 3, 2]] if swap else z))
    (t0, z0), (t1, z1) = found
    assert abs(t1[-1] - t0[-1]) <= AGREE * t0[-1]
    np.testing.assert_allclose(z1, z0, atol=AGREE * np.max(np.ptp(z0, axis=0)))


def _followed(length, time):
    system, _ = swing(length, time)
    unit = (length / time) ** 2
    found = dn.follow_periodic_family(system, [0.3 * unit, 0.8 * unit], nodes=NODES,
                                      continuation=dn.Continuation(exact=False, confirm=False))
    assert found.complete, found.message
    return [(member.energy / unit, member.orbit.orbit.period / time)
            for member in found.members]


@pytest.mark.slow_when(lambda length, time: time != 1.0, why="repetition")
@pytest.mark.parametrize("length, time", [(1e-8, 1.0), (1.0, 1e5)])
def test_a_family_is_followed_through_its_range_in_any_units(length, time):
    """The family's first steps come from the energy steps and the first slope ``dE/ds`` with
    no floor of ``1e-12`` on the slope (in energy units of ``1e-16`` the slope is ``3e-16``:
    the family walked in steps of ``1e-6`` of its range and stopped at ``max_orbits = 200``).
    The arclength still weighs the node values as they are, so the members' spacing depends on
    the units; each member must be the orbit the swing in lengths of 1 has at its energy."""
    members = _followed(length, time)
    energies = [energy for energy, _ in members]
    assert min(energies) <= 0.3 + 1e-12 and max(energies) >= 0.75  # the last step left 0.8
    system, _ = swing()
    for energy, period in members[::4]:
        same = dn.solve_periodic(system, energy=energy, nodes=NODES, section="p1=0")
        assert abs(period - same.orbit.period) <= AGREE * period  # measured 2.7e-16


@pytest.mark.parametrize("centre", [-5.0, 40.0, -3e3])
def test_the_default_start_does_not_depend_on_the_origin(centre):
    """The section's point is sought along a ray from the coordinates' origin, then from ``H``'s
    least value: a well away from the origin (a harmonic oscillator centred at ``q = -5``) was
    refused with "energy 0.5 is outside the range where the section p1=0 meets the energy
    surface", which is false (a helper's fresh look found it)."""
    system = dn.HamiltonianSystem(lambda q, p, t=None: p[0] ** 2 / 2 + (q[0] - centre) ** 2 / 2,
                                  1, name="well")
    solution = dn.solve_periodic(system, energy=0.5, nodes=NODES, section="p1=0")
    assert solution.status is dn.Status.SUCCESS, solution.message
    # the swing about its own well: amplitude 1 either side of the centre (the nodes need not
    # fall on the turning points: 1e-2 of it)
    assert abs((solution.q.max() + solution.q.min()) / 2 - centre) < 1e-2
    assert np.ptp(solution.q) == pytest.approx(2.0, rel=1e-2)
    assert solution.orbit.period == pytest.approx(2 * np.pi, rel=1e-3)


def test_a_section_that_misses_the_energy_says_where_the_ray_began():
    system = dn.HamiltonianSystem(lambda q, p, t=None: p[0] ** 2 / 2 + (q[0] + 5) ** 2 / 2, 1,
                                  name="well")
    with pytest.raises(dn.InputError, match=r"section q1=3 .*from H's least value at z = "
                                            r"\[-5\.0, 0\.0\].*give a start near the orbit"):
        dn.solve_periodic(system, energy=0.5, nodes=NODES, section="q1=3")
