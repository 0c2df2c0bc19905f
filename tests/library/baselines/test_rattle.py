"""RATTLE and SHAKE (``solvers/baselines/rattle.py``, steps in ``discrete/constrained_verlet.py``):
order 2 on the Cartesian pendulum against its elliptic solution, the constraints at the Newton
tolerance, SHAKE's energy error following its tolerance (the long study:
``scripts/benchmarks/bench_rattle.py``), the verdicts of the accuracy check against the
constrained exact flow, refusals, random pendulums and metamorphic relations.

Constrained systems from ``helpers.constrained`` (a stand-in for the core's constraints)."""

import numpy as np
import pytest
from helpers.common import fitted_order
from helpers.constrained import cartesian_pendulum, pendulum_start, spherical_pendulum
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import ellipj, ellipk

from ddvp_nlp import HamiltonianSystem, InputError
from ddvp_nlp.solvers import INTEGRATORS, Tolerance, assess
from ddvp_nlp.solvers.baselines.rattle import RATTLE, SHAKE, rattle_run
from ddvp_nlp.solvers.exact.constrained_flow import constraint_residuals

THETA = [1.0, 1.0]


# the unit pendulum as one system for the module: what a run builds is kept per system
PENDULUM = cartesian_pendulum()


def elliptic(t, angle):
    """The unit pendulum released at rest at ``angle`` (see tests/library/exact/
    test_constrained_reference.py for the derivation's check)."""
    k = np.sin(angle / 2)
    sn, cn, _, _ = ellipj(ellipk(k * k) - np.asarray(t, float), k * k)
    theta, omega = 2 * np.arcsin(k * sn), -2 * k * cn
    return np.column_stack([np.sin(theta), -np.cos(theta), omega * np.cos(theta),
                            omega * np.sin(theta)])


def run(method="rattle", tau=0.05, t_end=10.0, angle=1.0, **options):
    z0 = pendulum_start(angle)
    options.setdefault("theta", THETA)
    return rattle_run(PENDULUM, z0[:2], z0[2:], tau=tau, t_end=t_end,
                      method=method, **options)


def nodes(solution):
    return np.hstack([solution.q, solution.p])


def test_both_are_registered_once():
    names = [m.name for m in INTEGRATORS]
    assert names.count("rattle") == 1 and names.count("shake") == 1


@pytest.mark.parametrize("method, momentum_order", [("rattle", 2), ("shake", 1)])
def test_order_on_the_cartesian_pendulum(method, momentum_order):
    # positions of order 2 for both; SHAKE's node momenta keep an O(tau) normal component
    taus = [0.1, 0.05, 0.025, 0.0125]
    position, momentum = [], []
    for tau in taus:
        solution = run(method, tau=tau, t_end=5.0)
        assert solution.success
        exact = elliptic(5.0, 1.0)[0]
        position.append(np.max(np.abs(solution.q[-1] - exact[:2])))
        momentum.append(np.max(np.abs(solution.p[-1] - exact[2:])))
    assert 1.9 <= fitted_order(taus, position) <= 2.1, position  # measured 2.00 (both)
    assert momentum_order - 0.1 <= fitted_order(taus, momentum) <= momentum_order + 0.1


def test_rattle_keeps_both_constraints_at_its_newton_tolerance():
    solution = run(tau=0.05, t_end=500.0, tol=1e-14)  # 10^4 steps
    g, h = constraint_residuals(PENDULUM, solution.t, nodes(solution), THETA)
    assert solution.success and solution.t.size == 10_001
    assert g.max() <= 1e-12 and h.max() <= 1e-12  # measured 4.4e-16, 2.2e-16
    assert np.max(solution.stats["newton"]) <= 2 * 5  # two solves, quadratic


def test_shake_keeps_only_the_position_constraint():
    solution = run("shake", tau=0.05, t_end=50.0, tol=1e-14)
    g, h = constraint_residuals(PENDULUM, solution.t, nodes(solution), THETA)
    assert g.max() <= 1e-14
    assert h.max() > 1e-3  # its node momenta are not projected (O(tau))


def test_shake_energy_error_follows_its_tolerance():
    # short version of bench_rattle.py: against SHAKE at tol 1e-15 with the same steps, the
    # energy difference grows over the run and scales with the tolerance
    system = PENDULUM

    def energy(tol):
        solution = run("shake", tau=0.05, t_end=1000.0, tol=tol)
        return system.energy(solution.q, solution.p, solution.t, THETA)
    tight = energy(1e-15)
    gaps = {tol: np.abs(energy(tol) - tight) for tol in (1e-8, 1e-10, 1e-12)}
    largest = [gap.max() for gap in gaps.values()]
    # measured 8.2e-9, 5.4e-11, 2.3e-12: down with the tolerance, by 23 .. 150 a factor 100
    assert largest[0] > 10 * largest[1] > 100 * largest[2]
    for tol, gap in gaps.items():
        assert gap.max() <= 100 * tol
        tenth = gap.size // 10
        assert gap[-tenth:].mean() > 3 * gap[:tenth].mean()  # it drifts


def test_verdicts_against_the_constrained_exact_flow():
    # a large step drifts where the elliptic solution says it leaves the tolerance; a small
    # one is accurate and its measured error is the true one
    system = PENDULUM
    for tau, verdict in ((0.1, "drifted"), (0.003, "accurate")):
        solution = run(tau=tau, t_end=100.0)
        z = nodes(solution)
        report, _ = assess(system, solution.t, z, THETA, Tolerance())
        assert report["verdict"] == verdict
        exact = elliptic(solution.t, 1.0)
        error = np.max(np.abs(z - exact) / np.array(report["scale"]), axis=1)
        if verdict == "accurate":
            assert error.max() <= report["global_tol"]
            assert abs(error.max() - report["error_max"]) <= 1e-3 * error.max()
        else:
            first = solution.t[np.argmax(error > report["global_tol"])]
            assert abs(report["t_drift"] - first) <= tau  # measured: equal (11.5)


# -- refusals and bad input ------------------------------------------------------------------

def test_refused_on_unconstrained_systems():
    plain = HamiltonianSystem(lambda q, p, t: p[0] ** 2 / 2 + q[0] ** 2 / 2, 1, name="sho")
    for method in (RATTLE, SHAKE):
        assert "holonomic constraints" in method.applies(plain)
        assert method.applies(PENDULUM) is None
    with pytest.raises(InputError, match="shake needs a system with holonomic constraints"):
        rattle_run(plain, [1.0], [0.0], tau=0.1, t_end=1.0, method="shake")


def test_refused_on_a_non_separable_hamiltonian():
    from helpers.constrained import with_constraints

    def H(q, p, t):
        return (1 + q[1] ** 2) * (p[0] ** 2 + p[1] ** 2) / 2
    system = with_constraints(HamiltonianSystem(H, 2), lambda q, t: q[0] ** 2 + q[1] ** 2 - 1)
    assert "separable" in RATTLE.applies(system)


@pytest.mark.parametrize("change, words", [
    ({"tau": -0.1}, "tau must be positive"),
    ({"tau": np.nan}, "tau must be positive"),
    ({"tol": 0.0}, "tol must be positive"),
    ({"t_end": -1.0}, "t_end must be finite and after t0"),
    ({"method": "verlet"}, "method must be one of"),
    ({"theta": [1.0]}, "theta must be 2 finite numbers"),
])
def test_bad_inputs_are_named(change, words):
    with pytest.raises(InputError, match=words):
        run(**change)


def test_too_many_steps_is_named():
    with pytest.raises(InputError, match="max_steps"):
        run(tau=1e-3, t_end=10.0, max_steps=100)


def test_a_failed_solve_ends_the_run_with_its_nodes():
    solution = run(tau=0.05, t_end=1.0, tol=1e-30)  # below round-off: reached by luck at most
    assert solution.status.name == "RESIDUAL_TOO_LARGE" and solution.t.size < 21
    assert "the constraint solve stopped at" in solution.message


# -- random pendulums and metamorphic relations ----------------------------------------------

@settings(max_examples=5, deadline=None)
@given(length=st.floats(0.3, 3.0), mass=st.floats(0.2, 5.0), angle=st.floats(0.1, 2.5))
def test_random_pendulums_keep_their_constraints(length, mass, angle):
    system, gravity = cartesian_pendulum(length, mass, 1.0), 1.0
    z0 = pendulum_start(angle, length, mass)
    tau = 0.02 * np.sqrt(length / gravity)
    solution = rattle_run(system, z0[:2], z0[2:], tau=tau, t_end=200 * tau,
                          theta=[mass, gravity])
    g, h = constraint_residuals(system, solution.t, nodes(solution), [mass, gravity])
    assert solution.success
    size = 2 * length ** 2  # the terms of g, as the default tolerance reads them
    assert g.max() <= 1e-13 * size and tau * h.max() <= 1e-13 * size


def test_time_offset_and_units():
    base = run(tau=0.05, t_end=5.0)
    later = run(tau=0.05, t_end=45.0, t0=40.0)
    assert np.max(np.abs(nodes(base) - nodes(later))) <= 1e-12
    # lengths x3, masses x2, time x5: positions x3, momenta x 6/5, the same steps
    length, mass, clock = 3.0, 2.0, 5.0
    z0 = pendulum_start(1.0, length, mass)
    scaled = rattle_run(cartesian_pendulum(length, mass, length / clock ** 2), z0[:2], z0[2:],
                        tau=0.05 * clock, t_end=5.0 * clock, theta=[mass, length / clock ** 2])
    factor = np.array([length] * 2 + [mass * length / clock] * 2)
    assert np.max(np.abs(nodes(scaled) / factor - nodes(base))) <= 1e-12


def test_spherical_pendulum_keeps_its_angular_momentum():
    # RATTLE is symmetric under rotations about the vertical: L_z is kept to round-off
    system = spherical_pendulum()
    z0 = np.array([0.0, np.sin(0.1), -np.cos(0.1), 0.06, 0.0, 0.0])
    solution = rattle_run(system, z0[:3], z0[3:], tau=0.05, t_end=500.0, theta=[])
    z = nodes(solution)
    Lz = z[:, 0] * z[:, 4] - z[:, 1] * z[:, 3]
    assert np.max(np.abs(Lz / Lz[0] - 1)) <= 1e-12


def test_a_moving_pivot_is_the_pendulum_seen_from_a_moving_frame():
    # time-dependent constraint g = (x - c t)^2 + y^2 - 1: RATTLE's nodes are the pendulum's
    # shifted by the frame (RATTLE commutes with a Galilean boost), its hidden constraint kept
    from helpers.constrained import with_constraints
    c = 0.3

    def H(q, p, t):
        return (p[0] ** 2 + p[1] ** 2) / 2 + q[1]
    moving = with_constraints(HamiltonianSystem(H, 2, name="moving_pivot"),
                              lambda q, t: (q[0] - c * t) ** 2 + q[1] ** 2 - 1)
    z0 = pendulum_start(1.0)
    still = run(tau=0.05, t_end=20.0)
    solution = rattle_run(moving, z0[:2], z0[2:] + [c, 0.0], tau=0.05, t_end=20.0, theta=[])
    boost = np.column_stack([c * solution.t, 0 * solution.t, c + 0 * solution.t,
                             0 * solution.t])
    assert np.max(np.abs(nodes(solution) - boost - nodes(still))) <= 1e-11
    _, h = constraint_residuals(moving, solution.t, nodes(solution), [])
    assert h.max() <= 1e-12
