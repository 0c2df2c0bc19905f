"""Fixed ends of a constrained system in other units are the same discrete solution with the
same verdict: Newton's targets are each row's round-off and the verification's limits are
``tol`` relative to what each row measures, never a floor of 1 or an absolute ``tol``. With
``max(1, |q_ends|, |t_ends|)`` as the rows' scale, the Cartesian pendulum in lengths of
``1e-8`` or in time units of ``1e5`` returned its start (0 iterations, the energy rows ``1e-5``
of the energy off) as a verified ``vddvp`` solution, ``4.5e-2`` of the rod off the solution in
units of 1 (measured before the change)."""

import functools
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import GridOptions, HamiltonianSystem, solve_bvp
from ddvp_nlp.solution import Status

NODES = 41
SPAN = 2.0
ANGLES = (0.3, -0.5)


def pendulum(length: float, time: float, centre: float = 0.0):
    """A point on a rod of ``length`` about ``(centre, centre)`` under gravity ``length /
    time^2``: the unit pendulum with ``q`` times ``length`` (plus the centre), ``p`` times
    ``length / time`` and ``t`` times ``time``."""
    gravity = length / time ** 2

    def H(q, p, t):
        return (p[0] ** 2 + p[1] ** 2) / 2 + gravity * (q[1] - centre)

    def rod(q, t):
        return (q[0] - centre) ** 2 + (q[1] - centre) ** 2 - length ** 2
    return HamiltonianSystem(H, 2, name=f"rod {length:g}, time {time:g}, centre {centre:g}",
                             constraints=rod)


def point(angle: float, length: float, centre: float = 0.0) -> np.ndarray:
    return centre + length * np.array([np.sin(angle), -np.cos(angle)])


def solved(length: float, time: float, scheme: str, centre: float = 0.0, t0: float = 0.0):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an end projected by rounding
        return solve_bvp(pendulum(length, time, centre), point(ANGLES[0], length, centre),
                         point(ANGLES[1], length, centre), (t0, t0 + SPAN * time),
                         nodes=NODES, scheme=scheme)


@functools.cache
def reference(scheme: str):
    return solved(1.0, 1.0, scheme)


def assert_same(other, length: float, time: float, scheme: str, centre: float = 0.0,
                t0: float = 0.0, digits: float = 1e-10):
    base = reference(scheme)
    assert base.status is Status.SUCCESS and other.status is Status.SUCCESS, other.message
    assert other.verdict.name == base.verdict.name
    # the same nodes, to the conditioning of the grid's equations (1e-13 measured)
    assert np.max(np.abs((other.t - t0) / time - base.t)) <= digits * SPAN
    assert np.max(np.abs((other.q - centre) / length - base.q)) <= digits
    assert np.max(np.abs(other.p * time / length - base.p)) <= digits * np.ptp(base.p)


# lengths of 1e-8 stay in the default run; the other units repeat it
@pytest.mark.slow_when(lambda length, time: (length, time) != (1e-8, 1.0), why="repetition")
@pytest.mark.parametrize("length, time", [(1e-8, 1.0), (1.0, 1e5), (1e8, 1.0), (1e6, 1e-3)])
def test_the_energy_rule_in_other_units_is_the_same_solution(length, time):
    other = solved(length, time, "vddvp")
    assert_same(other, length, time, "vddvp")
    # Newton solved the energy rows: it did not stop at the start
    assert other.stats["iterations"] > 0
    # the limits follow the units: a constraint row's the rod's square, an energy row's H's
    base = reference("vddvp")
    ratio = other.constraints.constraint_limit / length ** 2 / base.constraints.constraint_limit
    assert 0.25 <= ratio <= 4, ratio
    ratio = other.ends.energy_limit / (length / time) ** 2 / base.ends.energy_limit
    assert 0.25 <= ratio <= 4, ratio


@pytest.mark.slow_when(lambda length, time: (length, time) != (1e-8, 1.0), why="repetition")
@pytest.mark.parametrize("length, time", [(1e-8, 1.0), (1.0, 1e5)])
def test_fixed_steps_in_other_units_are_the_same_solution(length, time):
    assert_same(solved(length, time, "fixed"), length, time, "fixed")


def test_a_shifted_centre_and_clock_give_the_same_nodes():
    """The rod about ``(1e4, 1e4)``, the clock from ``t = 1e3``: the same nodes, to the
    round-off those magnitudes carry (1e4 times the unit case's) through the grid's
    conditioning."""
    other = solved(1.0, 1.0, "vddvp", centre=1e4, t0=1e3)
    assert_same(other, 1.0, 1.0, "vddvp", centre=1e4, t0=1e3, digits=1e-6)


@settings(max_examples=3, deadline=None, derandomize=True)
@given(length=st.floats(-9, 9), time=st.floats(-4, 4))
def test_drawn_units(length, time):
    length, time = 10.0 ** length, 10.0 ** time
    assert_same(solved(length, time, "vddvp"), length, time, "vddvp")


def test_an_unsolved_point_is_refused_in_small_units():
    """The verification's limits are relative: one Newton step from the solution in units of
    1, scaled to lengths of ``1e-8`` and moved by ``1e-3`` of the rod, leaves rows far above
    their round-off but below ``1e-10`` as absolute numbers; it is not passed for a solution
    (an absolute ``tol`` passed it)."""
    length = 1e-8
    base = reference("vddvp")
    wiggle = 1e-3 * np.sin(np.linspace(0.0, np.pi, NODES))[:, None]
    guess = {"t": base.t, "q": length * (base.q + wiggle), "p": length * base.p}
    run = solve_bvp(pendulum(length, 1.0), length * base.q[0], length * base.q[-1],
                    (0.0, SPAN), nodes=NODES, scheme="vddvp", guess=guess,
                    options=GridOptions(max_iter=1, solver="newton"))
    assert run.status is not Status.SUCCESS, run.message
    assert "above its limit" in run.message


def solved_by_ipopt(length: float, time: float):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return solve_bvp(pendulum(length, time), point(ANGLES[0], length),
                         point(ANGLES[1], length), (0.0, SPAN * time), nodes=NODES,
                         scheme="vddvp", options=GridOptions(solver="ipopt"))


@pytest.mark.slow_when(lambda length, time: length == 1e6, why="repetition")
@pytest.mark.parametrize("length, time", [(1e-8, 1e4), (1e6, 1e-3)])
def test_ipopt_takes_the_same_iterations_in_other_units(length, time):
    """IPOPT on the unknowns and rows divided by their sizes (``ConstrainedIpopt.sizes``):
    the same iterations and nodes in any units. On the raw rows it ended ``not_verified`` in
    lengths of ``1e-8`` with time units of ``1e4`` (1 iteration) and ``solver_failed`` in
    lengths of ``1e6`` with time units of ``1e-3`` (200 iterations)."""
    base, other = solved_by_ipopt(1.0, 1.0), solved_by_ipopt(length, time)
    assert base.status is Status.SUCCESS and other.status is Status.SUCCESS, other.message
    assert [s.iterations for s in other.ends.stages] == [s.iterations for s in base.ends.stages]
    assert np.max(np.abs(other.t / time - base.t)) <= 1e-10 * SPAN
    assert np.max(np.abs(other.q / length - base.q)) <= 1e-10
    assert np.max(np.abs(other.p * time / length - base.p)) <= 1e-10 * np.ptp(base.p)
