"""Strongly unstable periodic orbits (issue 46): Hill's Lyapunov orbit, multiplier ~2000 a period,
found from the linearised orbit about its libration point, verified on the exact flow at the
same N as a stable orbit (multiple shooting on segments cut by the flow's growth), its
multiplier against scipy's DOP853 monodromy; the closure's answer under a change of time unit;
the linearised start's refusals."""

import casadi as ca
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from ddvp_nlp import (
    HamiltonianSystem,
    InputError,
    linearised_orbit,
    load_scene,
    periodic_stability,
    solve_periodic,
)
from ddvp_nlp.solvers.exact.closure import close_exact
from ddvp_nlp.solvers.exact.segments import GROWTH, growth_cuts

LIBRATION = 3.0 ** (-1.0 / 3.0)
EQUILIBRIUM = [LIBRATION, 0.0, 0.0, LIBRATION]
# Hill's Lyapunov orbit at E = -2.14 (issue 46: the user's scipy orbit, period 3.0396555, index
# 1970.2952 of its unstable pair).
PERIOD = 3.0396555
INDEX = 1970.2952


def _hill_field(_t, w):
    """Hill's equations in (x, y, p_x, p_y) with the variational equations (numpy)."""
    x, y, px, py = w[:4]
    r3 = (x * x + y * y) ** 1.5
    r5 = (x * x + y * y) ** 2.5
    f = [px + y, py - x, py + 2 * x - x / r3, -px - y - y / r3]
    # d f / d z
    hxx = 2 - (1 / r3 - 3 * x * x / r5)
    hxy = 3 * x * y / r5
    hyy = -1 - (1 / r3 - 3 * y * y / r5)
    A = np.array([[0, 1, 1, 0], [-1, 0, 0, 1], [hxx, hxy, 0, 1], [hxy, hyy, -1, 0]])
    Y = w[4:].reshape(4, 4)
    return np.concatenate([f, (A @ Y).ravel()])


def _scipy_monodromy(z0, period):
    run = solve_ivp(_hill_field, (0.0, period), np.concatenate([z0, np.eye(4).ravel()]),
                    method="DOP853", rtol=1e-12, atol=1e-13)
    return run.y[4:, -1].reshape(4, 4), run.y[:4, -1]


@pytest.fixture(scope="module")
def hill():
    return load_scene("hill")


@pytest.fixture(scope="module")
def lyapunov(hill):
    guess = linearised_orbit(hill.system, energy=-2.14, equilibrium=EQUILIBRIUM, section="q2=0")
    return solve_periodic(hill.system, energy=-2.14, nodes=401, section="q2=0", guess=guess)


def test_hill_lyapunov_orbit_is_found_and_verified_at_n_400(hill, lyapunov):
    """At N = 400 the flow from node 0 alone leaves the orbit by 1e-2 of its size within the
    period (the multiplier ~2000 amplifies node 0's O(N^-2) error): the check measures the
    orbit against the exact periodic orbit nearest it instead, found on several segments."""
    assert lyapunov.success, lyapunov.message
    assert lyapunov.verdict.name == "accurate"
    assert "multiple shooting" in lyapunov.verdict.estimate
    assert lyapunov.verdict.error_max < 1e-3
    assert abs(lyapunov.orbit.period - PERIOD) < 1e-4 * PERIOD


def test_hill_lyapunov_multiplier_agrees_with_scipy_dop853(hill, lyapunov):
    stability = periodic_stability(hill.system, lyapunov)
    exact = stability.exact_orbit
    assert exact.converged and exact.cuts.size - 1 > 1     # multiple shooting was needed
    assert stability.verdict == "unstable" and stability.exact.verdict == "unstable"
    index = float(np.max(stability.exact.indices.real))
    assert abs(index - INDEX) < 1e-4 * INDEX
    M, end = _scipy_monodromy(exact.z0, exact.period)
    assert np.max(np.abs(end - exact.z0)) < 1e-7       # scipy's flow closes the orbit too
    largest = np.max(np.abs(np.linalg.eigvals(M)))
    assert abs(index - (largest + 1 / largest)) < 1e-5 * index
    assert abs(float(np.max(stability.indices.real)) - INDEX) < 1e-2 * INDEX   # the grid's


def _scaled_hill(c):
    """Hill's problem with ``H`` times ``c``: the same orbits, run ``c`` times faster."""
    def hamiltonian(q, p, t):
        x, y = q[0], q[1]
        return c * (ca.sumsqr(p) / 2 + y * p[0] - x * p[1] - x ** 2 + y ** 2 / 2
                    - 1 / ca.sqrt(x ** 2 + y ** 2))
    return HamiltonianSystem(hamiltonian, 2, name=f"hill_times_{c}")


# c = 1 (no change) closes the orbit as test_hill_lyapunov_multiplier_agrees_with_scipy_dop853
# does (multiple shooting, the period, the index); c = 4 is the change of unit, in the default run
@pytest.mark.slow_when(lambda c, **_: c == 1.0, why="repetition")
@pytest.mark.parametrize("c", [1.0, 4.0])
def test_closure_under_a_change_of_time_unit(lyapunov, c):
    """``H -> c H`` runs the same orbit ``c`` times faster: the period scales by ``1/c``, the
    energy by ``c``, the multiplier and the segments are the same."""
    system = _scaled_hill(c)
    z0 = np.concatenate([lyapunov.q[0], lyapunov.p[0]])
    T = float(lyapunov.orbit.period) / c
    cuts = growth_cuts(system, [], z0, T, rtol=1e-12)
    exact = close_exact(system, [], z0, T, energy=-2.14 * c, section_index=2,
                        section_value=0.0)
    assert exact.converged and cuts.size - 1 > 1
    assert abs(exact.period * c - PERIOD) < 1e-6 * PERIOD
    largest = np.max(np.abs(np.linalg.eigvals(exact.monodromy)))
    assert abs(largest + 1 / largest - INDEX) < 1e-4 * INDEX


def test_single_shooting_stays_where_the_flow_does_not_grow():
    """A stable orbit's flow never stretches anything ``GROWTH`` times: one segment (single
    shooting, as before multiple shooting)."""
    scene = load_scene("henon_heiles")
    orbit = solve_periodic(scene.system, energy=0.1, nodes=101, section="p2=0",
                           start=scene.periodic.start)
    z0 = np.concatenate([orbit.q[0], orbit.p[0]])
    cuts = growth_cuts(scene.system, [], z0, orbit.orbit.period, rtol=1e-12)
    assert GROWTH > 1 and cuts.tolist() == [0.0, 1.0]


def test_linearised_orbit_is_the_centre_mode_at_the_energy(hill):
    guess = linearised_orbit(hill.system, energy=-2.15, equilibrium=EQUILIBRIUM,
                             section="q2=0", samples=101)
    q, p = guess["q"], guess["p"]
    assert q.shape == (101, 2) and np.array_equal(q[0], q[-1])
    assert abs(q[0, 1]) < 1e-12 and q[1, 1] > 0      # on the section, y increasing
    H = hill.system.energy(q[:1], p[:1], [0.0], [])[0]
    assert abs(H + 2.15) < 1e-10
    # the linearised period 2 pi / omega of the planar centre: omega^2 = 2 sqrt 7 - 1
    assert abs(guess["t"][-1] - 2 * np.pi / np.sqrt(2 * np.sqrt(7) - 1)) < 1e-9


def test_linearised_orbit_refuses_by_name(hill):
    system = hill.system
    with pytest.raises(InputError, match="equilibrium"):
        linearised_orbit(system, energy=-2.14, equilibrium=[0.5, 0.0, 0.0, 0.5],
                         section="q2=0")
    with pytest.raises(InputError, match="equilibrium"):
        linearised_orbit(system, energy=-2.14, equilibrium=[LIBRATION, 0.0], section="q2=0")
    with pytest.raises(InputError, match="section"):
        linearised_orbit(system, energy=-2.14, equilibrium=EQUILIBRIUM, section="q1=0")
    with pytest.raises(InputError, match="energy"):
        linearised_orbit(system, energy=-2.2, equilibrium=EQUILIBRIUM, section="q2=0")
    with pytest.raises(InputError, match="energy"):
        linearised_orbit(system, energy=float("nan"), equilibrium=EQUILIBRIUM,
                         section="q2=0")
    with pytest.raises(InputError, match="samples"):
        linearised_orbit(system, energy=-2.14, equilibrium=EQUILIBRIUM, samples=2)


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=4,
                max_size=4), st.floats(allow_nan=True, allow_infinity=True))
def test_linearised_orbit_reads_any_numbers(hill, point, energy):
    """Whatever numbers it is given: a guess on the section at the energy, or `InputError`."""
    try:
        guess = linearised_orbit(hill.system, energy=energy, equilibrium=point,
                                 section="q2=0", samples=8)
    except InputError:
        return
    H = hill.system.energy(guess["q"][:1], guess["p"][:1], [0.0], [])[0]
    assert np.isfinite(H) and abs(guess["q"][0, 1]) < 1e-9


def test_a_multiplier_of_millions_closes_on_segments(lyapunov):
    """The orbit run twice (a period of multiplier ~3.9e6, far beyond the 1e4 of issue 46)
    closes on multiple segments, with the square of the single orbit's multiplier; single
    shooting (one segment: no cut at any growth) does not close it."""
    system = load_scene("hill").system
    z = np.hstack([lyapunov.q, lyapunov.p])
    t = lyapunov.t - lyapunov.t[0]
    twice_t, twice_z = np.r_[t, t[1:] + t[-1]], np.vstack([z, z[1:]])

    def close(growth=GROWTH):
        return close_exact(system, [], twice_z[0], twice_t[-1], energy=-2.14, section_index=2,
                           section_value=0.0, path=(twice_t, twice_z), growth=growth)
    exact = close()
    assert exact.converged and exact.cuts.size - 1 > 2
    assert abs(exact.period - 2 * PERIOD) < 2e-6 * PERIOD
    largest = np.max(np.abs(np.linalg.eigvals(exact.monodromy)))
    single = (INDEX + np.sqrt(INDEX ** 2 - 4)) / 2
    assert largest > 1e4 and abs(largest - single ** 2) < 1e-4 * single ** 2
    assert not close(np.inf).converged


def test_linearised_orbit_about_the_mirrored_point_is_the_mirrored_orbit(hill):
    """``H`` is even under ``z -> -z`` (a half turn of the plane): the linearised orbit about
    the libration point at ``-x`` is the one about ``+x`` turned, half a period on (node 0 must
    cross ``y = 0`` upwards), with the same period; its amplitude differs at the nonlinear
    order (node 0, where ``H = E`` is set, is on the other side), its shape does not."""
    right = linearised_orbit(hill.system, energy=-2.15, equilibrium=EQUILIBRIUM,
                             section="q2=0", samples=201)
    left = linearised_orbit(hill.system, energy=-2.15, equilibrium=[-v for v in EQUILIBRIUM],
                            section="q2=0", samples=201)
    assert left["t"][-1] == pytest.approx(right["t"][-1], rel=1e-12)
    turned = -(np.hstack([right["q"], right["p"]]) - EQUILIBRIUM)
    mirrored = np.hstack([left["q"], left["p"]]) + EQUILIBRIUM
    turned, mirrored = turned / np.max(np.abs(turned)), mirrored / np.max(np.abs(mirrored))
    assert np.allclose(np.roll(turned[:-1], -100, axis=0), mirrored[:-1], atol=1e-9)
