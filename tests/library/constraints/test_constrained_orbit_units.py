"""A constrained periodic orbit, and the accuracy verdict on a constrained motion, are the same in
any units.

The Cartesian pendulum ``H = |p|^2 / 2 + (L / T^2) y`` on the rod ``x^2 + y^2 = L^2``, its
libration at ``E = -(L/T)^2 / 2`` from the bottom: in lengths ``L`` and times ``T`` the same
discrete orbit. Before, Newton's targets were 64 round-offs of ``max(|q|, |p|, |E|, tau)``, which
mixes units (lengths of ``1e-8`` left the period ``1e-9`` off), and the verification's ``tol``
was absolute. The accuracy check took the rod's ``x`` in lengths of ``1e4`` for a winding angle
(its range passes a turn, ``H`` does not depend on it, the constrained field's forces made the
shift look first order): its scale was cut to one turn, and the same orbit, and the same march,
were judged inaccurate (``drifted``) where in lengths of 1 they were accurate.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import ddvp_nlp as dn

NODES = 81
AGREE = 1e-11  # two solutions of one discrete system, each to its rows' round-off


def rod(length=1.0, time=1.0):
    return dn.HamiltonianSystem(
        lambda q, p, t=None: (p[0] ** 2 + p[1] ** 2) / 2 + (length / time ** 2) * q[1], 2,
        name="rod", constraints=lambda q, t=None: q[0] ** 2 + q[1] ** 2 - length ** 2)


def orbit(length=1.0, time=1.0):
    solution = dn.solve_periodic(rod(length, time), energy=-0.5 * (length / time) ** 2,
                                 nodes=NODES, section="p1=0",
                                 start=([0.0, -length], [length / time, 0.0]))
    assert solution.status is dn.Status.SUCCESS, solution.message
    assert solution.verdict.name == "accurate", solution.message
    return solution.t / time, solution.q / length, solution.p * time / length


@pytest.fixture(scope="module")
def reference():
    return orbit()


@pytest.mark.parametrize("length, time", [(1e-8, 1.0), (1e4, 1.0), (1e8, 1.0), (1.0, 1e-4),
                                          (1.0, 1e5)])
def test_the_same_orbit_in_any_units(reference, length, time):
    t, q, p = orbit(length, time)
    t0, q0, p0 = reference
    assert abs(t[-1] - t0[-1]) <= AGREE * t0[-1]
    np.testing.assert_allclose(q, q0, rtol=0, atol=AGREE)
    np.testing.assert_allclose(p, p0, rtol=0, atol=AGREE * np.max(np.abs(p0)))


@pytest.mark.parametrize("length", [1e4, 1e8])
def test_a_constrained_march_is_judged_the_same_in_any_units(length):
    """The fixed-step march (it reaches its end; the energy rules' steps break down on this
    rod near t = 1 whatever tau0) is judged by its scales in its own units."""
    verdicts = []
    for size in (1.0, length):
        run = dn.march(rod(size), [0.0, -size], [size, 0.0], (0.0, 10.0), tau0=0.05,
                       scheme="fixed")
        assert run.status is dn.Status.SUCCESS, run.message
        verdicts.append((run.verdict.name, run.verdict.local_error_max,
                         np.asarray(run.verdict.scale) / size))
    (name, local, scale), (name_l, local_l, scale_l) = verdicts
    assert name == name_l == "accurate"
    assert local_l == pytest.approx(local, rel=1e-6)
    np.testing.assert_allclose(scale_l, scale, rtol=1e-9)


def test_a_winding_angle_on_a_periodic_constraint_is_still_one():
    """The rule's other side: a coordinate on which ``H`` and the constraints both repeat every
    ``2 pi`` (a bead on a ring parametrised by an angle ``a`` and a height held at 0) still
    counts at most a turn."""
    system = dn.HamiltonianSystem(lambda q, p, t=None: p[0] ** 2 / 2 + p[1] ** 2 / 2
                                  + 0.1 * ca.cos(q[0]), 2, name="ring",
                                  constraints=lambda q, t=None: q[1])
    run = dn.march(system, [0.0, 0.0], [2.0, 0.0], (0.0, 40.0), tau0=0.05, scheme="fixed")
    assert run.status is dn.Status.SUCCESS, run.message
    assert np.ptp(run.q[:, 0]) > 20 * np.pi
    assert run.verdict.scale[0] <= 2 * np.pi  # one turn, not the whole winding
