"""Floquet multipliers of discrete periodic orbits against the exact flow's: orders fitted in N,
the trivial multipliers set apart, verdicts that do not change with the units, and drawn
systems judged against DOP853's monodromy."""

import casadi as ca
import numpy as np
import pytest
from helpers.common import fitted_order
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from scipy.special import ellipe, ellipk

from ddvp_nlp import (
    GridOptions,
    HamiltonianSystem,
    InputError,
    Tolerance,
    load_scene,
    periodic_stability,
    solve_periodic,
)
from ddvp_nlp.solvers.periodic.floquet import stability_indices, verdict

# Each example solves orbits: a failure is reported as drawn, not shrunk (shrinking re-solves
# for minutes).
NO_SHRINK = (Phase.explicit, Phase.generate)


def _orbits(scene, settings, energy, sizes, base_nodes=400, **options):
    """Orbits at ``energy`` on each grid of ``sizes``, each from one orbit on ``base_nodes``
    (from the scene's default start). The coarse grids of a convergence study are not held to
    the accuracy check's 1e-2 (a Henon-Heiles orbit at N = 50 closes to 1.1e-2): their verdict
    is recorded (``Tolerance(stop=False)``) and their error is what the study measures."""
    common = {"section": settings.section, "start": settings.start,
              "integrals": settings.integrals,
              "options": GridOptions(accuracy=Tolerance(stop=False)), **options}
    base = solve_periodic(scene.system, energy=energy, nodes=base_nodes + 1, **common)
    assert base.success, base.message
    return [solve_periodic(scene.system, energy=energy, nodes=N + 1, guess=base, **common)
            for N in sizes]


# the axis orbit keeps the order-two fit and a verdict against the exact flow's in the default
# run; an unstable verdict against the exact flow's is test_unstable_orbits.py's
# test_hill_lyapunov_multiplier_agrees_with_scipy_dop853, also in the default run
@pytest.mark.slow_when(lambda family, **_: family == "loop", why="study")
@pytest.mark.slow_when(lambda family, **_: family == "across", why="repetition")
@pytest.mark.parametrize("family", ["loop", "across", "axis"])
def test_henon_heiles_indices_converge_at_order_two_to_the_exact_flows(family):
    """At E = 0.1 the loop orbit is stable (index 0.0884), the orbit across the axis unstable
    (2.955), the orbit on the axis stable (0.664): the discrete index's distance from the exact
    flow's (DOP853 at 1e-12 on the variational equations, from the exact orbit found by
    shooting) falls like N^-2 (fitted slope 2 within 0.1 over N = 50, 100, 200), and every
    verdict is the exact flow's."""
    scene = load_scene("henon_heiles")
    settings = scene.periodic if family == "axis" else scene.periodic.families[family]
    errors = []
    for orbit in _orbits(scene, settings, 0.1, (50, 100, 200)):
        assert orbit.success, orbit.message
        stability = periodic_stability(scene.system, orbit)
        assert stability.exact_orbit.converged and stability.exact is not None
        assert stability.exact_orbit.distance < 1e-2  # node 0 within the scheme's error
        assert stability.verdict == stability.exact.verdict
        assert stability.trivial.size == 2 and stability.indices.size == 1
        assert stability.trivial_error < 1e-10  # relative to |M|: round-off
        errors.append(abs(stability.indices[0] - stability.exact.indices[0]))
    assert abs(fitted_order([50, 100, 200], errors) + 2) < 0.1, errors


def test_pendulum_has_only_the_trivial_pair_and_its_period_derivative_converges():
    """One degree of freedom: no nontrivial multiplier, the pair at 1 found on both sides. The
    trivial block carries dT/dE (the condensed orbit equations differentiated in E), which
    converges at order 2 to 4 dK/dE of the exact period 4 K(E/2)."""
    scene = load_scene("pendulum")
    energy, m = 0.5, 0.25
    exact_slope = (ellipe(m) - (1 - m) * ellipk(m)) / (m * (1 - m))
    sizes, errors = (50, 100, 200), []
    for orbit in _orbits(scene, scene.periodic, energy, sizes, base_nodes=200,
                         angles=scene.periodic.angles):
        stability = periodic_stability(scene.system, orbit)
        assert stability.indices.size == 0 and stability.verdict == "stable"
        assert stability.trivial.size == 2 and stability.trivial_error < 1e-10
        assert stability.exact.trivial_error < 1e-10
        assert abs(stability.exact_orbit.period_derivative - exact_slope) < 1e-9
        errors.append(abs(stability.extra["period_derivative"] - exact_slope))
    assert abs(fitted_order(sizes, errors) + 2) < 0.1, errors


@pytest.mark.slow(why="study")
def test_the_figure_eight_is_linearly_stable_and_its_indices_converge():
    """Eight trivial multipliers (flow, two translations, rotation: two each) and two stable
    pairs, indices -0.5952 and 1.99720 on the exact flow; the discrete ones converge at order
    2 over N = 200, 400, 800, and the verdict at the scene's N = 600 (601 nodes) is stable. (At
    N = 100 the index near 2 comes out 2.00014: the discretisation error, 2.9e-3, is larger than the
    orbit's margin, 2.8e-3; the exact flow's check says so.)"""
    scene = load_scene("figure_eight")
    settings = scene.periodic
    sizes = (200, 400, 800)
    orbits = _orbits(scene, settings, settings.energy, (*sizes, settings.nodes - 1))
    errors = []
    for orbit in orbits:
        stability = periodic_stability(scene.system, orbit, integrals=settings.integrals)
        assert stability.trivial.size == 8 and stability.indices.size == 2
        assert stability.isotropy < 1e-8  # zero total momentum: the symmetries commute
        assert stability.exact.verdict == "stable"
        np.testing.assert_allclose(stability.exact.indices.real, [-0.59519, 1.99720],
                                   atol=2e-5)
        errors.append(float(np.max(np.abs(stability.indices - stability.exact.indices))))
    assert stability.verdict == "stable" and orbit.steps == 600
    assert abs(fitted_order(sizes, errors[:3]) + 2) < 0.15, errors


@pytest.mark.slow(why="study")
def test_indices_and_verdicts_do_not_change_with_the_units():
    """``q = a Q``, ``p = b P`` and ``H' = c H(a Q, b P) / (a b)`` (times ``1/c``): the same
    motion in other units, discretely too (the midpoint rule is affine, the energy equation
    the same level set). From the reference orbit's nodes in the new units (the march that
    makes the default start is not unit-free: at b = 10 it led Newton and IPOPT astray), the
    solve returns the same grid; the indices agree to 1e-7 and the verdict is the same, for
    units drawn over four decades."""
    scene = load_scene("henon_heiles")
    loop = scene.periodic.families["loop"]
    reference_orbit = solve_periodic(scene.system, energy=0.1, nodes=301, section=loop.section,
                                     start=loop.start)
    reference = periodic_stability(scene.system, reference_orbit, exact=False)

    @settings(max_examples=6, deadline=None, derandomize=True, phases=NO_SHRINK,
              suppress_health_check=[HealthCheck.too_slow])
    @given(st.floats(-2, 2), st.floats(-2, 2), st.floats(-2, 2))
    def check(log_a, log_b, log_c):
        a, b, c = 10.0 ** log_a, 10.0 ** log_b, 10.0 ** log_c

        def hamiltonian(q, p, t):
            return c * scene.hamiltonian(a * q, b * p, t) / (a * b)
        system = HamiltonianSystem(hamiltonian, 2, name="henon_heiles_units")
        guess = {"t": reference_orbit.t / c, "q": reference_orbit.q / a,
                 "p": reference_orbit.p / b}
        orbit = solve_periodic(system, energy=0.1 * c / (a * b), nodes=301,
                               section="q1=0", guess=guess)
        assert orbit.success, orbit.message
        assert abs(orbit.orbit.period * c / reference_orbit.orbit.period - 1) < 1e-10
        stability = periodic_stability(system, orbit, exact=False)
        assert stability.verdict == reference.verdict
        np.testing.assert_allclose(stability.indices, reference.indices, rtol=0, atol=1e-7)
    check()


@pytest.mark.slow(why="study")
@settings(max_examples=4, deadline=None, derandomize=True, phases=NO_SHRINK,
          suppress_health_check=[HealthCheck.too_slow])
@given(st.floats(0.7, 1.4), st.floats(-0.6, 0.6), st.floats(-0.6, 0.6), st.floats(0.2, 0.8))
def test_drawn_systems_indices_match_the_exact_flow_within_their_richardson_estimate(
        omega, alpha, beta, amplitude):
    """``H = |p|^2/2 + q1^2/2 + omega^2 q2^2/2 + alpha q1^2 q2 + beta q2^3/3`` with drawn
    frequency and cubic terms: the orbit through the section ``p2 = 0`` on the invariant plane
    ``q1 = p1 = 0`` at an energy a drawn fraction of the way to the plane's escape energy. The
    discrete index at N = 200 lies within twice its Richardson estimate ``|k_200 - k_100| / 3``
    of the exact flow's (plus round-off), and the verdicts agree away from the margin."""
    def hamiltonian(q, p, t):
        return (ca.sumsqr(p) / 2 + q[0] ** 2 / 2 + omega ** 2 * q[1] ** 2 / 2
                + alpha * q[0] ** 2 * q[1] + beta * q[1] ** 3 / 3)
    system = HamiltonianSystem(hamiltonian, 2, name="drawn")
    # the potential on the plane, omega^2 y^2/2 + beta y^3/3, has its barrier at
    # y = -omega^2/beta with height omega^6/(6 beta^2)
    barrier = omega ** 6 / (6 * beta ** 2) if beta else 1.0
    energy = amplitude * min(barrier, 1.0) * 0.5
    start = ([0.0, 1.0], [0.0, 0.0])
    coarse = solve_periodic(system, energy=energy, nodes=101, section="p2=0", start=start)
    fine = solve_periodic(system, energy=energy, nodes=201, section="p2=0", guess=coarse)
    assert coarse.success and fine.success, (coarse.message, fine.message)
    k_coarse = periodic_stability(system, coarse, exact=False).indices[0]
    checked = periodic_stability(system, fine)
    k_fine, k_exact = checked.indices[0], checked.exact.indices[0]
    estimate = abs(k_fine - k_coarse) / 3
    assert abs(k_fine - k_exact) <= 2 * estimate + 1e-9, (k_fine, k_coarse, k_exact)
    if abs(abs(k_exact.real) - 2) > 4 * estimate + 1e-6:
        assert checked.verdict == checked.exact.verdict


def test_stability_indices_come_from_the_characteristic_polynomial():
    """Built symplectic matrices with known multipliers: a rotation pair and a real pair give
    indices 2 cos(theta) and lambda + 1/lambda; a complex quadruplet gives complex indices;
    the verdicts follow with the stated tolerance."""
    rng = np.random.default_rng(3)
    theta, lam = 0.7, 3.0
    block = np.zeros((4, 4))
    block[np.ix_([0, 2], [0, 2])] = [[np.cos(theta), np.sin(theta)],
                                    [-np.sin(theta), np.cos(theta)]]
    block[np.ix_([1, 3], [1, 3])] = [[lam, 0.0], [0.0, 1.0 / lam]]
    # a symplectic change of basis keeps the multipliers
    S = rng.normal(size=(2, 2))
    change = np.block([[S, np.zeros((2, 2))], [np.zeros((2, 2)), np.linalg.inv(S).T]])
    R = change @ block @ np.linalg.inv(change)
    indices = stability_indices(R)
    np.testing.assert_allclose(indices.real, [2 * np.cos(theta), lam + 1 / lam], atol=1e-12)
    assert np.all(np.abs(indices.imag) < 1e-12)
    assert verdict(indices, 1e-6) == "unstable"
    assert verdict(np.array([2 - 1e-7 + 0j]), 1e-6) == "marginal"
    assert verdict(np.array([1.9 + 0j, -1.9 + 0j]), 1e-6) == "stable"
    assert verdict(np.array([0.5 + 0.3j, 0.5 - 0.3j]), 1e-6) == "unstable"


def test_bad_arguments_are_refused_by_name():
    scene = load_scene("pendulum")
    with pytest.raises(InputError, match="solution must be a periodic orbit"):
        periodic_stability(scene.system, "orbit")
    orbit = solve_periodic(scene.system, energy=0.5, nodes=61)
    with pytest.raises(InputError, match="tol"):
        periodic_stability(scene.system, orbit, tol=-1.0)
    with pytest.raises(InputError, match="integrals: the orbit was solved with 0"):
        periodic_stability(scene.system, orbit, integrals=(lambda q, p: p[0],))
