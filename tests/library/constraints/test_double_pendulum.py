"""The double pendulum in Cartesian coordinates (4 coordinates, 2 constraints; issue 48): the
constrained march keeps both links and their hidden constraints to round-off, the energy steps
keep the interval energy to round-off, and the verdict holds against an independent reference,
the double pendulum in its two angles solved by scipy's DOP853 at rtol 1e-12. Unit masses,
lengths and gravity; a few thousand steps each (about 3 s CPU in all)."""

import warnings

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ddvp_nlp import HamiltonianSystem, march

GLOBAL_TOL = 0.01  # the default Tolerance's global_tol, relative to the verdict's scales


def hamiltonian(q, p, t):
    return (p[0] ** 2 + p[1] ** 2 + p[2] ** 2 + p[3] ** 2) / 2 + q[1] + q[3]


def links(q, t):
    return ca.vertcat(q[0] ** 2 + q[1] ** 2 - 1, (q[2] - q[0]) ** 2 + (q[3] - q[1]) ** 2 - 1)


SYSTEM = HamiltonianSystem(hamiltonian, 4, name="double_pendulum", constraints=links)


def cartesian(a, b, wa, wb):
    """Positions and momenta of both bobs from the angles ``a, b`` (from the downward
    vertical, each link's own) and their rates; arrays over the last axis."""
    a, b, wa, wb = np.broadcast_arrays(a, b, wa, wb)
    x1, y1 = np.sin(a), -np.cos(a)
    x2, y2 = x1 + np.sin(b), y1 - np.cos(b)
    u1, v1 = wa * np.cos(a), wa * np.sin(a)
    u2, v2 = u1 + wb * np.cos(b), v1 + wb * np.sin(b)
    return np.stack([x1, y1, x2, y2], -1), np.stack([u1, v1, u2, v2], -1)


def angles_field(t, y):
    """The double pendulum in its angles (unit masses, lengths, gravity)."""
    a, b, wa, wb = y
    d = a - b
    den = 3 - np.cos(2 * d)
    dwa = (-3 * np.sin(a) - np.sin(a - 2 * b)
           - 2 * np.sin(d) * (wb ** 2 + wa ** 2 * np.cos(d))) / den
    dwb = 2 * np.sin(d) * (2 * wa ** 2 + 2 * np.cos(a) + wb ** 2 * np.cos(d)) / den
    return [wa, wb, dwa, dwb]


def reference(angles, times):
    solved = solve_ivp(angles_field, (times[0], times[-1]), angles, method="DOP853",
                       rtol=1e-12, atol=1e-12, dense_output=True)
    return cartesian(*solved.sol(times))


def marched(angles, t_end, tau0, scheme):
    q0, p0 = cartesian(*angles)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # the start is consistent: no move
        return march(SYSTEM, q0, p0, (0, t_end), tau0=tau0, scheme=scheme)


def check_verdict(solution, angles):
    """A run called accurate is within the tolerance of the reference (relative to the
    verdict's scales); one called drifted has passed it, near the time it says."""
    verdict = solution.verdict
    q, p = reference(angles, solution.t)
    error = np.abs(np.hstack([q, p]) - np.hstack([solution.q, solution.p]))
    relative = (error / np.asarray(verdict.scale)).max(axis=1)
    if verdict.accurate:
        assert relative.max() <= GLOBAL_TOL
    else:
        assert relative.max() > 0.5 * GLOBAL_TOL
    if verdict.drifted:
        passes = solution.t[np.argmax(relative > GLOBAL_TOL)]
        assert abs(passes - verdict.t_drift) <= 0.1 * verdict.t_drift
    return relative.max()


def energy(solution):
    return np.array([float(hamiltonian(q, p, 0)) for q, p in zip(solution.q, solution.p,
                                                                   strict=True)])


@pytest.mark.parametrize("tau0, t_end, accurate", [(0.005, 15.0, False), (0.002, 6.0, True)])
def test_fixed_steps_on_a_chaotic_release(tau0, t_end, accurate):
    """Released at rest at angles (2, 2.5): chaotic energy (E = 1.63, the second link
    swinging over). Both constraints and their hidden ones at round-off at every node."""
    angles = (2.0, 2.5, 0.0, 0.0)
    solution = marched(angles, t_end, tau0, "fixed")
    record = solution.constraints
    assert solution.success and solution.t.size - 1 == round(t_end / tau0)
    assert record.constraint_residual.max() <= 1e-12
    assert record.hidden_residual.max() <= 1e-12
    assert record.newton_updates.max() <= 5
    check_verdict(solution, angles)
    assert solution.verdict.accurate == accurate


def test_energy_steps_keep_the_energy_to_round_off():
    """A fast start (rates 5 and 3 at the bottom, E = 41.5): vddvp's energy row at most 1e-12
    of the energy, the constraints at most 1e-12, over a few thousand steps."""
    angles = (0.0, 0.0, 5.0, 3.0)
    solution = marched(angles, 30.0, 0.005, "vddvp")
    record = solution.constraints
    H = energy(solution)
    assert solution.success and solution.t.size > 5000
    assert np.abs(solution.energy_residual).max() <= 1e-12 * abs(H[0])
    assert record.constraint_residual.max() <= 1e-12
    assert record.hidden_residual.max() <= 1e-12
    # the nodes' H is not the conserved quantity (the interval energy is): it wanders at the
    # order of the step squared, without drift
    assert np.abs(H - H[0]).max() <= 1e-3 * abs(H[0])
    check_verdict(solution, angles)
    assert solution.verdict.accurate
