"""An unstable periodic orbit (Hill's Lyapunov orbit, multiplier ~2000 a period) is found,
verified and closed on the exact flow alike in any units of length and time, with the origin
moved and a constant added to ``H``.

The system in lengths ``L``, times ``T``, origin at ``c``, ``H + C``::

    H = (L/T)^2 h((q - c)/L, p T/L) + C,     h Hill's Hamiltonian,

the same motion, its energy ``-2.14 (L/T)^2 + C``. Before, in lengths of ``1e-8`` IPOPT ended
at an acceptable point the verification refused (``solver_failed``); in lengths of ``1e6`` its
point had negative steps and the accuracy check crashed in scipy (```x` must be strictly
increasing``); in time units of ``1e4`` the exact orbit was cut into 25 segments instead of 5,
and in lengths of ``1e-6`` with time units of ``1e-3`` the solve took 32 s instead of 2 s
(IPOPT on unscaled rows with one absolute tolerance, the flow's growth in a norm that mixes
positions and momenta, the closure's tolerances from ``max(1, |z_0|)``).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import HamiltonianSystem, linearised_orbit, periodic_stability, solve_periodic
from ddvp_nlp.solvers.accuracy.judgement import Judgement
from ddvp_nlp.solvers.exact.closure import close_exact
from ddvp_nlp.solvers.exact.segments import growth_cuts
from ddvp_nlp.solvers.options import Tolerance

LIBRATION = 3.0 ** (-1.0 / 3.0)
ENERGY = -2.14
NODES = 201


def hill(L=1.0, T=1.0, c=0.0, C=0.0):
    def hamiltonian(q, p, t):
        x, y = (q[0] - c) / L, q[1] / L
        P = p * T / L
        return (L / T) ** 2 * (ca.sumsqr(P) / 2 + y * P[0] - x * P[1] - x ** 2 + y ** 2 / 2
                               - 1 / ca.sqrt(x ** 2 + y ** 2)) + C
    return HamiltonianSystem(hamiltonian, 2, name="hill_in_units")


def found(L=1.0, T=1.0, c=0.0, C=0.0):
    """The orbit, its closure on the exact flow, and the units to read both in hill()'s."""
    system = hill(L, T, c, C)
    energy = ENERGY * (L / T) ** 2 + C
    guess = linearised_orbit(system, energy=energy, equilibrium=[LIBRATION * L + c, 0.0, 0.0,
                                                                 LIBRATION * L / T],
                             section="q2=0")
    orbit = solve_periodic(system, energy=energy, nodes=NODES, section="q2=0", guess=guess)
    assert orbit.success, orbit.message
    assert orbit.verdict.name == "accurate", orbit.verdict
    stability = periodic_stability(system, orbit)
    return orbit, stability, np.array([L, L, L / T, L / T]), np.array([c, 0.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def reference():
    return found()


# each case moves the lengths, the time unit, the origin or the energy's zero; the first runs
# in the default run, the others (repetitions of its class) in the slow tier
@pytest.mark.slow_when(lambda L, T, c, C: L != 1e-8, why="repetition")
@pytest.mark.parametrize("L, T, c, C", [(1e-8, 1e4, 3e-7, 1e-21), (1.0, 1e-3, 1e3, 1e3),
                                        (1e6, 1.0, -2e6, -5.0)])
def test_the_same_orbit_and_exact_closure_in_any_units(reference, L, T, c, C):
    orbit0, stability0, _, _ = reference
    orbit, stability, unit, origin = found(L, T, c, C)
    # the discrete orbit: one root of the same equations (IPOPT's path to it differs by
    # round-off; Newton finishes at each row's round-off)
    assert abs(orbit.orbit.period / T - orbit0.orbit.period) <= 1e-9 * orbit0.orbit.period
    q0 = (orbit.q[0] - origin[:2]) / unit[:2]
    assert np.max(np.abs(q0 - orbit0.q[0])) <= 1e-8 * np.ptp(orbit0.q, axis=0).max()
    # the exact orbit nearest it: the same segments, iterations and multiplier
    exact, exact0 = stability.exact_orbit, stability0.exact_orbit
    assert exact.converged and exact0.converged
    assert exact.cuts.size == exact0.cuts.size > 2
    assert exact.iterations == exact0.iterations
    z = (exact.z0 - origin) / unit
    assert np.max(np.abs(z - exact0.z0) / exact0.sizes) <= 1e-8
    index, index0 = (float(np.max(s.exact.indices.real)) for s in (stability, stability0))
    assert abs(index - index0) <= 1e-6 * index0
    # the verdict's figures are relative to the motion: the same numbers
    assert orbit.verdict.error_max == pytest.approx(orbit0.verdict.error_max, rel=1e-4)


def test_the_flow_grows_alike_in_any_time_unit(reference):
    """The cuts are where the flow's Jacobian has grown ``GROWTH`` times in ``|W dz|``: as many
    segments in any time unit (the plain 2-norm of ``Y`` counted the time unit in its
    position-momentum blocks: 5 segments in units of 1, 25 in units of ``1e4``). A cut falls
    on an accepted step of the pilot run, and DOP853's first step is not chosen alike in every
    time unit (scipy's rule, which the flow follows), so the fractions agree to a few steps."""
    orbit0 = reference[0]
    z0 = np.r_[orbit0.q[0], orbit0.p[0]]
    period = orbit0.orbit.period
    cuts0 = growth_cuts(hill(), [], z0, period, rtol=1e-12)
    for T in (1e4, 1e-3):
        cuts = growth_cuts(hill(T=T), [], z0 * np.r_[1, 1, 1 / T, 1 / T], period * T,
                           rtol=1e-12)
        assert cuts.size == cuts0.size > 2
        np.testing.assert_allclose(cuts, cuts0, rtol=0, atol=0.05)


def test_the_closure_in_small_lengths_iterates_as_in_lengths_of_one(reference):
    """With tolerances of ``max(1, |z_0|)`` a start ``1e-8`` of a length in size was closed at
    once, to ``1e-8`` of nothing."""
    orbit0 = reference[0]
    z0 = np.r_[orbit0.q[0], orbit0.p[0]]
    path = (orbit0.t, np.hstack([orbit0.q, orbit0.p]))
    kwargs = {"section_index": 2, "section_value": 0.0}
    exact0 = close_exact(hill(), [], z0, orbit0.orbit.period, energy=ENERGY, path=path,
                         **kwargs)
    L = 1e-8
    exact = close_exact(hill(L=L), [], z0 * L, orbit0.orbit.period, energy=ENERGY * L ** 2,
                        path=(path[0], path[1] * L), **kwargs)
    assert exact0.converged and exact.converged
    assert exact.iterations == exact0.iterations >= 1
    assert np.max(np.abs(exact.z0 / L - exact0.z0) / exact0.sizes) <= 1e-9


def test_a_grid_whose_times_turn_back_is_inaccurate_not_a_crash():
    """A solver's point with a step of the wrong sign is not a trajectory: the check says so
    (``inaccurate``, the first such step) instead of measuring it; a march run backwards
    (every step negative) is still measured."""
    system = hill()
    check = Judgement(system, [], Tolerance())
    t = np.array([0.0, 0.1, 0.05, 0.2, 0.3])
    z = np.tile([LIBRATION + 0.01, 0.0, 0.0, LIBRATION], (t.size, 1))
    report, local = check.report(t, z)
    assert report["verdict"] == "inaccurate"
    failure = report["first_failure"]
    assert failure["test"] == "node times run one way" and failure["step"] == 1
    assert failure["value"] == pytest.approx(-0.05)
    assert local.shape == (t.size - 1,)


def plane(L=1.0, T=1.0):
    """Two coupled oscillators whose plane ``q1 = p1 = 0`` is invariant (``H`` even in
    ``q1``), in lengths ``L`` and times ``T``."""
    def hamiltonian(q, p, t):
        x, P = q / L, p * T / L
        return (L / T) ** 2 * (ca.sumsqr(P) / 2 + 0.9 * x[0] ** 2 / 2 + 1.3 * x[1] ** 2 / 2
                               + 0.7 * x[0] ** 2 * x[1] - 0.25 * x[1] ** 3)
    return HamiltonianSystem(hamiltonian, 2, name="plane_in_units")


@pytest.mark.slow_when(lambda L, T: L == 1.0, why="repetition")
@pytest.mark.parametrize("L, T", [(1.0, 1.0), (1e6, 1e-3)])
def test_an_orbit_in_an_invariant_plane_is_found_alike_in_any_units(L, T):
    """The orbit in the plane ``q1 = p1 = 0`` from its linearised start: Newton stalls, IPOPT
    finds it in 7 iterations in any units. The unfolding ``tau grad H lambda`` needed
    ``lambda`` in other units in a position's row than in a momentum's, so its column's shape
    changed with the time unit and the scaled IPOPT took another path: ``solver_failed`` in
    lengths of ``1e6`` with time units of ``1e-3`` (a helper's find); the unfolding's metric
    (`closed_grid.unfolding_metric`) gives every unfolding parameter one unit."""
    system, energy = plane(L, T), 0.05 * (L / T) ** 2
    guess = linearised_orbit(system, energy=energy, equilibrium=[0.0] * 4, section="q2=0")
    orbit = solve_periodic(system, energy=energy, nodes=201, section="q2=0", guess=guess)
    assert orbit.success, orbit.message
    assert "ipopt: Solve_Succeeded after 7 iterations" in orbit.message
    assert orbit.orbit.period / T == pytest.approx(5.5725121942106, rel=1e-9)
