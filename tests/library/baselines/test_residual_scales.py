"""The baselines' own residual tests take their scales from the problem (no floor of 1 in the
units of the state): the AVF march accepts the same steps in units scaled by 1e-6 and 1e6, and
no step Lee's left-point march accepts has residuals above ``tol`` relative to the motion in
any unit (with the floor of 1 the micrometre march accepted 39 steps whose energy residuals
reached 8.6e-9 of the motion's energy, 1e6 times its metre march's 6.9e-15)."""

import sys
from pathlib import Path

import numpy as np
import pytest

from ddvp_nlp.solvers.baselines.fixed_step import fixed_step_run
from ddvp_nlp.solvers.baselines.lee_left_stepper import lee_left_march

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "marching"))
from test_acceptance_scales import NEWTON, P0, Q0, T_END, pendulum  # noqa: E402


def _start(s):
    system = pendulum(s)
    return system, np.array([s * Q0]), np.array([s * P0]), system.parameter_vector(None)


def test_the_avf_march_accepts_the_same_steps_in_other_units():
    runs = {}
    for s in (1.0, 1e-6, 1e6):
        system, q0, p0, theta = _start(s)
        runs[s] = fixed_step_run(system, "avf", q0, p0, tau=0.1 * s, t_end=T_END * s, t0=0.0,
                                 theta=theta, compiler=None)
    unit = runs[1.0]
    assert unit.success and unit.steps == 50
    for s, other in runs.items():
        assert other.status == unit.status and other.steps == unit.steps
        np.testing.assert_allclose(other.q / s, unit.q, rtol=0, atol=NEWTON)
        np.testing.assert_allclose(other.p / s, unit.p, rtol=0, atol=NEWTON)


@pytest.mark.parametrize("s", [1.0, 1e-6])
def test_lee_left_accepts_no_step_above_its_tolerance_of_the_motion(s):
    system, q0, p0, theta = _start(s)
    solution = lee_left_march(system, q0, p0, tau0=0.01 * s, t_end=T_END * s, t0=0.0,
                              theta=theta, tol=1e-10, compiler=None)
    # the motion's energy (pendulum H ~ s) and size (~ s): both residuals relative to s
    energy = np.abs(np.asarray(solution.energy_residual)) / s
    assert solution.steps >= 1 and np.all(energy <= 1e-10)
