"""A coordinate that winds (one ``H`` does not depend on: an azimuth, the polar angle of a
central force) must not set the scales the other coordinates and the energy are judged by.

Its range grows without bound over a long run while the rest of the motion stays put; when it
set its block's floor, a spherical pendulum's polar angle was judged against hundreds of
radians and the energy against a scale a thousand times ``|H|`` (issue 45). Two properties:

- on the spherical pendulum, the polar angle's scale is its own range and the energy scale
  does not grow with the horizon;
- metamorphic, on random systems: adding a winding coordinate ``q_c`` with ``H' = H + p_c w(q)``
  and ``p_c = 0`` leaves the motion of ``(q, p)`` as it was (``p_c`` stays 0, so ``q`` feels no
  force from it) while ``q_c`` winds at the rate ``w(q) > 0``; the verdict and the scales of
  the old components must not change.
"""

import casadi as ca
import numpy as np
import pytest
from helpers.random_cases import cases_and_units
from hypothesis import HealthCheck, assume, given, settings

from ddvp_nlp import Compilation, HamiltonianSystem, Tolerance, march
from ddvp_nlp.solvers.accuracy.judgement import free_components

VM = Compilation(compiler=None, fast=False)
CHECK = Tolerance(stop=False)


def spherical_pendulum():
    def H(q, p, t):
        return p[0] ** 2 / 2 + p[1] ** 2 / (2 * ca.sin(q[0]) ** 2) - ca.cos(q[0])
    return HamiltonianSystem(H, 2, name="spherical_pendulum")


def test_the_cyclic_coordinates_are_found_on_the_symbols():
    assert free_components(spherical_pendulum()).tolist() == [False, True, False, False]
    coupled = HamiltonianSystem(lambda q, p, t: (p[0] ** 2 + p[1] ** 2) / 2
                                + ca.cos(q[0] - q[1]), 2)
    assert free_components(coupled) is None


@pytest.mark.parametrize("tau0", [0.05, 0.3])
def test_a_winding_azimuth_sets_neither_the_polar_angle_nor_the_energy_scale(tau0):
    system = spherical_pendulum()
    short, long = (march(system, [2.0, 0.0], [0.0, 1.2], (0.0, t_end), tau0=tau0,
                         accuracy=CHECK) for t_end in (100.0, 400.0))
    for run in (short, long):
        theta = run.q[:, 0]
        # the polar angle's scale is its own range (the reference's states may widen it a
        # little), not a tenth of the azimuth's hundreds of radians
        assert run.verdict.scale[0] == pytest.approx(np.ptp(theta), rel=0.05)
        assert run.verdict.scale[1] >= np.ptp(run.q[:, 1])
        H = system.energy(run.q, run.p, run.t, np.zeros(0))
        # |S * grad H| over the motion: of the size of the energy's own change over it
        assert run.verdict.energy_scale < 10 * (np.max(np.abs(H)) + np.ptp(H) + 1.0)
    # the horizon (four times longer, the azimuth's range four times larger) changes neither
    assert long.verdict.energy_scale == pytest.approx(short.verdict.energy_scale, rel=0.05)
    assert long.verdict.scale[0] == pytest.approx(short.verdict.scale[0], rel=0.05)


def with_winding(drawn, rate: float) -> HamiltonianSystem:
    """``H'(q, q_c, p, p_c) = H(q, p, t) + p_c rate (1 + sin(q_1) / 2)``."""
    n = drawn.n

    def H(q, p, t):
        return drawn.hamiltonian(q[:n], p[:n], t) + p[n] * rate * (1 + ca.sin(q[0]) / 2)
    return HamiltonianSystem(H, n + 1, name="with_winding")


# five drawn systems (each marched twice; about as many more are drawn and left by the
# assumption below): a winding coordinate that set the old components' scales would move them
# on every system with a motion, so any one of them shows it
@settings(max_examples=5, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(cases_and_units())
def test_a_winding_coordinate_added_leaves_the_verdict_and_the_scales(drawn):
    case, _ = drawn
    n = case.system.n
    plain = HamiltonianSystem(case.system.hamiltonian, n, name="plain")
    span = (0.0, case.t_end)
    # the added coordinate winds a hundred times the others' largest range over the run
    rate = 100 * (1.0 + max(map(abs, case.Q0 + case.P0))) / case.t_end
    runs = [march(system, [*case.Q0, *extra], [*case.P0, *extra], span, tau0=case.tau0,
                  scheme=case.scheme, compilation=VM, accuracy=CHECK)
            for system, extra in ((plain, ()), (with_winding(case.system, rate), (0.0,)))]
    # a march that breaks down does so where a Newton's round-off decides: compare whole runs
    assume(all(run.status.name == "SUCCESS" for run in runs))
    a, b = (run.verdict for run in runs)
    assert runs[1].t.size == runs[0].t.size
    assert np.ptp(runs[1].q[:, n]) > 10 * np.max(np.ptp(runs[0].q, axis=0))
    assert b.name == a.name
    assert (a.first_failure is None) == (b.first_failure is None)
    if a.first_failure is not None:
        assert (b.first_failure.step, b.first_failure.test) == \
            (a.first_failure.step, a.first_failure.test)
    old = list(range(n)) + list(range(n + 1, 2 * n + 1))
    # the same nodes to the Newton's tolerance: the old components' scales agree to far
    # below the verdict's thresholds (1e-2)
    assert np.asarray(b.scale)[old] == pytest.approx(np.asarray(a.scale), rel=1e-6, abs=1e-12)
    assert b.energy_scale == pytest.approx(a.energy_scale, rel=1e-6)


def rotor_pair():
    """A pendulum coupled to a rotor: ``H`` is ``2 pi``-periodic in both angles, neither is
    cyclic, and the rotor's angle winds (its range grows with the horizon)."""
    return HamiltonianSystem(lambda q, p, t: (p[0] ** 2 + p[1] ** 2) / 2 + (1 - ca.cos(q[0]))
                             + 0.3 * (1 - ca.cos(q[0] - q[1])), 2, name="rotor_pair")


@pytest.mark.slow(why="repetition")
def test_a_winding_angle_counts_one_turn_for_itself_and_the_others():
    """Before, the pendulum's angle was judged against a tenth of the rotor's winding (14 rad
    at t = 50, 116 rad at t = 400) and the energy against 28-225 for |H| about 5."""
    system = rotor_pair()
    runs = [march(system, [0.3, 0.0], [0.0, 3.0], (0.0, t_end), tau0=0.02, scheme="fixed",
                  compilation=VM, accuracy=CHECK) for t_end in (50.0, 400.0)]
    for run in runs:
        scale = run.verdict.scale
        assert np.ptp(run.q[:, 1]) > 100 and scale[1] == pytest.approx(2 * np.pi)
        assert scale[0] == pytest.approx(np.ptp(run.q[:, 0]), rel=0.05)
    assert runs[1].verdict.energy_scale == pytest.approx(runs[0].verdict.energy_scale,
                                                         rel=0.05)
    # a whole turn added to the rotor's start changes nothing of the verdict
    shifted = march(system, [0.3, 2 * np.pi], [0.0, 3.0], (0.0, 50.0), tau0=0.02,
                    scheme="fixed", compilation=VM, accuracy=CHECK)
    assert shifted.verdict.name == runs[0].verdict.name
    assert np.asarray(shifted.verdict.scale) == pytest.approx(np.asarray(runs[0].verdict.scale),
                                                              rel=1e-6)


def test_a_declared_azimuth_is_judged_within_a_turn():
    """The spherical pendulum's azimuth, declared an angle: judged within a turn (2 pi), not
    against the hundreds of radians it winds; undeclared, a cyclic coordinate keeps its own
    range (it may as well be a free direction, in any units)."""
    def H(q, p, t):
        return p[0] ** 2 / 2 + p[1] ** 2 / (2 * ca.sin(q[0]) ** 2) - ca.cos(q[0])
    declared = HamiltonianSystem(H, 2, name="spherical", angles=("q2",))
    run = march(declared, [2.0, 0.0], [0.0, 1.2], (0.0, 100.0), tau0=0.05, accuracy=CHECK)
    assert np.ptp(run.q[:, 1]) > 100
    assert run.verdict.scale[1] == pytest.approx(2 * np.pi)
    plain = march(spherical_pendulum(), [2.0, 0.0], [0.0, 1.2], (0.0, 100.0), tau0=0.05,
                  accuracy=CHECK)
    assert plain.verdict.scale[1] >= np.ptp(plain.q[:, 1])
    # stricter on the azimuth, the same on the rest
    assert run.verdict.scale[0] == pytest.approx(plain.verdict.scale[0], rel=1e-9)
    assert run.verdict.t_drift <= plain.verdict.t_drift


@pytest.mark.parametrize("angles", [("q3",), ("x",), (1,), "q0"])
def test_bad_angles_are_refused_by_name(angles):
    from ddvp_nlp import InputError

    with pytest.raises(InputError, match=r"angles must name coordinates q1\.\.q2"):
        HamiltonianSystem(lambda q, p, t: p[0] ** 2 + p[1] ** 2, 2, angles=angles)
