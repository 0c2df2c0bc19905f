"""The exact flow of a constrained system (``solvers/exact/constrained.py``): the Cartesian
pendulum against its elliptic-function solution, the spherical pendulum against its equations
in angles (scipy's DOP853 at rtol 1e-13), the stated error bound, the named errors, random
pendulums (hypothesis) and the metamorphic relations (rotated frame, time offset, units).

The constrained systems come from ``helpers.constrained.with_constraints``, a stand-in for the
core's ``HamiltonianSystem(..., constraints=g)`` until it lands."""

import casadi as ca
import numpy as np
import pytest
from helpers.constrained import (
    cartesian_pendulum,
    pendulum_start,
    spherical_pendulum,
    spherical_start,
    with_constraints,
)
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.special import ellipj, ellipk

from ddvp_nlp import HamiltonianSystem, InputError
from ddvp_nlp.solvers.exact.constrained import (
    constrained_field,
    constraint_residuals,
    projection_function,
)
from ddvp_nlp.solvers.exact.constrained_reference import constrained_reference
from ddvp_nlp.solvers.exact.flow import exact_flow


def elliptic_pendulum(t, angle, length=1.0, mass=1.0, gravity=1.0):
    """The pendulum released at rest at ``angle`` from the downward vertical, in Cartesian
    coordinates: ``sin(theta/2) = k sn(K - w t, k^2)``, ``k = sin(angle/2)``, ``w = sqrt(g/L)``;
    ``theta' = -2 w k cn(K - w t)``."""
    k, w = np.sin(angle / 2), np.sqrt(gravity / length)
    sn, cn, _, _ = ellipj(ellipk(k * k) - w * np.asarray(t, float), k * k)
    theta, omega = 2 * np.arcsin(k * sn), -2 * w * k * cn
    return np.column_stack([length * np.sin(theta), -length * np.cos(theta),
                            mass * length * omega * np.cos(theta),
                            mass * length * omega * np.sin(theta)])


def relative_error(z, exact):
    scale = exact.max(axis=0) - exact.min(axis=0)
    return np.max(np.abs(z - exact) / scale, axis=1), scale


def test_the_elliptic_formula_is_the_pendulum():
    # its start is the release at rest and it solves theta'' = -sin(theta) (differences)
    t = np.linspace(0, 7, 7001)
    z = elliptic_pendulum(t, 1.0)
    assert np.max(np.abs(z[0] - pendulum_start(1.0))) < 1e-15
    theta = np.arctan2(z[:, 0], -z[:, 1])
    dt = t[1] - t[0]
    second = (theta[2:] - 2 * theta[1:-1] + theta[:-2]) / dt ** 2
    assert np.max(np.abs(second + np.sin(theta[1:-1]))) < 1e-6


@pytest.mark.parametrize("rtol", [1e-8, 1e-10, 1e-12])
def test_cartesian_pendulum_against_the_elliptic_solution(rtol):
    system, theta = cartesian_pendulum(), [1.0, 1.0]
    t = np.linspace(0, 100, 2001)
    reference = constrained_reference(system, pendulum_start(1.0), 0.0, 100.0, theta, rtol=rtol)
    exact = elliptic_pendulum(t, 1.0)
    error, scale = relative_error(reference.states(t), exact)
    claim = reference.error(t, scale)
    assert np.all(error <= claim)  # the stated bound holds at every time
    assert error.max() <= 10 * rtol  # measured: 1.0e-5, 6.0e-8, 4.7e-10, 3.5e-12 at 1e-6 .. 1e-12
    t_nodes, z_nodes = reference.fine.nodes()
    g, h = constraint_residuals(system, t_nodes, z_nodes, theta)
    assert g.max() <= 1e-15 and h.max() <= 1e-15  # projected in every step: round-off


def angles_solution(t, z0):
    """The spherical pendulum (``H = |p|^2/2 + z`` on the unit sphere) in its polar angle from
    the downward vertical and its azimuth, by scipy's DOP853 at rtol 1e-13, in Cartesian
    coordinates."""
    q, v = z0[:3], z0[3:]
    polar, azimuth = np.arccos(-q[2]), np.arctan2(q[1], q[0])
    e_polar = np.array([np.cos(polar) * np.cos(azimuth), np.cos(polar) * np.sin(azimuth),
                        np.sin(polar)])
    e_azimuth = np.array([-np.sin(azimuth), np.cos(azimuth), 0.0])

    def rhs(_, u):
        th, _, thd, phd = u
        return [thd, phd, np.sin(th) * np.cos(th) * phd ** 2 - np.sin(th),
                -2 * np.cos(th) / np.sin(th) * thd * phd]
    start = [polar, azimuth, e_polar @ v, e_azimuth @ v / np.sin(polar)]
    u = solve_ivp(rhs, (t[0], t[-1]), start, method="DOP853", rtol=1e-13, atol=1e-13,
                  t_eval=t).y
    th, ph, thd, phd = u
    s, c, sp, cp = np.sin(th), np.cos(th), np.sin(ph), np.cos(ph)
    q = np.column_stack([s * cp, s * sp, -c])
    v = thd[:, None] * np.column_stack([c * cp, c * sp, s]) + \
        (phd * s)[:, None] * np.column_stack([-sp, cp, 0 * ph])
    return np.hstack([q, v])


def test_spherical_pendulum_against_its_angles_and_its_angular_momentum():
    system, z0 = spherical_pendulum(), spherical_start()
    t = np.linspace(0, 50, 1001)
    reference = constrained_reference(system, z0, 0.0, 50.0, [], rtol=1e-12)
    error, scale = relative_error(reference.states(t), angles_solution(t, z0))
    assert np.all(error <= reference.error(t, scale))
    assert error.max() <= 1e-10  # measured 6.7e-12
    _, z = reference.fine.nodes()
    Lz = z[:, 0] * z[:, 4] - z[:, 1] * z[:, 3]
    assert np.max(np.abs(Lz / Lz[0] - 1)) <= 1e-12  # measured 5.4e-14


def test_without_projection_the_index_one_equation_drifts_off_the_manifold():
    # why the projection is there: the same field integrated alone leaves g = 0
    system, theta = cartesian_pendulum(), [1.0, 1.0]
    from ddvp_nlp.solvers.exact.flow import AdaptiveFlow
    plain = AdaptiveFlow(constrained_field(system), compiler=None)
    run = plain.run(pendulum_start(1.0), 0.0, 200.0, theta, rtol=1e-6)
    projected = exact_flow(system, compiler=None).run(pendulum_start(1.0), 0.0, 200.0, theta,
                                                      rtol=1e-6)
    g_plain, _ = constraint_residuals(system, *run.nodes(), theta)
    g_projected, _ = constraint_residuals(system, *projected.nodes(), theta)
    assert g_plain.max() > 1e3 * g_projected.max()
    assert g_projected.max() <= 1e-15


def test_the_hook_picks_the_constrained_flow_only_for_constrained_systems():
    plain = HamiltonianSystem(lambda q, p, t: (p[0] ** 2 + p[1] ** 2) / 2 + q[1], 2)
    assert exact_flow(plain).layout.d == 4
    free = exact_flow(plain, compiler=None).run([1.0, 0.0, 0.0, 0.0], 0.0, 1.0, [], rtol=1e-10)
    assert abs(free.z_end[1] + 0.5) < 1e-9  # falls freely: y = -t^2/2
    held = exact_flow(cartesian_pendulum(), compiler=None).run(
        [1.0, 0.0, 0.0, 0.0], 0.0, 1.0, [1.0, 1.0], rtol=1e-10)
    assert abs(np.hypot(*held.z_end[:2]) - 1) < 1e-14


# -- named errors ----------------------------------------------------------------------------

def test_bad_inputs_are_named():
    system, theta = cartesian_pendulum(), [1.0, 1.0]
    z0 = pendulum_start(1.0)
    plain = HamiltonianSystem(lambda q, p, t: p[0] ** 2 / 2, 1)
    with pytest.raises(InputError, match="no constraints"):
        constrained_reference(plain, [0.0, 0.0], 0.0, 1.0, [])
    with pytest.raises(InputError, match="z0 must be 4 finite"):
        constrained_reference(system, z0[:3], 0.0, 1.0, theta)
    with pytest.raises(InputError, match="z0 must be 4 finite"):
        constrained_reference(system, [np.nan, 0, 0, 0], 0.0, 1.0, theta)
    with pytest.raises(InputError, match="t_end must be finite"):
        constrained_reference(system, z0, 0.0, np.inf, theta)
    with pytest.raises(InputError, match="rtol must be"):
        constrained_reference(system, z0, 0.0, 1.0, theta, rtol=0.5)
    with pytest.raises(InputError, match="scale must be positive"):
        constrained_reference(system, z0, 0.0, 1.0, theta, scale=[1, 1, 0, 1])
    with pytest.raises(InputError, match="not a consistent start.*component 0"):
        constrained_reference(system, z0 + [1e-3, 0, 0, 0], 0.0, 1.0, theta)
    with pytest.raises(InputError, match="not a consistent start.*component 2"):
        constrained_reference(system, z0 + [0, 0, 1e-3, 0], 0.0, 1.0, theta)


def test_bad_constraints_are_named():
    def H(q, p, t):
        return (p[0] ** 2 + p[1] ** 2) / 2
    system = HamiltonianSystem(H, 2)
    system.n_constraints, system.G = 2, ca.vertcat(system.q[0])  # count and column disagree
    with pytest.raises(InputError, match="n_constraints = 2"):
        constrained_field(system)
    clock = with_constraints(HamiltonianSystem(H, 2), lambda q, t: t - 1)
    with pytest.raises(InputError, match="do not depend on q"):
        projection_function(clock)


# -- random pendulums ----------------------------------------------------------------------

@settings(max_examples=6, deadline=None)
@given(length=st.floats(0.3, 3.0), mass=st.floats(0.2, 5.0), gravity=st.floats(0.5, 20.0),
       angle=st.floats(0.1, 2.8))
def test_random_pendulums_stay_on_the_manifold_with_their_energy(length, mass, gravity, angle):
    system, theta = cartesian_pendulum(length, mass, gravity), [mass, gravity]
    period = 2 * np.pi * np.sqrt(length / gravity)
    z0 = pendulum_start(angle, length, mass)
    reference = constrained_reference(system, z0, 0.0, 5 * period, theta, rtol=1e-10,
                                      compiler=None)
    t, z = reference.fine.nodes()
    g, h = constraint_residuals(system, t, z, theta)
    assert g.max() <= 8 * np.finfo(float).eps * length ** 2  # projected: round-off of g
    speed = np.sqrt(2 * gravity * length)  # the largest speed's scale
    assert h.max() <= 8 * np.finfo(float).eps * length * speed
    H = system.energy(z[:, :2], z[:, 2:], t, theta)
    scale = mass * gravity * length  # the energy's range over the swing
    assert np.max(np.abs(H - H[0])) <= 1e-9 * scale


# -- metamorphic relations -----------------------------------------------------------------

def tilted_pendulum(angle):
    """The Cartesian pendulum seen in a frame rotated by ``a`` (``q_upright = R q``): its
    potential ``e_y . R q``."""
    down = rotation(angle).T @ np.array([0.0, 1.0])

    def H(q, p, t):
        return (p[0] ** 2 + p[1] ** 2) / 2 + down[0] * q[0] + down[1] * q[1]
    return with_constraints(HamiltonianSystem(H, 2, name="tilted"),
                            lambda q, t: q[0] ** 2 + q[1] ** 2 - 1)


def rotation(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, s], [-s, c]])  # maps the upright frame onto the tilted one


def test_rotated_frame_gives_the_rotated_motion():
    angle, t = 0.7, np.linspace(0, 20, 201)
    z0 = pendulum_start(1.2)
    R = rotation(angle)
    upright = constrained_reference(cartesian_pendulum(), z0, 0.0, 20.0, [1.0, 1.0],
                                    rtol=1e-11).states(t)
    start = np.concatenate([R.T @ z0[:2], R.T @ z0[2:]])
    tilted = constrained_reference(tilted_pendulum(angle), start, 0.0, 20.0, [],
                                   rtol=1e-11).states(t)
    back = np.hstack([tilted[:, :2] @ R.T, tilted[:, 2:] @ R.T])
    assert np.max(np.abs(back - upright)) <= 1e-9


def test_a_time_offset_shifts_the_motion():
    system, z0, t = cartesian_pendulum(), pendulum_start(1.0), np.linspace(0, 15, 151)
    first = constrained_reference(system, z0, 0.0, 15.0, [1.0, 1.0], rtol=1e-11).states(t)
    later = constrained_reference(system, z0, 40.0, 55.0, [1.0, 1.0],
                                  rtol=1e-11).states(t + 40.0)
    assert np.max(np.abs(first - later)) <= 1e-9


def test_scaled_units_scale_the_motion():
    # lengths by 3, masses by 2, time by 5 (gravity by 3 / 25): positions x3, momenta x 6/5
    length, mass, clock = 3.0, 2.0, 5.0
    gravity = length / clock ** 2
    t = np.linspace(0, 12, 121)
    unit = constrained_reference(cartesian_pendulum(), pendulum_start(1.1), 0.0, 12.0,
                                 [1.0, 1.0], rtol=1e-11).states(t)
    big = constrained_reference(cartesian_pendulum(length, mass, gravity),
                                pendulum_start(1.1, length, mass), 0.0, 12.0 * clock,
                                [mass, gravity], rtol=1e-11).states(t * clock)
    expected = np.hstack([unit[:, :2] * length, unit[:, 2:] * mass * length / clock])
    assert np.max(np.abs(big - expected) / np.array([length] * 2 + [mass * length / clock] * 2)) \
        <= 1e-9


def test_a_pivot_moving_at_constant_velocity_is_the_pendulum_seen_from_a_moving_frame():
    # g(q, t) = (x - c t)^2 + y^2 - 1: time-dependent (g_t, h_t); a Galilean change of frame
    c = 0.3

    def H(q, p, t):
        return (p[0] ** 2 + p[1] ** 2) / 2 + q[1]
    moving = with_constraints(HamiltonianSystem(H, 2, name="moving_pivot"),
                              lambda q, t: (q[0] - c * t) ** 2 + q[1] ** 2 - 1)
    z0 = pendulum_start(1.0) + [0.0, 0.0, c, 0.0]
    t = np.linspace(0, 30, 301)
    z = constrained_reference(moving, z0, 0.0, 30.0, [], rtol=1e-11).states(t)
    exact = elliptic_pendulum(t, 1.0) + np.column_stack([c * t, 0 * t, c + 0 * t, 0 * t])
    assert np.max(np.abs(z - exact)) <= 1e-9
