"""Periodic orbits of constrained systems (solvers/periodic/constrained_orbit.py): the spherical
pendulum's conical orbit against its closed form (order 2 in N), the Cartesian pendulum's
libration against the angle pendulum's period (elliptic integral), metamorphic relations (time
unit, energy offset, coordinates permuted and rotated), the start at the energy drawn by
hypothesis, and bad input refused by name."""

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import ellipk

from ddvp_nlp import HamiltonianSystem, periodic_stability, solve_periodic
from ddvp_nlp.errors import InputError
from ddvp_nlp.solution import Status
from ddvp_nlp.solvers.periodic.constrained_orbit import at_energy


def sphere_h(q, p, t, grav, offset):
    return (p[0] ** 2 + p[1] ** 2 + p[2] ** 2) / 2 + grav * q[2] + offset


def sphere(q, t, grav, offset):
    return q[0] ** 2 + q[1] ** 2 + q[2] ** 2 - 1


SPHERICAL = HamiltonianSystem(sphere_h, 3, {"grav": 1.0, "offset": 0.0}, name="spherical",
                              constraints=sphere)


def conical(theta0, grav=1.0):
    """``(E, T, start)`` of the conical orbit at polar angle ``theta0`` from the downward
    vertical (unit length): ``w^2 = g / cos theta0``, ``T = 2 pi / w``."""
    w = np.sqrt(grav / np.cos(theta0))
    energy = 0.5 * (w * np.sin(theta0)) ** 2 - grav * np.cos(theta0)
    start = ([np.sin(theta0), 0.0, -np.cos(theta0)], [0.0, 1.0, 0.0])
    return energy, 2 * np.pi / w, start


def test_the_conical_orbit_is_found_verified_and_judged_accurate():
    energy, period, start = conical(0.6)
    solution = solve_periodic(SPHERICAL, energy=energy, nodes=41, section="q2=0", start=start)
    assert solution.status is Status.SUCCESS, solution.message
    assert solution.verdict.name == "accurate"
    assert abs(solution.orbit.period - period) / period < 2e-3  # measured 1.03e-3 at N = 40
    assert abs(solution.orbit.unfolding) < 1e-14
    record = solution.constraints
    assert record.constraint_residual.max() < 1e-14 and record.hidden_residual.max() < 1e-14
    assert np.allclose(solution.q[0], solution.q[-1], atol=1e-14)
    assert np.max(np.abs(solution.energy_residual)) < 1e-13
    # the discrete conical orbit is uniform: equal steps, the height constant
    assert np.ptp(np.diff(solution.t)) < 1e-12 and np.ptp(solution.q[:, 2]) < 1e-12


def _slope(counts, errors):
    return -np.polyfit(np.log(counts), np.log(errors), 1)[0]


@pytest.mark.slow(why="study")
@pytest.mark.parametrize("theta0", [0.3, 0.6, 1.1])
def test_the_conical_period_converges_at_order_two(theta0):
    energy, period, start = conical(theta0)
    counts, errors = [20, 40, 80, 160], []
    for N in counts:
        solution = solve_periodic(SPHERICAL, energy=energy, nodes=N + 1, section="q2=0",
                                  start=start)
        assert solution.orbit.residuals["canonical"] < 1e-12, solution.message
        errors.append(abs(solution.orbit.period - period) / period)
    assert abs(_slope(counts, errors) - 2) < 0.05, errors


def pendulum_h(q, p, t, grav):
    return (p[0] ** 2 + p[1] ** 2) / 2 + grav * q[1]


def rod(q, t, grav):
    return q[0] ** 2 + q[1] ** 2 - 1


CARTESIAN = HamiltonianSystem(pendulum_h, 2, {"grav": 1.0}, name="cartesian", constraints=rod)


def libration_period(energy, grav=1.0):
    """The angle pendulum's period at ``E = -g cos(theta_max)``: ``4 K(sin^2(theta_max / 2)) /
    sqrt(g)``."""
    amplitude = np.arccos(-energy / grav)
    return 4 * ellipk(np.sin(amplitude / 2) ** 2) / np.sqrt(grav)


@pytest.mark.slow(why="study")
def test_the_cartesian_libration_converges_to_the_elliptic_period():
    energy = -0.5
    period = libration_period(energy)
    counts, errors = [40, 80, 160, 320], []
    for N in counts:
        solution = solve_periodic(CARTESIAN, energy=energy, nodes=N + 1, section="p1=0",
                                  start=([0.0, -1.0], [1.0, 0.0]))
        assert solution.orbit.residuals["g"] < 1e-13, solution.message
        errors.append(abs(solution.orbit.period - period) / period)
        if N >= 80:
            assert solution.status is Status.SUCCESS and solution.verdict.name == "accurate"
    assert abs(_slope(counts, errors) - 2) < 0.1, errors


@pytest.mark.slow(why="study")
def test_time_unit_and_energy_offset_change_only_what_they_should():
    """Gravity 4: the same orbit in half the time at four times the energy; an offset added
    to H: the same orbit at the energy shifted by it."""
    energy, _, start = conical(0.6)
    base = solve_periodic(SPHERICAL, energy=energy, nodes=41, section="q2=0", start=start)
    fast = solve_periodic(SPHERICAL, energy=4 * energy, nodes=41, section="q2=0", start=start,
                          params={"grav": 4.0})
    shifted = solve_periodic(SPHERICAL, energy=energy + 2.5, nodes=41, section="q2=0",
                             start=start, params={"offset": 2.5})
    assert fast.success and shifted.success
    assert fast.orbit.period == pytest.approx(base.orbit.period / 2, rel=1e-12)
    assert np.allclose(fast.q, base.q, atol=1e-12) and np.allclose(fast.p, 2 * base.p,
                                                                   atol=1e-12)
    assert shifted.orbit.period == pytest.approx(base.orbit.period, rel=1e-12)
    assert np.allclose(shifted.q, base.q, atol=1e-12)


def permuted_h(q, p, t):
    return (p[0] ** 2 + p[1] ** 2 + p[2] ** 2) / 2 + q[0]  # the vertical is q1


@pytest.mark.slow(why="study")
def test_permuted_and_rotated_coordinates_give_the_same_orbit():
    energy, period, start = conical(0.6)
    base = solve_periodic(SPHERICAL, energy=energy, nodes=41, section="q2=0", start=start)
    permuted = HamiltonianSystem(permuted_h, 3, name="permuted",
                                 constraints=lambda q, t: q[0] ** 2 + q[1] ** 2 + q[2] ** 2 - 1)
    # (x, y, z) -> (z, x, y): the section q2=0 becomes q3=0
    order = [2, 0, 1]
    moved = solve_periodic(permuted, energy=energy, nodes=41, section="q3=0",
                           start=([start[0][i] for i in order], [start[1][i] for i in order]))
    assert moved.success
    assert moved.orbit.period == pytest.approx(base.orbit.period, rel=1e-12)
    assert np.allclose(moved.q, base.q[:, order], atol=1e-12)
    # rotated about the vertical by 0.7: the section through the rotated start
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    q0 = R @ start[0]
    rotated = solve_periodic(SPHERICAL, energy=energy, nodes=41, section=f"q2={float(q0[1])!r}",
                             start=(q0, R @ start[1]))
    assert rotated.success
    assert rotated.orbit.period == pytest.approx(base.orbit.period, rel=1e-10)
    assert np.allclose(rotated.q, base.q @ R.T, atol=1e-10)


@settings(max_examples=30, deadline=None)
@given(polar=st.floats(0.05, 3.0), azimuth=st.floats(-np.pi, np.pi),
       off=st.floats(-1e-4, 1e-4), speed=st.floats(0.1, 3.0),
       energy=st.floats(-0.9, 5.0))
def test_the_start_is_put_on_the_constraints_at_the_energy(polar, azimuth, off, speed, energy):
    q = (1 + off) * np.array([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth),
                              -np.cos(polar)])
    p = speed * np.array([-np.sin(azimuth), np.cos(azimuth), 0.3])
    theta = SPHERICAL.parameter_vector(None)
    if energy <= -np.cos(polar) * (1 + off) + 1e-9:
        with pytest.raises(InputError, match="no motion"):
            at_energy(SPHERICAL, theta, q, p, energy)
        return
    z, _ = at_energy(SPHERICAL, theta, q, p, energy)
    assert abs(z[:3] @ z[:3] - 1) < 1e-14
    assert abs(z[:3] @ z[3:]) < 1e-13 * max(1.0, np.abs(z[3:]).max())
    assert float(SPHERICAL.H_function(z[:3], z[3:], 0.0, theta)) == pytest.approx(energy,
                                                                                   abs=1e-13)


@pytest.mark.parametrize("keywords, words", [
    ({"energy": -1.5}, "energy = -1.5 has no motion at the start"),
    ({"start": None}, "needs start=\\(q, p\\)"),
    ({"start": ([0.0, 0.0, 0.0], [0.0, 1.0, 0.0])}, "singular Jacobian"),
    ({"start": ([0.6, 0.0, -0.8], [0.6, 0.0, -0.8])}, "no kinetic energy"),
    ({"guess": {"t": [0, 1], "q": [[0, 0, -1]] * 2, "p": [[0, 0, 0]] * 2}}, "at least 3"),
    ({"angles": ("q1",)}, "angles"),
    ({"derivatives": "energy"}, "derivatives"),
    ({"nodes": 3}, "nodes"),
    ({"section": "q7=0"}, "section names no coordinate"),
    ({"scheme": "fixed"}, "no energy equation"),
])
def test_bad_input_is_refused_by_name(keywords, words):
    energy, _, start = conical(0.6)
    arguments = {"energy": energy, "nodes": 21, "section": "q2=0", "start": start, **keywords}
    with pytest.raises(InputError, match=words):
        solve_periodic(SPHERICAL, **arguments)


def test_an_integral_whose_symmetry_is_the_orbits_own_flow_is_refused():
    energy, _, start = conical(0.6)

    def angular_momentum(q, p):
        return q[0] * p[1] - q[1] * p[0]
    with pytest.raises(InputError, match="relative equilibrium"):
        solve_periodic(SPHERICAL, energy=energy, nodes=21, section="q2=0", start=start,
                       integrals=(angular_momentum,))


@pytest.mark.slow(why="study")
def test_a_start_that_is_not_periodic_is_refused_by_name():
    """The Hairer-Lubich-Wanner start of the spherical pendulum moves quasi-periodically: its
    state never returns to the section's first crossing."""
    start = ([0.0, np.sin(0.1), -np.cos(0.1)], [0.06, 0.0, 0.0])
    energy = 0.5 * 0.06 ** 2 - np.cos(0.1)
    with pytest.raises(InputError, match="does not return"):
        solve_periodic(SPHERICAL, energy=energy, nodes=21, section="q1=0", start=start)


def test_the_conical_orbits_multipliers_are_the_polar_oscillation():
    """On the manifold (d = 4): the trivial pair, and exp(+-i Omega T) with
    Omega T = 2 pi sqrt(1 + 3 cos^2 theta0), the small oscillation about the cone (index
    2 cos(Omega T)); measured within 1e-9 of it at theta0 = 0.3, 0.6, 1.1."""
    energy, period, start = conical(0.6)
    solution = solve_periodic(SPHERICAL, energy=energy, nodes=41, section="q2=0", start=start)
    stability = periodic_stability(SPHERICAL, solution)
    assert stability.kind == "exact" and stability.extra["manifold_dimension"] == 4
    assert stability.trivial.size == 2 and np.allclose(stability.trivial, 1, atol=1e-6)
    expected = 2 * np.cos(2 * np.pi * np.sqrt(1 + 3 * np.cos(0.6) ** 2))
    assert stability.indices.size == 1
    assert abs(stability.indices[0] - expected) < 1e-7
    assert stability.verdict == "stable"
    assert stability.extra["exact_period"] == pytest.approx(period, rel=1e-10)
    assert np.allclose(np.abs(stability.multipliers), 1, atol=1e-7)


@pytest.mark.slow(why="study")
def test_a_family_in_the_energy_follows_the_cones():
    """Each orbit the guess of the next (solve_periodic_family): the periods follow 2 pi / w
    of the cone at each energy to the discretisation error."""
    from ddvp_nlp import solve_periodic_family

    angles = [0.6, 0.65, 0.7]
    energies = [conical(a)[0] for a in angles]
    family = solve_periodic_family(SPHERICAL, energies, nodes=81, section="q2=0",
                                   start=conical(0.6)[2])
    for angle, (energy, orbit) in zip(angles, family, strict=True):
        period = conical(angle)[1]
        assert energy == conical(angle)[0] and orbit.success
        assert abs(orbit.orbit.period - period) / period < 3e-4


def test_following_a_family_is_refused_by_name():
    from ddvp_nlp import follow_periodic_family

    energy, _, start = conical(0.6)
    with pytest.raises(InputError, match="follow_periodic_family"):
        follow_periodic_family(SPHERICAL, (energy, energy + 0.1), nodes=41, section="q2=0",
                               start=start)


def test_the_discrete_monodromy_of_a_constrained_orbit_is_refused_by_name():
    from ddvp_nlp.solvers.periodic.floquet import orbit_stability

    energy, _, start = conical(0.6)
    solution = solve_periodic(SPHERICAL, energy=energy, nodes=21, section="q2=0", start=start)
    with pytest.raises(InputError, match="orbit_stability"):
        orbit_stability(SPHERICAL, solution)


def test_time_dependent_constraints_are_refused():
    moving = HamiltonianSystem(lambda q, p, t: (p[0] ** 2 + p[1] ** 2) / 2 + q[1], 2,
                               name="moving",
                               constraints=lambda q, t: q[0] ** 2 + q[1] ** 2 - 1 - 0.1 * ca.sin(t))
    with pytest.raises(InputError, match="depend on t"):
        solve_periodic(moving, energy=-0.5, nodes=21, start=([0.0, -1.0], [1.0, 0.0]))
