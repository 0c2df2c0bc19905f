"""A constrained march's acceptance test takes its scales from the problem (constrained_steps.py:
each kind of row against the magnitudes it is computed from, no floor of 1): the Cartesian
pendulum marched in units scaled by 1e-6 and 1e6 (``q``, ``p``, ``t``, ``H`` and the constraint
by one factor) and with a constant added to ``H`` accepts the same steps with the same status,
its nodes the unit march's to 1e-9 of the motion's size (main's floor of 1 left the null-space
march in micrometres 8e-7 of it away); a tolerance below round-off is refused in micrometres as
in metres."""

import warnings

import numpy as np
import pytest

from ddvp_nlp import Compilation, HamiltonianSystem, StepControl, march

VM = Compilation(compiler=None)
T_END = 1.03


def cartesian_pendulum(s: float = 1.0, offset: float = 0.0) -> HamiltonianSystem:
    """``H = (px^2 + py^2)/2 + y`` on ``x^2 + y^2 = 1``, in units ``1/s`` times smaller."""
    def hamiltonian(q, p, t):
        return s * (((p[0] / s) ** 2 + (p[1] / s) ** 2) / 2 + q[1] / s) + offset

    def rod(q, t):
        return s * ((q[0] / s) ** 2 + (q[1] / s) ** 2 - 1)
    return HamiltonianSystem(hamiltonian, 2, constraints=rod, name="cartesian_in_units")


def march_in(s=1.0, offset=0.0, *, scheme="vddvp", method="multipliers", tol=1e-10):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return march(cartesian_pendulum(s, offset), [0.0, -s], [3.0 * s, 0.0], (0.0, T_END * s),
                     tau0=0.01 * s, scheme=scheme, accuracy=None, compilation=VM,
                     steps=StepControl(tol=tol, constraint_method=method))


@pytest.mark.slow_when(lambda scheme, method, **_: (scheme, method) in
                       {("vddvp", "multipliers"), ("fixed", "null_space")}, why="repetition")
@pytest.mark.parametrize("scheme, method", [("vddvp", "multipliers"), ("vddvp", "null_space"),
                                            ("fixed", "multipliers"), ("fixed", "null_space")])
def test_the_same_constrained_motion_in_other_units_accepts_the_same_steps(scheme, method):
    unit = march_in(scheme=scheme, method=method)
    assert unit.success and unit.steps > 80
    for s, offset in ((1e-6, 0.0), (1e6, 0.0), (1.0, -3.5)):
        other = march_in(s, offset, scheme=scheme, method=method)
        assert other.status == unit.status and other.steps == unit.steps, (s, other.message)
        np.testing.assert_allclose(other.q / s, unit.q, rtol=0, atol=1e-9 * 3)
        np.testing.assert_allclose(other.p / s, unit.p, rtol=0, atol=1e-9 * 3)


def test_a_tolerance_below_round_off_is_refused_in_micrometres_too():
    """At ``tol = 1e-17``, below round-off of the rows' magnitudes, the march in metres ends
    within its first steps (``RESIDUAL_TOO_LARGE`` after 3 whose residuals happen to be 0);
    the march in micrometres too, after 0 (which of the first steps round exactly to 0
    differs with the units). With the floor of 1 it passed all 103 steps in micrometres."""
    for s in (1.0, 1e-6):
        solution = march_in(s, tol=1e-17, scheme="fixed")
        assert solution.status.name == "RESIDUAL_TOO_LARGE" and solution.steps <= 3, s
