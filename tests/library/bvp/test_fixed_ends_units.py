"""A fixed-endpoint solve in other units is the same discrete solution: every row's Newton
target and verification limit comes from the problem (the rows' own round-off, the motion's
size), never from a floor of 1 or an absolute tolerance. With ``max(1, |q|, |p|, |t|)`` as the
rows' scale and ``tol`` absolute, a swing in lengths of 1e-8 stopped at 1e-6 of its motion
and passed with its energy rows 1e-5 of its energy off (measured before the change)."""

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import GridOptions, HamiltonianSystem, solve_bvp

NODES = 200
SPAN = 5.0


def swing(length: float, time: float):
    """The pendulum ``x = q / length`` in time units of ``time``: the same motion, its ``q``
    times ``length``, ``p`` times ``length / time``, ``t`` times ``time``."""
    def H(q, p, t):
        x, v = q[0] / length, p[0] * time / length
        return (length / time) ** 2 * (v ** 2 / 2 + 1 - ca.cos(x))
    return HamiltonianSystem(H, n=1, name=f"swing in units {length:g}, {time:g}")


def solved(length: float, time: float):
    return solve_bvp(swing(length, time), [0.5 * length], [0.3 * length],
                     (0.0, SPAN * time), nodes=NODES)


@pytest.fixture(scope="module")
def reference():
    return solved(1.0, 1.0)


@pytest.mark.parametrize("length, time", [(1e-8, 1.0), (1.0, 1e5), (1e6, 1e-3)])
def test_other_units_give_the_same_nodes_and_limits(reference, length, time):
    other = solved(length, time)
    assert reference.success and other.success, other.message
    # the same discrete solution to the conditioning of the grid's equations (1e-12 measured)
    assert np.max(np.abs(other.t / time - reference.t)) <= 1e-10 * SPAN
    assert np.max(np.abs(other.q / length - reference.q)) <= 1e-10 * np.ptp(reference.q)
    assert np.max(np.abs(other.p * time / length - reference.p)) <= 1e-10 * np.ptp(reference.p)
    # the energy rows' limit follows the energy's unit (within the spread of the round-off it is
    # read off); the canonical limit reported is that of the row with the largest residual, a
    # position's or a momentum's
    ratio = other.ends.energy_limit / (length / time) ** 2 / reference.ends.energy_limit
    assert 0.25 <= ratio <= 4, ratio


@pytest.mark.parametrize("t0, q0", [(1e3, 0.0), (0.0, 40.0)])
def test_a_shifted_clock_or_origin_gives_the_same_nodes(reference, t0, q0):
    """``t -> t + t0`` and ``q -> q + q0`` (``H`` of ``q - q0``): the same nodes, to the
    round-off that the larger magnitudes carry, amplified by the grid's conditioning."""
    def H(q, p, t):
        return p[0] ** 2 / 2 + 1 - ca.cos(q[0] - q0)
    system = HamiltonianSystem(H, n=1, name=f"swing shifted by {t0:g}, {q0:g}")
    other = solve_bvp(system, [0.5 + q0], [0.3 + q0], (t0, t0 + SPAN), nodes=NODES)
    assert other.success, other.message
    magnitude = max(abs(t0), abs(q0), 1.0)  # the shift's round-off, relative to the motion's
    assert np.max(np.abs(other.t - t0 - reference.t)) <= 1e-10 * magnitude * SPAN
    assert np.max(np.abs(other.q - q0 - reference.q)) <= 1e-10 * magnitude * np.ptp(reference.q)
    assert np.max(np.abs(other.p - reference.p)) <= 1e-10 * magnitude * np.ptp(reference.p)


def solved_by_ipopt(length: float, time: float):
    return solve_bvp(swing(length, time), [0.5 * length], [0.3 * length],
                     (0.0, SPAN * time), nodes=NODES, options=GridOptions(solver="ipopt"))


@pytest.fixture(scope="module")
def ipopt_reference():
    return solved_by_ipopt(1.0, 1.0)


@pytest.mark.slow_when(lambda length, time: length == 1e6, why="repetition")
@pytest.mark.parametrize("length, time", [(1e-8, 1e4), (1e6, 1e-3)])
def test_ipopt_takes_the_same_iterations_in_other_units(ipopt_reference, length, time):
    """IPOPT works on the unknowns and rows divided by their sizes (``phases.ipopt_scales``):
    the same iterations in every phase and the same nodes in any units. On the raw rows, with
    one absolute tolerance, it ended ``not_verified`` in lengths of ``1e-8`` or time units of
    ``1e5``, ``solver_failed`` after 200 iterations in lengths of ``1e6`` and time units of
    ``1e-3``, and took the straight line as solved (0 iterations) in lengths of ``1e-8`` and
    time units of ``1e4``."""
    reference, other = ipopt_reference, solved_by_ipopt(length, time)
    assert reference.success and other.success, other.message
    assert [stage.iterations for stage in other.ends.stages] == \
        [stage.iterations for stage in reference.ends.stages]
    assert all(stage.solver == "ipopt" for stage in other.ends.stages)
    assert np.max(np.abs(other.t / time - reference.t)) <= 1e-10 * SPAN
    assert np.max(np.abs(other.q / length - reference.q)) <= 1e-10 * np.ptp(reference.q)
    assert np.max(np.abs(other.p * time / length - reference.p)) <= 1e-10 * np.ptp(reference.p)
