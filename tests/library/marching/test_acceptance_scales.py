"""The march's acceptance test takes its scales from the problem (acceptance.py), never from 1:
the same motion marched in units scaled by 1e-6 and 1e6 (``q``, ``p``, ``t`` and ``H`` by one
factor), with a constant added to ``H`` and with ``q`` translated (a system written about that
point), accepts the same steps, ends with the same status, and its nodes are the unit march's
in those units to round-off of the motion's size. A tolerance below round-off is refused in
every unit (a floor of 1 had let the micrometre march pass it), a start at ``q = 0`` with
``H = 0`` is still judged, and a state at rest at an equilibrium marches."""

import functools
import warnings

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import Compilation, HamiltonianSystem, StepControl, march
from ddvp_nlp.solvers.marching.acceptance import Acceptance, start_scales

VM = Compilation(compiler=None)  # the chunk's path on CasADi's virtual machine: no compiler
CAREFUL = Compilation(compiler=None, fast=False)
Q0, P0, TAU0, T_END = 0.5, 0.3, 0.1, 4.93  # t_end away from a node of either rule


@functools.cache  # one system per units: a march's functions are built once per system
def pendulum(s: float = 1.0, offset: float = 0.0, shift: float = 0.0) -> HamiltonianSystem:
    """``H = s H~((q - shift) / s, p / s) + offset`` of ``H~ = p^2/2 + 1 - cos q``: the
    pendulum with ``q``, ``p``, ``t`` and ``H`` in units ``1/s`` times smaller (``s = 1e-6``:
    metres to micrometres), a constant added to ``H`` and ``q`` measured from ``-shift``."""
    def hamiltonian(q, p, t):
        return s * ((p[0] / s) ** 2 / 2 + 1 - ca.cos((q[0] - shift) / s)) + offset
    return HamiltonianSystem(hamiltonian, 1, name="pendulum_in_units")


def march_in(s=1.0, offset=0.0, shift=0.0, *, scheme="vddvp", tol=1e-10, compilation=VM,
             q0=Q0, p0=P0):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the solvability monitor at rest
        return march(pendulum(s, offset, shift), [s * q0 + shift], [s * p0],
                     (0.0, s * T_END), tau0=s * TAU0, scheme=scheme,
                     steps=StepControl(tol=tol), accuracy=None, compilation=compilation)


@functools.cache
def unit_march(scheme):
    """``march_in(scheme=scheme)``, marched once for the tests that compare another unit's
    march with it (they only read it)."""
    return march_in(scheme=scheme)


# How closely the nodes agree, relative to the motion's size. Not round-off: the step's Newton
# stops where its residual is below an absolute 1e-14 in the state's units
# (``step_newton.NEWTON_OPTIONS``), which a motion of size 5e-7 meets 2e-8 of its size from
# the root; measured, the nodes of the micrometre march are 1.5e-9 of the motion's size from
# the unit march's (2.7e-9 with q translated), the megametre march's 3.3e-11, on main and here.
NEWTON = 1e-8


def assert_same_march(unit, other, s, shift=0.0):
    """Same status and steps; the nodes the unit march's in the other units, to `NEWTON` of
    the motion's size (``|q| + |shift|`` where ``q`` is translated: its round-off is there)."""
    assert other.status == unit.status and other.steps == unit.steps
    size = s * max(np.max(np.abs(unit.q)), np.max(np.abs(unit.p)))
    rounding = NEWTON * (size + abs(shift))
    np.testing.assert_allclose(other.t, s * unit.t, rtol=0, atol=NEWTON * s * T_END)
    np.testing.assert_allclose(other.q, s * unit.q + shift, rtol=0, atol=rounding)
    np.testing.assert_allclose(other.p, s * unit.p, rtol=0, atol=rounding)


@pytest.mark.parametrize("scheme", ["vddvp", "fixed"])
@pytest.mark.parametrize("s, offset, shift", [(1e-6, 0.0, 0.0), (1e6, 0.0, 0.0),
                                              (1.0, -1.0, 0.0), (1e-6, 3e-6, 2e-3)],
                         ids=["micro", "mega", "H_offset", "micro_offsets"])
def test_the_same_motion_in_other_units_accepts_the_same_steps(scheme, s, offset, shift):
    unit = unit_march(scheme)
    assert unit.success and unit.steps > 40
    assert_same_march(unit, march_in(s, offset, shift, scheme=scheme), s, shift)


@pytest.mark.parametrize("s", [1.0, 1e-6])
def test_a_tolerance_below_round_off_is_refused_in_every_unit(s):
    """``tol = 1e-17`` is below the round-off of a state of size 0.5: the first step fails in
    metres, and in micrometres too. With the floor of 1 the micrometre march passed residuals
    of 1e-22 against ``1e-17 max(1, 5e-7) = 1e-17`` and marched its 51 steps to a success."""
    for compilation in (VM, CAREFUL):
        solution = march_in(s, tol=1e-17, compilation=compilation)
        assert solution.status.name == "RESIDUAL_TOO_LARGE" and solution.steps == 0


@settings(max_examples=6, derandomize=True, deadline=None, database=None)
@given(exponent=st.floats(-6, 6), offset=st.floats(-1e3, 1e3),
       scheme=st.sampled_from(["vddvp", "lee", "fixed"]))
def test_drawn_units_and_offsets_leave_the_march_unchanged(exponent, offset, scheme):
    s = 10.0 ** exponent
    assert_same_march(unit_march(scheme), march_in(s, s * offset, scheme=scheme), s)


def test_the_scales_follow_the_units_and_ignore_a_constant_in_H():
    """``(Z, E)`` of a start at ``q = 0`` with ``H = 0`` (the pendulum at its bottom, ``H``
    offset by ``-p0^2/2``): both positive, ``E = p0 |H_p| = p0^2`` (twice the kinetic energy),
    scaled by ``s`` in units ``s``, unchanged by the constant."""
    unit = None
    for s, offset in ((1.0, 0.0), (1.0, -P0 ** 2 / 2), (1e-6, -1e-6 * P0 ** 2 / 2), (1e6, 7e6)):
        system = pendulum(s, offset)
        Z, E = start_scales(system, [0.0], [s * P0], 0.0, s * TAU0,
                            system.parameter_vector(None))
        unit = unit or (Z, E)
        assert Z == pytest.approx(s * unit[0], rel=1e-12)
        assert E == pytest.approx(s * unit[1], rel=1e-12)
    assert unit[0] == pytest.approx(P0) and unit[1] == pytest.approx(P0 ** 2, rel=1e-2)


def test_an_energy_residual_at_H_zero_is_judged_against_the_motion():
    """At ``H_k = 0`` the energy residual is judged against ``E`` of the motion: a residual of
    1e-3 of ``E`` fails at ``tol = 1e-10`` in every unit (``max(1, |H_k|)`` let it pass in
    micrometres, where ``E = 9e-8``)."""
    for s in (1.0, 1e-6):
        system = pendulum(s, -s * P0 ** 2 / 2)
        Z, E = start_scales(system, [0.0], [s * P0], 0.0, s * TAU0,
                            system.parameter_vector(None))
        acceptance = Acceptance(1e-10, z_scale=Z, H_scale=E)
        assert not acceptance.residuals_ok(0.0, 0.0, 1e-3 * E, 0.0)
        assert acceptance.residuals_ok(0.0, 0.0, 1e-11 * E, 0.0)


@pytest.mark.parametrize("scheme", ["vddvp", "fixed"])
def test_a_state_at_rest_at_an_equilibrium_marches(scheme):
    """``Z = E = 0``: the exact motion is the state itself, every residual is exactly zero and
    passes; the march reaches its end with every node at the equilibrium."""
    system = pendulum()
    assert start_scales(system, [0.0], [0.0], 0.0, TAU0,
                        system.parameter_vector(None)) == (0.0, 0.0)
    solution = march_in(q0=0.0, p0=0.0, scheme=scheme)
    assert solution.success and solution.t[-1] >= T_END and solution.steps >= 49
    assert not np.any(solution.q) and not np.any(solution.p)
