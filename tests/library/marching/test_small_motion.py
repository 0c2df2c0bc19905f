"""Small motions march as the same motions in units of 1, or are refused for a cause the
message names.

Found when the step acceptance's scales were first taken from the motion alone: the pendulum's
energy row evaluates ``1 - cos q``, whose round-off is ``eps`` of the terms' size (about 1),
not of the motion's energy (``q^2/2``), and an acceptance test relative to the motion's energy
alone refused the pendulum at amplitude 1e-3 after 2 steps. The energy rows are now allowed the
round-off bound of ``H``'s own evaluation (``physics/roundoff.py``). Then, that Newton's
absolute stopping test (1e-14) passed at the RK4 guess of a motion far below the units (a floor
of 1 had called that guess a ``vddvp`` success with every step equal to ``tau0``); Newton's rows
are now divided by min(1, |z| / 1e-2) (``steps.newton_scale``) and the
careful path polishes a root its ``newton`` left short.

Where the energy equation changes by less than ``H``'s round-off over a step, round-off sets an
energy rule's step lengths (``1 - cos q`` at amplitude 1e-6: steps from 0.05 to 0.068); the run
is then judged whole by the accuracy check, and a step refused there names that cause
(``2 sin(q/2)^2``, the same function without the cancellation, has steps its energy sets)."""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import HamiltonianSystem, load_scene, march

# loaded once: a march's functions are built once per system (ddvp_nlp/cache.py)
PENDULUM = load_scene("pendulum")


def _pendulum_march(amplitude, scheme):
    scene = PENDULUM
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


def test_energy_rows_at_the_round_off_of_H_are_judged_or_named_as_the_cause():
    solution = _pendulum_march(1e-6, "vddvp")
    if solution.success:  # the steps round-off sets still solve the scheme within it
        assert solution.verdict.name == "accurate"
        assert solution.steps >= 70
    else:
        assert solution.status.name == "RESIDUAL_TOO_LARGE"
        assert "round-off sets the step length" in solution.message
        assert "2 sin(q/2)**2" in solution.message


def test_a_refusal_at_the_round_off_of_H_names_the_cause():
    """The message of a step refused where the energy equation changes by less than H's
    round-off over a step (`Acceptance.residuals_refused` at the pendulum's start, 1e-6)."""
    from ddvp_nlp.solvers.marching.acceptance import Acceptance
    from ddvp_nlp.solvers.options import StepControl

    scene = PENDULUM
    config = scene.resolve({})
    acceptance = Acceptance.at_start(StepControl(), scene.system,
                                     np.asarray(config.q0) * 1e-6,
                                     np.asarray(config.p0) * 1e-6, 0.0, 0.05, [])
    words = acceptance.residuals_refused(5e-15, 6e-7, 0.0, 1e-13)
    assert "round-off sets the step length" in words and "2 sin(q/2)**2" in words
    # at amplitude 1e-2 the energy equation is far above H's round-off: no such words
    acceptance = Acceptance.at_start(StepControl(), scene.system,
                                     np.asarray(config.q0) * 1e-2,
                                     np.asarray(config.p0) * 1e-2, 0.0, 0.05, [])
    assert "round-off" not in acceptance.residuals_refused(5e-12, 6e-3, 0.0, 1e-5)


def _half_angle():
    return HamiltonianSystem(lambda q, p, t: p[0] ** 2 / 2 + 2 * ca.sin(q[0] / 2) ** 2, n=1,
                             name="half-angle pendulum")


def test_the_same_pendulum_without_the_cancellation_marches_by_energy_steps():
    solution = march(_half_angle(), [5e-7], [5e-7], (0.0, 5.0), tau0=0.05, scheme="vddvp")
    assert solution.success, solution.message
    assert solution.verdict.name == "accurate"
    assert np.ptp(np.diff(solution.t)) > 0  # the energy equation set the steps


# The Duffing oscillator, one system for the module (lengths by L are the parameter b = L^-2):
# a march's functions are built once per system (ddvp_nlp/cache.py)
DUFFING = HamiltonianSystem(
    lambda q, p, t, a, b: p[0] ** 2 / 2 + a * q[0] ** 2 / 2 + b * q[0] ** 4 / 4, n=1,
    params={"a": 1.0, "b": 1.0}, name="duffing")


@functools.cache  # the march in units of 1 is every size's reference: marched once a scheme
def duffing_march(L, scheme):
    return march(DUFFING, [L], [0.5 * L], (0.0, 20.0), tau0=0.05, scheme=scheme,
                 params={"a": 1.0, "b": 1.0 / L ** 2})


@pytest.mark.parametrize("scheme", ["vddvp", "fixed"])
@pytest.mark.parametrize("size", [1e-5, 1e-10])
def test_a_motion_far_below_the_units_marches_as_in_units_of_one(size, scheme):
    """The Duffing oscillator with lengths by ``size`` (``b`` by ``size^-2``: the same
    physics): the same steps and verdict as in units of 1."""
    one, small = duffing_march(1.0, scheme), duffing_march(size, scheme)
    assert small.success, small.message
    assert small.steps == one.steps
    assert small.verdict.name == one.verdict.name
    # the node times agree to the rounding the acceptance allows (tol 1e-10 of the motion)
    assert np.max(np.abs(np.asarray(small.t) - np.asarray(one.t))) <= 1e-6
    if scheme == "vddvp":
        assert np.ptp(np.diff(small.t)) > 0  # the energy equation set the steps


def test_kepler_in_lengths_of_1e_minus_10_takes_the_steps_of_units_of_one():
    """Found by a user: 5001 equal steps (its RK4 guess) called an accurate vddvp success,
    where the same orbit in units of 1 takes 1259 steps and drifts."""
    system = HamiltonianSystem(lambda q, p, t, k: ca.dot(p, p) / 2 - k / ca.norm_2(q),
                               n=2, params={"k": 1.0}, name="kepler")  # one system, k = L^3

    def run(L):
        e = 0.6
        return march(system, np.array([1 - e, 0.0]) * L,
                     np.array([0.0, np.sqrt((1 + e) / (1 - e))]) * L, (0.0, 10.0), tau0=0.01,
                     params={"k": L ** 3})
    one, small = run(1.0), run(1e-10)
    assert small.success, small.message
    assert small.steps == one.steps
    assert small.verdict.name == one.verdict.name


def test_the_energy_guard_stops_at_the_same_node_in_any_units():
    """Found by a user: ``energy_guard`` read ``max(1, |H0|)``, so a Duffing oscillator in
    millimetres passed a band the same motion in metres and kilometres left at step 3."""
    from ddvp_nlp.solvers.options import StepControl

    def run(L):
        return march(DUFFING, [L], [0.5 * L], (0.0, 20.0), tau0=0.2, scheme="fixed",
                     steps=StepControl(energy_guard=1e-3), params={"a": 1.0, "b": 1.0 / L ** 2})
    runs = [run(L) for L in (1.0, 1e-3, 1e3)]
    assert {r.status.name for r in runs} == {"ENERGY_GUARD"}
    assert len({r.steps for r in runs}) == 1
