"""A derivative's own finite-difference check under an offset origin or a constant added to
``H``: the same derivatives, and a check that agrees. Measured before the change: the checks
moved an end by ``1e-5 |q|`` and an energy by ``1e-5 |E|`` (a tenth of the swing at ``q =
1e4``: "disagrees"; at ``1e6`` the re-solves failed: "not checked"), and compared the quotient
with the derivative along the move as asked, not as ``q + delta`` rounds it (a march offset by
``1e6``: "disagrees" of a derivative right to round-off)."""

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import HamiltonianSystem, Output, march, solve_bvp, solve_periodic


def swing(centre: float = 0.0, constant: float = 0.0):
    def H(q, p, t, w):
        return p[0] ** 2 / 2 + w ** 2 * (1 - ca.cos(q[0] - centre)) + constant
    return HamiltonianSystem(H, 1, {"w": 1.0}, name=f"swing at {centre:g} plus {constant:g}")


def verdicts(checks: dict) -> set:
    return {check["verdict"] for check in checks.values()}


def test_fixed_ends_far_from_the_origin():
    names = ("q_start", "q_end", "params")
    runs = [solve_bvp(swing(c), [0.1 + c], [0.5 + c], (0.0, 2.0), nodes=101, derivatives=names)
            for c in (0.0, 1e6)]
    for run in runs:
        assert run.success and verdicts(run.derivatives["checks"]) == {"agrees"}
    for name in names:
        base, other = (run.derivatives["p_end"][name] for run in runs)
        # 1e6 eps of round-off in the rows, through the grid's conditioning
        assert np.max(np.abs(other - base)) <= 1e-6 * np.max(np.abs(base))


def test_an_orbit_with_a_constant_added_to_h():
    runs = [solve_periodic(swing(constant=c), energy=0.5 + c, nodes=101,
                           derivatives=("energy", "params")) for c in (0.0, 1e7)]
    for run in runs:
        assert run.success and verdicts(run.derivatives["checks"]) == {"agrees"}
    base, other = (run.derivatives["period"]["energy"] for run in runs)
    assert other == pytest.approx(base, rel=1e-6)


@pytest.mark.slow_when(lambda centre: centre != 1e6, why="repetition")
@pytest.mark.parametrize("centre", [1e4, 1e6])
def test_a_march_far_from_the_origin(centre):
    runs = [march(swing(c), [0.5 + c], [0.0], (0.0, 10.0), tau0=0.05,
                  derivatives=("q0", "p0", "params"), output=Output(t_eval=[5.0, 10.0]))
            for c in (0.0, centre)]
    for run in runs:
        assert run.success and run.derivatives.check.verdict == "agrees", \
            run.derivatives.check
    # the check's allowance for the nodes' round-off grows with the offset, no more: at 1e4 it
    # still holds a derivative to 2e-3
    base, other = (run.derivatives.check.tolerance for run in runs)
    assert other <= base + 1e-14 * 2 * centre * np.sqrt(runs[1].t.size) / 1e-6


def units_swing(length: float, time: float):
    def H(q, p, t, w):
        return (length / time) ** 2 * ((p[0] * time / length) ** 2 / 2
                                        + w ** 2 * (1 - ca.cos(q[0] / length)))
    return HamiltonianSystem(H, 1, {"w": 1.0}, name=f"swing {length:g} {time:g}")


@pytest.mark.parametrize("scheme", ["fixed", "vddvp"])
def test_fixed_ends_in_small_lengths_and_long_times(scheme):
    """Lengths of 1e-7 and time units of 1e4: the end positions' pins had Newton's target of
    the times' pins (one target for every pin), so a check's move of an end was taken for
    converged before the first step: quotient 0, "disagrees" (measured before)."""
    names = ("q_start", "q_end", "params")
    runs = [solve_bvp(units_swing(length, time), [0.1 * length], [0.5 * length],
                      (0.0, 2.0 * time), nodes=101, scheme=scheme, derivatives=names)
            for length, time in ((1.0, 1.0), (1e-7, 1e4))]
    for run in runs:
        assert run.success and verdicts(run.derivatives["checks"]) == {"agrees"}
    base, other = (run.derivatives["p_end"]["q_start"] for run in runs)
    assert other * 1e4 == pytest.approx(base, rel=1e-8)  # dp/dq in units 1 / time
