"""The one Newton on the exact flow's residuals (``solvers/exact/flow_newton.py``): it converges
on a known root with a bound of its own error that holds, and says it failed where there
is no root."""

import numpy as np

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
                                             newton_tol=1e-10)
