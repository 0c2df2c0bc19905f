"""Energy-determined steps on a constraint that moves: a bead on a hoop turning about the
vertical. The hoop does work on the bead, so ``H`` changes along the motion, and the energy
row of ``vddvp`` is ``E_k - E_{k-1} = W_k`` (``discrete/constrained.py``, `constraint_work`:
the node time's derivative of the multiplier term of the augmented action). Before, the row
read ``E_k = E_{k-1}`` and had no positive root after the first step.

Judged against the bead's angle equation ``theta'' = sin(theta) (w^2 cos(theta) - g / R)``
solved by scipy's DOP853 (independent of the package's constrained reference): the verdict's
error and drift time equal the true ones; the end error falls at order 2 in ``tau0``; the
constraints hold to round-off in both forms; metamorphic relations (a time offset carried by
the constraint, a change of units); ``lee`` is ``vddvp`` for this autonomous ``H`` (its row is
the derivative of the action in ``t_k`` by CasADi); a libration stops where the coefficient
``c`` of docs/theory.md section 12 changes sign, as on a fixed hoop."""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from ddvp_nlp import Compilation, HamiltonianSystem, MarchState, StepControl, continue_march, march
from ddvp_nlp.solution import Status
from ddvp_nlp.solvers.marching.constrained_steps import UPDATE_SHARE

VM = Compilation(fast=False)
SPIN, SPEED = 0.7, 3.0  # the hoop's rate; the bead's speed at the bottom (it goes round)
DEFAULTS = {"R": 1.0, "grav": 1.0, "w": SPIN, "c": 0.0}


def hamiltonian(q, p, t, R, grav, w, c):
    return ca.sumsqr(p) / 2 + grav * q[2]


def hoop_constraints(q, t, R, grav, w, c):
    """The sphere of radius ``R`` and the vertical plane at angle ``w (t + c)``."""
    angle = w * (t + c)
    return ca.vertcat(ca.sumsqr(q) - R ** 2, -ca.sin(angle) * q[0] + ca.cos(angle) * q[1])


HOOP = HamiltonianSystem(hamiltonian, 3, DEFAULTS, constraints=hoop_constraints,
                         name="turning hoop energy steps")


def run(tau0, t_span=(0.0, 10.0), method="multipliers", scheme="vddvp", q0=None, p0=None,
        params=None):
    q0 = [0.0, 0.0, -1.0] if q0 is None else q0
    p0 = [SPEED, 0.0, 0.0] if p0 is None else p0
    return march(HOOP, q0, p0, t_span, tau0=tau0, scheme=scheme, params=params,
                 steps=StepControl(constraint_method=method), compilation=VM)


@functools.cache
def plain_run(tau0, t_span=(0.0, 10.0), method="multipliers", scheme="vddvp"):
    """``run`` from the default start, once per arguments for the module: the tests that march
    the same run read the same solution."""
    return run(tau0, t_span, method, scheme)


def exact(t, theta0=0.0, rate0=SPEED, R=1.0, grav=1.0, w=SPIN, c=0.0):
    """``(q, p)`` at the times ``t`` (either side of 0) from the angle equation started at
    ``t = 0`` (DOP853, tolerances 1e-13)."""
    def field(_, y):
        return [y[1], np.sin(y[0]) * (w ** 2 * np.cos(y[0]) - grav / R)]
    t = np.asarray(t, float)
    th, om = np.empty_like(t), np.empty_like(t)
    for side in (t < 0, t >= 0):
        if side.any():
            end = t[side].min() if t[side].min() < 0 else t[side].max()
            solution = solve_ivp(field, (0.0, end), [theta0, rate0], method="DOP853",
                                 rtol=1e-13, atol=1e-13, dense_output=True)
            th[side], om[side] = solution.sol(t[side])
    phi = w * (t + c)
    cp, sp, ct, st_ = np.cos(phi), np.sin(phi), np.cos(th), np.sin(th)
    q = R * np.stack([st_ * cp, st_ * sp, -ct], 1)
    p = R * np.stack([ct * om * cp - w * st_ * sp, ct * om * sp + w * st_ * cp, st_ * om], 1)
    return q, p


def true_errors(solution) -> np.ndarray:
    """Per node, the largest error against `exact` relative to the verdict's scales."""
    q, p = exact(solution.t)
    error = np.abs(np.hstack([solution.q - q, solution.p - p]))
    return (error / np.asarray(solution.verdict.scale)).max(axis=1)


def newton_bound(solution) -> float:
    """Two marches that differ only where each Newton stopped: one update (``tol /
    UPDATE_SHARE`` of the unknowns' size) per step."""
    size = np.abs(np.hstack([solution.q, solution.p])).max()
    return solution.t.size * StepControl().tol / UPDATE_SHARE * size


@pytest.mark.parametrize("method", ["multipliers", "null_space"])
def test_energy_steps_follow_the_turning_hoop(method):
    """799 energy steps to t = 10, the bead going round the hoop: a success the independent
    angle equation confirms (measured: largest error 4.0e-3 of the motion's size, the
    verdict's the same to 1e-9), with the constraints at round-off while H changes by the
    hoop's work."""
    solution = plain_run(0.01, method=method)
    assert solution.status is Status.SUCCESS and solution.verdict.name == "accurate"
    truth = true_errors(solution)
    assert truth.max() < 0.01
    assert solution.verdict.error_max == pytest.approx(truth.max(), rel=1e-2)
    record = solution.constraints
    assert record.constraint_residual.max() <= 1e-14
    assert record.hidden_residual.max() <= 1e-14
    H = HOOP.energy(solution.q, solution.p, solution.t, HOOP.parameter_vector())
    assert np.ptp(H) > 0.3  # the hoop's work: H is not what the row keeps
    assert np.abs(solution.energy_residual).max() <= 1e-13 * np.abs(H).max()
    taus = np.diff(solution.t)
    assert 0.0099 < taus.min() and taus.max() < 0.02  # steps of the size of tau0


def test_the_two_forms_march_the_same_nodes_on_the_turning_hoop():
    multipliers, null_space = (plain_run(0.02, (0.0, 3.0), method=m)
                               for m in ("multipliers", "null_space"))
    assert multipliers.t.size == null_space.t.size
    assert np.abs(multipliers.t - null_space.t).max() <= 1e-10
    assert np.abs(multipliers.q - null_space.q).max() <= 1e-10


def test_order_two_and_the_drift_verdict_against_the_angle_equation():
    """End error at t = 10 against DOP853: measured 5.72e-2, 1.46e-2, 3.70e-3 at tau0 = 0.02,
    0.01, 0.005 (ratios 3.91, 3.95). At tau0 = 0.02 the run drifts: the verdict's drift time is
    the node where the true error first passes 0.01 of the motion's size (t = 6.95)."""
    runs = [plain_run(tau0) for tau0 in (0.02, 0.01, 0.005)]
    ends = []
    for solution in runs:
        assert solution.status is Status.SUCCESS
        q, p = exact(solution.t)
        ends.append(np.abs(np.hstack([solution.q[-1] - q[-1], solution.p[-1] - p[-1]])).max())
    orders = np.log2(np.array(ends[:-1]) / np.array(ends[1:]))
    assert np.all((orders > 1.9) & (orders < 2.1)), orders
    coarse = runs[0]
    truth = true_errors(coarse)
    assert coarse.verdict.name == "drifted"
    assert coarse.verdict.t_drift == coarse.t[np.argmax(truth > coarse.verdict.global_tol)]
    assert [s.verdict.name for s in runs[1:]] == ["accurate", "accurate"]


def test_a_time_offset_carried_by_the_constraint_gives_the_same_nodes():
    """The hoop marched from t = 1.3 equals the hoop written at t + 1.3 marched from 0."""
    offset, span = 1.3, 2.0
    turned = [SPEED * np.cos(SPIN * offset), SPEED * np.sin(SPIN * offset), 0.0]
    late = run(0.02, (offset, offset + span), p0=turned)
    written = run(0.02, (0.0, span), p0=turned, params={"c": offset})
    assert late.success and written.success and late.t.size == written.t.size
    bound = newton_bound(late)  # each step's tau is a Newton unknown
    assert np.abs(late.t - offset - written.t).max() <= bound
    assert np.abs(late.q - written.q).max() <= bound
    assert np.abs(late.p - written.p).max() <= bound


def test_a_change_of_units_gives_the_same_motion():
    """Lengths in units 2 times smaller (R = 2), times 3 times smaller: ``grav -> 2 / 9``,
    ``w -> w / 3``, ``p -> (2 / 3) p``, ``tau0 -> 3 tau0``."""
    a, b, span = 2.0, 3.0, 2.0
    base = run(0.02, (0.0, span))
    scaled = run(b * 0.02, (0.0, b * span), q0=[0.0, 0.0, -a], p0=[a / b * SPEED, 0.0, 0.0],
                 params={"R": a, "grav": a / b ** 2, "w": SPIN / b})
    assert base.success and scaled.success and base.t.size == scaled.t.size
    bound = newton_bound(base)
    assert np.abs(scaled.t / b - base.t).max() <= bound
    assert np.abs(scaled.q / a - base.q).max() <= bound
    assert np.abs(scaled.p * b / a - base.p).max() <= bound
    assert scaled.verdict.name == base.verdict.name == "accurate"


def test_a_continued_march_carries_the_last_multipliers_into_the_work():
    """The first row after a resume reads mu_{k-1} of the carried multipliers in W_k."""
    whole = run(0.02, (0.0, 2.0))
    part = run(0.02, (0.0, 1.0))
    state = MarchState.of(part.t, part.q, part.p, part.t_end, part.march.carried)
    go_on = continue_march(HOOP, state, 2.0, tau0=0.02, scheme="vddvp", compilation=VM)
    assert go_on.success and go_on.t.size == whole.t.size
    bound = newton_bound(whole)
    assert np.abs(go_on.t - whole.t).max() <= bound
    assert np.abs(go_on.q - whole.q).max() <= bound and np.abs(go_on.p - whole.p).max() <= bound
    assert np.abs(go_on.energy_residual).max() <= 1e-13


def test_a_backward_march_on_the_turning_hoop():
    """From t = 2 back to 0 (the time-reversed system carries g(q, -s)): a success judged
    accurate, its error against the angle equation what the verdict says."""
    q, p = exact(np.array([2.0]))
    back = march(HOOP, q[0], p[0], (2.0, 0.0), tau0=0.01, scheme="vddvp", compilation=VM)
    assert back.success and back.verdict.name == "accurate"
    qe, pe = exact(back.t)
    truth = (np.abs(np.hstack([back.q - qe, back.p - pe])) / np.asarray(back.verdict.scale)).max()
    assert back.verdict.error_max == pytest.approx(truth, rel=1e-2)
    assert back.constraints.constraint_residual.max() <= 1e-14


def test_lee_marches_the_same_steps_as_vddvp_on_the_hoop():
    """For an autonomous H the two rules differ only in the clock of H's explicit time, which
    this H does not have: the vddvp row, with the constraint's work, is lee's derivative of
    the augmented action in t_k."""
    vddvp, lee = (plain_run(0.02, (0.0, 3.0), scheme=scheme) for scheme in ("vddvp", "lee"))
    assert vddvp.success and lee.success and vddvp.t.size == lee.t.size
    assert np.abs(vddvp.t - lee.t).max() <= 1e-10


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=22, max_size=22),
       st.floats(0.001, 0.1), st.floats(0.5, 2.0), st.floats(-2.0, 2.0))
def test_the_vddvp_row_is_the_derivative_of_the_augmented_action_in_t_k(values, tau, ratio,
                                                                         spin):
    """At any nodes and multipliers (not only solutions), the vddvp row of an autonomous H on
    a moving constraint equals lee's (CasADi's gradient of the interval actions in t_k plus
    Lambda_k . g_t), to round-off."""
    from ddvp_nlp.discrete.constrained import energy_expression
    from ddvp_nlp.discrete.scheme import Scheme

    z = np.asarray(values)
    t1 = z[0]
    times = (t1 - tau * ratio, t1, t1 + tau)
    nodes = (*times, z[1:4], z[4:7], z[7:10], z[10:13], z[13:16], z[16:19])
    multipliers = (z[19:21], z[21:22].repeat(2), z[19:21][::-1], z[20:22])
    theta = [1.0, 1.0, spin, 0.0]
    rows = [float(energy_expression(HOOP, Scheme.coerce(rule), rule, nodes, multipliers,
                                    theta)) for rule in ("vddvp", "lee")]
    assert rows[0] == pytest.approx(rows[1], abs=1e-13)


def test_a_libration_stops_where_c_changes_sign():
    """Released at 0.5 rad, at rest on the hoop (spin 0.7 < 1: it swings about the bottom), the
    coefficient c of the energy row's tau^2 term is negative at the release and changes sign
    a quarter swing later; the energy steps stop there with a status, as on a fixed hoop
    (measured: the last node at t = 0.2547, c = 0 at t = 0.265)."""
    from ddvp_nlp.discrete.constrained import solvability_function

    q0, p0 = [np.sin(0.5), 0.0, -np.cos(0.5)], [0.0, SPIN * np.sin(0.5), 0.0]
    stopped = run(0.01, (0.0, 5.0), q0=q0, p0=p0)
    assert stopped.status in (Status.NO_ADMISSIBLE_STEP, Status.RESIDUAL_TOO_LARGE)
    assert stopped.message and stopped.t.size > 2
    fixed = run(0.005, (0.0, 1.0), q0=q0, p0=p0, scheme="fixed")
    c = solvability_function(HOOP).map(fixed.t.size)(
        np.hstack([fixed.q, fixed.p]).T, fixed.t, HOOP.parameter_vector())
    c = np.asarray(c).ravel()
    assert c[0] < 0
    crossing = fixed.t[np.argmax(c > 0)]
    assert 0 < crossing - stopped.t[-1] < 4 * np.diff(stopped.t).max()
