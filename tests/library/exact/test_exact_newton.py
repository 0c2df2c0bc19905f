"""The one Newton on the exact flow's residuals (``solvers/exact/flow_newton.py``): it converges
on a known root with a bound of its own error that holds, and says it failed where there
is no root; each caller's bound (shooting, closure, transfer, fit) holds against a root known
in closed form (the fit's: the start its data were drawn from)."""

import casadi as ca
import numpy as np

from ddvp_nlp import HamiltonianSystem, HigherOrderSystem
from ddvp_nlp.solvers.accuracy import positions
from ddvp_nlp.solvers.bvp import at_energy
from ddvp_nlp.solvers.exact import closure, shooting
from ddvp_nlp.solvers.exact.flow import exact_flow
from ddvp_nlp.solvers.exact.flow_newton import exact_newton
from ddvp_nlp.solvers.exact.tolerance import EXACT_TOLERANCE, ExactTolerance


def _problem(shift):
    """``F(x) = (x_0^2 - 2 + shift, x_1 - x_0)``: roots ``x_0 = x_1 = +-sqrt(2 - shift)``."""
    def evaluate(x):
        F = np.array([x[0] ** 2 - 2.0 + shift, x[1] - x[0]])
        J = np.array([[2 * x[0], 0.0], [-1.0, 1.0]])
        return F, J

    def step(_x, F, J):
        return np.linalg.solve(J, -F)

    return evaluate, step


def _size(F):
    return float(np.max(np.abs(F)))


def test_converges_on_a_known_root_with_a_bound_that_holds():
    evaluate, step = _problem(0.0)
    for halvings in (0, 30):
        result = exact_newton(evaluate, step, np.array([3.0, 0.0]), size=_size,
                              tolerance=EXACT_TOLERANCE.newton_tol, max_iterations=30,
                              halvings=halvings)
        assert result.converged and not result.failed_evaluation
        assert 0 < result.iterations < 30
        assert result.residual <= EXACT_TOLERANCE.newton_tol
        error = float(np.max(np.abs(result.x - np.sqrt(2.0))))
        assert error <= result.error_bound


def test_no_root_is_a_failure_status_not_an_exception():
    evaluate, step = _problem(3.0)  # x_0^2 + 1 = 0 has no real root
    for halvings in (0, 30):
        result = exact_newton(evaluate, step, np.array([0.5, 0.0]), size=_size,
                              tolerance=1e-10, max_iterations=20, halvings=halvings)
        assert not result.converged
        assert result.residual >= 1.0


def test_a_failed_evaluation_is_reported():
    result = exact_newton(lambda x: (None, None), lambda *a: None, np.zeros(1), size=_size,
                          tolerance=1e-10, max_iterations=5)
    assert result.failed_evaluation and not result.converged and result.iterations == 0


def test_the_policy_is_one_frozen_object():
    assert EXACT_TOLERANCE == ExactTolerance(flow_rtol=1e-12, reference_rtol=1e-9,
                                             newton_tol=1e-10, newton_tight_tol=1e-11,
                                             newton_accept_tol=1e-9)


# --- every caller's bound, against a root known in closed form --------------------------------
# H = (p^2 + q^2)^2 / 4 turns every circle r^2 = p^2 + q^2 at the rate r^2: from (0, p_0),
# q(t) = p_0 sin(p_0^2 t), nonlinear in p_0 and the time; from (0, 1), (sin t, cos t) with the
# period 2 pi at H = 1/4. The fit's root is the start its data were taken from by the exact
# flow (at a tolerance far below the fit's). Each caller's distance to the root is measured in
# its own scales (its ``step_size``), as its bound is.

def _spy(monkeypatch, module):
    """The results of ``module``'s calls of `exact_newton`, with the scaled size each caller
    measures its steps by."""
    calls = []

    def spy(*args, **kwargs):
        result = exact_newton(*args, **kwargs)
        calls.append((result, kwargs.get("step_size") or _size))
        return result
    monkeypatch.setattr(module, "exact_newton", spy)
    return calls


def _rotation():
    return HamiltonianSystem(lambda q, p, t: (p[0] ** 2 + q[0] ** 2) ** 2 / 4, 1,
                             name="quartic_rotation")


def _holds(calls, root):
    (result, step_size), = calls
    assert result.converged and result.iterations > 1 and np.isfinite(result.error_bound)
    assert step_size(result.x - root) <= result.error_bound


def test_the_bound_holds_for_shooting(monkeypatch):
    calls = _spy(monkeypatch, shooting)
    t = np.linspace(0.0, 1.0, 41)
    z = 1.05 * np.column_stack([np.sin(t), np.cos(t)])  # a discrete solution 5 % off
    shot = shooting.shoot(_rotation(), np.zeros(0), t, z, [np.sin(1.0)], np.ones(2))
    cuts = shot.cuts[1:-1]
    _holds(calls, np.concatenate([[1.0], np.column_stack([np.sin(cuts), np.cos(cuts)]).ravel()]))


def test_the_bound_holds_for_the_closure(monkeypatch):
    calls = _spy(monkeypatch, closure)
    orbit = closure.close_exact(_rotation(), np.zeros(0), [0.0, 1.05], 6.0, energy=0.25,
                                section_index=1, section_value=0.0)
    assert orbit.converged and orbit.error_bound == calls[0][0].error_bound
    phases = 2 * np.pi * orbit.cuts[:-1]  # each segment's start on the circle (sin, cos)
    _holds(calls, np.concatenate([np.column_stack([np.sin(phases), np.cos(phases)]).ravel(),
                                  [2 * np.pi, 0.0]]))


def test_the_bound_holds_for_the_transfer_at_an_energy(monkeypatch):
    calls = _spy(monkeypatch, at_energy)
    t = np.linspace(0.0, 1.03, 21)
    q = np.sin(t / 1.03)[:, None]
    exact = at_energy.shoot_transfer(_rotation(), np.zeros(0), t, q, np.full((21, 1), 1.05),
                                     0.25)
    assert exact["converged"]
    _holds(calls, np.array([1.0, 1.0]))


def test_the_bound_holds_for_the_fit_of_a_higher_order_start(monkeypatch):
    """``q'''' = sin q`` (``L = q''^2 / 2 + cos q``), its data at both ends: least squares."""
    calls = _spy(monkeypatch, positions)
    system = HigherOrderSystem(lambda q, v, t: v[1][0] ** 2 / 2 + ca.cos(q[0]), 1, 2,
                               name="beam_on_a_pendulum")
    root = np.array([0.5, 0.2, -0.3, 0.1])
    t = np.linspace(0.0, 2.0, 21)
    run = exact_flow(system, compiler=None).run(root, 0.0, 2.0, np.zeros(0), rtol=1e-14,
                                                atol=1e-14 * np.ones(4))
    q = run.z(t)[:, :1]
    ends = np.r_[0:4, 17:21]  # two nodes more than the unknowns at each end
    y0, reason = positions.fit_start(system, np.zeros(0), t, ends, q, 2, np.ptp(q, axis=0))
    assert reason == "" and y0 is not None
    _holds(calls, root)
