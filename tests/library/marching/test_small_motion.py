"""Small oscillations march, or are refused for a cause the message names.

Found when the step acceptance's scales were first taken from the motion alone: the pendulum's
energy row evaluates ``1 - cos q``, whose round-off is ``eps`` of the terms' size (about 1),
not of the motion's energy (``q^2/2``), and an acceptance test relative to the motion's energy
alone refused the pendulum at amplitude 1e-3 after 2 steps. The energy rows are now allowed the
round-off bound of ``H``'s own evaluation (``physics/roundoff.py``).

Below that, two limits are real and said, not passed off as results: where the energy equation
changes by less than ``H``'s round-off over a step, round-off sets an energy rule's step length
(``1 - cos q`` at amplitude 1e-6; ``2 sin(q/2)^2``, the same function without the cancellation,
marches there); and where the whole motion is below Newton's absolute stopping test, Newton stops
at its RK4 guess, which the scheme's equations do not satisfy (a floor of 1 used to call that
guess a ``vddvp`` success with every step equal to ``tau0``)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import HamiltonianSystem, load_scene, march


def _pendulum_march(amplitude, scheme):
    scene = load_scene("pendulum")
    config = scene.resolve({})
    return march(scene.system, np.asarray(config.q0) * amplitude,
                 np.asarray(config.p0) * amplitude, (0.0, 5.0), tau0=0.05, scheme=scheme)


@pytest.mark.parametrize("amplitude,scheme", [(1e-3, "vddvp"), (1e-5, "vddvp"),
                                              (1e-3, "fixed"), (1e-6, "fixed")])
def test_a_pendulum_marches_its_small_oscillations(amplitude, scheme):
    solution = _pendulum_march(amplitude, scheme)
    assert solution.success, solution.message
    assert solution.steps >= 80
    assert solution.verdict.name == "accurate"


def test_energy_rows_at_the_round_off_of_H_are_named_as_the_cause():
    solution = _pendulum_march(1e-6, "vddvp")
    if not solution.success:
        assert solution.status.name == "RESIDUAL_TOO_LARGE"
        assert "round-off sets the step length" in solution.message
        assert "2 sin(q/2)**2" in solution.message


def _half_angle():
    return HamiltonianSystem(lambda q, p, t: p[0] ** 2 / 2 + 2 * ca.sin(q[0] / 2) ** 2, n=1,
                             name="half-angle pendulum")


def test_the_same_pendulum_without_the_cancellation_marches_by_energy_steps():
    solution = march(_half_angle(), [5e-7], [5e-7], (0.0, 5.0), tau0=0.05, scheme="vddvp")
    assert solution.success, solution.message
    assert solution.verdict.name == "accurate"
    assert np.ptp(np.diff(solution.t)) > 0  # the energy equation set the steps


@pytest.mark.parametrize("scheme", ["vddvp", "fixed"])
def test_a_motion_below_newtons_stop_is_not_passed_off_as_the_scheme(scheme):
    solution = march(_half_angle(), [5e-10], [5e-10], (0.0, 5.0), tau0=0.05, scheme=scheme)
    if solution.success:  # then Newton solved the scheme, not stopped at the guess
        assert scheme == "fixed" or np.ptp(np.diff(solution.t)) > 0
    else:
        assert "Newton stops" in solution.message
        assert "units where its size is of order 1" in solution.message
