"""The edges of a constrained march: a backward span (the time-reversed system carries the
constraint g(q, -t)), continue_march (the carried drift and multipliers) and march_ensemble
(each start projected, what moved said per orbit). Each against the march over the whole span
from the same start, to tolerances taken from the march's own error estimates or from its
Newton tolerance; metamorphic relations (a time offset, the time unit, rotated coordinates);
the verdicts against the constrained exact flow.

The default-tier cases run on CasADi's virtual machine (no C compile) and short spans; the
compiled path is in the slow tier."""

import json
import warnings

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import (
    Compilation,
    HamiltonianSystem,
    InputError,
    MarchState,
    Output,
    StepControl,
    continue_march,
    march,
    march_ensemble,
)
from ddvp_nlp.solvers.marching.constrained_steps import UPDATE_SHARE

VM = Compilation(fast=False)


def pendulum_h(q, p, t, a, b, L):
    """Unit mass under the force -(a, b) (the same system as test_constrained_march.py)."""
    return (p[0] ** 2 + p[1] ** 2) / 2 + a * q[0] + b * q[1]


def rod(q, t, a, b, L):
    return q[0] ** 2 + q[1] ** 2 - L ** 2


# one system for every test: its built functions (and its time-reversed twin's) are shared
SYSTEM = HamiltonianSystem(pendulum_h, 2, {"a": 0.0, "b": 1.0, "L": 1.0}, name="cartesian",
                           constraints=rod)


def pendulum():
    return SYSTEM


def breathing_rod(q, t, w):
    """A rod whose length changes in time: a constraint that depends on t."""
    return q[0] ** 2 + q[1] ** 2 - (1 + 0.1 * ca.sin(w * t)) ** 2


def breathing(w=1.3):
    return HamiltonianSystem(lambda q, p, t, w: (p[0] ** 2 + p[1] ** 2) / 2 + q[1], 2,
                             {"w": w}, name="breathing", constraints=breathing_rod)


Q0, P0 = [0.0, -1.0], [3.0, 0.0]  # a rotation, E = 3.5: vddvp's steps apply


def error_bound(*solutions) -> np.ndarray:
    """The sum of the runs' own estimates of their largest trajectory error, per coordinate
    (the verdict's error is relative to the motion's size, per coordinate)."""
    return sum(s.verdict.error_max * np.asarray(s.verdict.scale) for s in solutions)


def newton_bound(solution, steps_after: int, tol: float = StepControl().tol) -> float:
    """What two runs that differ only in where a Newton stopped may differ by: one Newton
    update (``tol / UPDATE_SHARE`` of the unknowns' size) per step after the junction."""
    size = np.abs(np.hstack([solution.q, solution.p])).max()
    return (steps_after + 1) * tol / UPDATE_SHARE * size


@pytest.mark.parametrize("scheme", ["fixed", "vddvp"])
def test_backward_then_forward_returns_to_the_start(scheme):
    forward = march(pendulum(), Q0, P0, (0, 2), tau0=0.02, scheme=scheme, compilation=VM)
    back = march(pendulum(), forward.q[-1], forward.p[-1], (forward.t[-1], 0), tau0=0.02,
                 scheme=scheme, compilation=VM)
    assert forward.success and back.success
    assert forward.verdict.name == back.verdict.name == "accurate"
    assert np.all(np.diff(back.t) < 0) and back.march.backward
    record = back.constraints
    assert record.constraint_residual.max() <= 1e-13 and record.hidden_residual.max() <= 1e-13
    q, p = back.at([0.0])
    gap = np.abs(np.concatenate([q[0], p[0]]) - np.concatenate([Q0, P0]))
    assert np.all(gap <= error_bound(forward, back))
    if scheme == "fixed":  # a symmetric scheme on the same grid retraces its steps
        assert gap.max() <= newton_bound(back, back.t.size)


def test_a_backward_march_keeps_a_time_dependent_constraint():
    """g(q, -t) in the reversed march: the returned nodes keep g(q_k, t_k) = 0 in the original
    time, which a reversed system that forgot the sign of t would break by the rod's change."""
    system = breathing()
    length = 1 + 0.1 * np.sin(1.3 * 2.0)
    rate = 0.1 * 1.3 * np.cos(1.3 * 2.0)
    back = march(system, [0.0, -length], [2.5, -rate], (2.0, 0.0), tau0=0.01, scheme="fixed",
                 compilation=VM)  # on the rod and its hidden constraint: y' = -L'
    assert not back.constraints.start.moved
    assert back.success
    assert back.constraints.constraint_residual.max() <= 1e-13
    assert back.constraints.hidden_residual.max() <= 1e-12
    forward = march(system, back.q[-1], back.p[-1], (0.0, 2.0), tau0=0.01, scheme="fixed",
                    compilation=VM)
    gap = np.abs(np.concatenate([forward.q[-1], forward.p[-1]]) -
                 np.concatenate([back.q[0], back.p[0]]))
    assert gap.max() <= error_bound(forward, back).max()


@pytest.mark.parametrize("scheme", ["fixed", "vddvp"])
def test_a_backward_march_is_metamorphic(scheme):
    """A time offset, the time unit (t -> c t: gravity / c^2, p / c) and rotated coordinates
    (gravity along any direction, the start rotated) give the same backward march."""
    base = march(pendulum(), Q0, P0, (1.0, 0.0), tau0=0.02, scheme=scheme, compilation=VM)
    shifted = march(pendulum(), Q0, P0, (4.0, 3.0), tau0=0.02, scheme=scheme, compilation=VM)
    c = 2.0
    slow = march(pendulum(), Q0, np.asarray(P0) / c, (c, 0.0), tau0=0.02 * c, scheme=scheme,
                 params={"b": 1 / c ** 2}, compilation=VM)
    angle = 0.7
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    a, b = R @ [0.0, 1.0]
    turned = march(pendulum(), R @ Q0, R @ P0, (1.0, 0.0), tau0=0.02, scheme=scheme,
                   params={"a": a, "b": b}, compilation=VM)
    bound = newton_bound(base, base.t.size)
    for other, t, q, p in ((shifted, shifted.t - 3.0, shifted.q, shifted.p),
                           (slow, slow.t / c, slow.q, slow.p * c),
                           (turned, turned.t, turned.q @ R, turned.p @ R)):
        assert other.success and other.t.size == base.t.size
        assert np.abs(t - base.t).max() <= 1e-12
        assert np.abs(q - base.q).max() <= bound
        assert np.abs(p - base.p).max() <= bound


@pytest.mark.parametrize("scheme", ["fixed", "vddvp"])
def test_a_continued_march_is_the_whole_march(scheme):
    whole = march(pendulum(), Q0, P0, (0, 2), tau0=0.02, scheme=scheme, compilation=VM)
    steps = StepControl(max_steps=40) if scheme == "fixed" else None
    part = march(pendulum(), Q0, P0, (0, 2 if scheme == "fixed" else 1), tau0=0.02,
                 scheme=scheme, steps=steps, compilation=VM)
    carried = json.loads(json.dumps(part.march.carried))  # as a run folder keeps it
    state = MarchState.of(part.t, part.q, part.p, part.t_end, carried)
    go_on = continue_march(pendulum(), state, 2.0, tau0=0.02, scheme=scheme, compilation=VM)
    assert go_on.success and go_on.t.size == whole.t.size
    after = whole.t.size - part.t.size
    bound = newton_bound(whole, after)
    assert np.abs(go_on.t - whole.t).max() <= bound
    assert np.abs(go_on.q - whole.q).max() <= bound and np.abs(go_on.p - whole.p).max() <= bound
    # the earlier steps' multipliers, recovered from their interval rows
    assert np.abs(go_on.constraints.multipliers - whole.constraints.multipliers).max() <= \
        1e4 * newton_bound(whole, 0)
    assert go_on.verdict.name == whole.verdict.name == "accurate"
    assert go_on.constraints.constraint_residual.max() <= 1e-13
    assert go_on.canonical_residual.max() <= StepControl().tol
    assert np.abs(go_on.energy_residual).max() <= max(1e-12,
                                                       2 * np.abs(whole.energy_residual).max())


def test_a_continued_march_refuses_what_it_cannot_carry():
    part = march(pendulum(), Q0, P0, (0, 0.5), tau0=0.05, compilation=VM)
    carried = dict(part.march.carried, multipliers=[1.0, 2.0, 3.0])
    state = MarchState.of(part.t, part.q, part.p, part.t_end, carried)
    with pytest.raises(InputError, match="2m = 2 multipliers"):
        continue_march(pendulum(), state, 1.0, tau0=0.05, compilation=VM)
    with pytest.raises(InputError, match="finite"):
        MarchState.of(part.t, part.q, part.p, part.t_end,
                      dict(part.march.carried, multipliers=[np.nan, 1.0]))
    state = MarchState.of(part.t, part.q, part.p, part.t_end, part.march.carried)
    with pytest.raises(InputError, match="events"):
        continue_march(pendulum(), state, 1.0, tau0=0.05, compilation=VM,
                       output=Output(events=[lambda t, q, p: q[0]]))
    with pytest.raises(InputError, match="t_end must be at least"):
        continue_march(pendulum(), state, 0.2, tau0=0.05, compilation=VM)
    with pytest.raises(InputError, match="tau0"):
        continue_march(pendulum(), state, 1.0, tau0=0.04, compilation=VM)


def test_an_ensemble_member_is_the_same_start_marched_alone():
    """Three starts, one off the rod (projected: one warning names it, its record says what
    moved), marched in this process (workers=1: no fork in the default tier)."""
    q0s = [Q0, [0.1, -1.05], [np.sin(0.3), -np.cos(0.3)]]
    p0s = [P0, [3.0, 0.2], [3.2 * np.cos(0.3), 3.2 * np.sin(0.3)]]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        members = march_ensemble(pendulum(), q0s, p0s, (0, 1), tau0=0.02, workers=1,
                                 compilation=VM)
    said = [str(w.message) for w in caught if "starts were projected" in str(w.message)]
    assert len(said) == 1 and "1 of 3" in said[0] and "orbit 1:" in said[0]
    for i, member in enumerate(members):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            alone = march(pendulum(), q0s[i], p0s[i], (0, 1), tau0=0.02, compilation=VM)
        assert member.success and member.verdict.name == "accurate"
        assert member.t.size == alone.t.size
        bound = newton_bound(alone, alone.t.size)
        assert np.abs(member.q - alone.q).max() <= bound
        assert np.abs(member.p - alone.p).max() <= bound
        assert (member.constraints.start.moved_q > 0) == (i == 1)
        q, _ = member.at([0.5])  # the constrained field's dense output
        assert abs(q[0] @ q[0] - 1) <= 1e-3


def test_an_ensemble_start_that_cannot_be_made_consistent_names_its_orbit():
    with pytest.raises(InputError, match="orbit 1: .*singular|orbit 1: .*consistent"):
        march_ensemble(pendulum(), [Q0, [0.0, 0.0]], [P0, P0], (0, 1), tau0=0.02, workers=1,
                       compilation=VM)


@pytest.mark.slow(why="repetition")
@pytest.mark.parametrize("scheme", ["fixed", "vddvp"])
def test_the_edges_on_the_compiled_path_and_forked_workers(scheme):
    forward = march(pendulum(), Q0, P0, (0, 10), tau0=0.01, scheme=scheme)
    back = march(pendulum(), forward.q[-1], forward.p[-1], (forward.t[-1], 0), tau0=0.01,
                 scheme=scheme)
    assert back.verdict.name == "accurate"
    q, p = back.at([0.0])
    assert np.all(np.abs(np.concatenate([q[0], p[0]]) - np.concatenate([Q0, P0]))
                  <= error_bound(forward, back))
    part = march(pendulum(), Q0, P0, (0, 10 if scheme == "fixed" else 4), tau0=0.01,
                 scheme=scheme, steps=StepControl(max_steps=400) if scheme == "fixed" else None)
    state = MarchState.of(part.t, part.q, part.p, part.t_end, part.march.carried)
    go_on = continue_march(pendulum(), state, 10.0, tau0=0.01, scheme=scheme)
    assert go_on.t.size == forward.t.size
    assert np.abs(go_on.q - forward.q).max() <= newton_bound(forward, forward.t.size)
    members = march_ensemble(pendulum(), [Q0] * 3, [P0, [2.8, 0.0], [3.3, 0.0]], (0, 10),
                             tau0=0.01, scheme=scheme, workers=2)
    assert np.abs(members[0].q - forward.q).max() <= newton_bound(forward, forward.t.size)
    assert all(m.verdict.name == "accurate" for m in members)


@pytest.mark.slow(why="study")
def test_a_drifted_backward_march_says_when_in_its_own_time():
    """Released at rest at 1 rad, q(-t) = q(t) (the pendulum is reversible), so a coarse
    backward march drifts where the forward one does, at -t."""
    start = [np.sin(1.0), -np.cos(1.0)]
    forward = march(pendulum(), start, [0.0, 0.0], (0, 30), tau0=0.1, scheme="fixed")
    back = march(pendulum(), start, [0.0, 0.0], (0, -30), tau0=0.1, scheme="fixed")
    assert forward.verdict.name == back.verdict.name == "drifted"
    assert forward.verdict.t_drift > 0
    assert abs(back.verdict.t_drift + forward.verdict.t_drift) <= 0.1 + 1e-9
    assert np.abs(back.q - forward.q).max() <= 1e-12  # q(-t) = q(t), p(-t) = -p(t)
    assert np.abs(back.p + forward.p).max() <= 1e-12


@pytest.mark.slow(why="repetition")
def test_a_checkpoint_of_a_constrained_march_continues_as_the_whole_march():
    """The checkpoint's third argument is the carried state (drift, last multipliers) at its
    last node; a march continued from any checkpoint is the whole march."""
    saved = []

    def save(t, z, carried):
        saved.append((t.copy(), z.copy(), carried))
    whole = march(pendulum(), Q0, P0, (0, 30), tau0=0.01, compilation=Compilation(chunk=16),
                  output=Output(checkpoint=save, checkpoint_interval=0.01))
    assert saved and whole.success
    t, z, carried = saved[len(saved) // 2]
    assert len(carried["multipliers"]) == 2
    state = MarchState.of(t, z[:, :2], z[:, 2:], 30.0, carried)
    go_on = continue_march(pendulum(), state, 30.0, tau0=0.01, compilation=Compilation(chunk=16))
    assert go_on.t.size == whole.t.size
    assert np.abs(go_on.q - whole.q).max() <= newton_bound(whole, whole.t.size - t.size)


JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.floats(allow_nan=True) | st.integers() | st.text(max_size=5),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=3), inner,
                                                                max_size=3),
    max_leaves=8)


@settings(max_examples=60, deadline=None)
@given(value=JSON_VALUES)
def test_carried_multipliers_are_read_as_finite_numbers_or_refused_by_name(value):
    """What a run folder's meta.json may hold under carried.multipliers: a tuple of finite
    numbers (its length checked against the system later) or an InputError naming it."""
    carried = {"drift": 0.0, "careful_left": 0, "phase": 0, "multipliers": value}
    t, q = np.array([0.0]), np.array([Q0])
    try:
        state = MarchState.of(t, q, np.array([P0]), 1.0, carried)
    except InputError as exc:
        assert "multipliers" in str(exc)
        return
    assert value is None or all(np.isfinite(state.multipliers))
    assert "True" not in repr(value) and "False" not in repr(value)  # booleans are refused
