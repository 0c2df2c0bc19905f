"""The grid Newton's hooks for Newtons with a globalisation of their own (shooting, the
continuation's corrector): a step test's ``converged``, ``search``, ``singular`` and ``halted``,
the ``factor`` of the linear solve, and ``last_iteration``; on one-unknown problems whose
iterates are known."""

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ddvp_nlp.solvers.grid.newton import FullSteps, NaturalMonotonicity, newton


@dataclass(frozen=True)
class _Layout:
    size: int = 1
    bandwidth: int = 0

    def time_index(self):
        return np.zeros(0, int)


class _Scalar:
    """``F(x) = f(x) - data`` in one unknown, ``J = f'(x)``."""

    layout = _Layout()

    def __init__(self, f, df):
        self.f, self.df = f, df

    def evaluate(self, x, data, jacobian=True):
        with np.errstate(all="ignore"):
            F = np.array([self.f(x[0]) - data])
            return F, (np.array([[self.df(x[0])]]) if jacobian else None)

    def banded(self, jacobian):
        return np.asfortranarray(jacobian, float)

    def sparse(self, jacobian):
        return sp.csc_matrix(jacobian)

    def release(self):
        pass

    def parameter_jacobian(self, x, data):
        return sp.csc_matrix([[-1.0]])


SQUARE = _Scalar(lambda x: x * x, lambda x: 2 * x)
TARGET = np.array([1e-14])


def test_the_default_newton_ends_in_the_iteration_after_its_last_step():
    result = newton(SQUARE, np.array([1.0]), 2.0, TARGET, tau_floor=-np.inf)
    assert result.converged and abs(result.x[0] - math.sqrt(2)) < 1e-14
    assert result.last_iteration == result.iterations + 1


def test_full_steps_are_newtons_own_iterates_and_run_out_as_a_failure():
    x, iterates = 1.0, []
    for _ in range(3):
        x = x - (x * x - 2.0) / (2 * x)
        iterates.append(x)
    result = newton(SQUARE, np.array([1.0]), 2.0, TARGET, tau_floor=-np.inf, max_iter=3,
                    test=FullSteps())
    assert result.x[0] == iterates[-1] and result.step_lengths == [1.0] * 3
    assert not result.converged and result.last_iteration == 3
    assert result.outcome.startswith("max_iter = 3 reached")


def test_a_full_step_to_a_non_finite_residual_ends_the_next_iteration():
    """``log(x) = 1`` from 10: the full step lands at ``10 (2 - log 10) < 0``."""
    logarithm = _Scalar(np.log, lambda x: 1 / x)
    result = newton(logarithm, np.array([10.0]), 1.0, TARGET, tau_floor=-np.inf,
                    test=FullSteps())
    assert result.x[0] < 0 and not result.converged
    assert result.outcome == "non-finite residuals at iteration 2"
    assert (result.iterations, result.last_iteration) == (1, 2)


def test_a_step_test_names_its_singular_solve_and_halts_after_a_step():
    class Halting(NaturalMonotonicity):
        def singular(self, iteration):
            return f"no solve in iteration {iteration}"

        def halted(self, norm, best_norm):
            return f"halted at {norm:.3g} after {best_norm:.3g}"

    class Nothing:
        def solve(self, rhs):
            return np.full_like(rhs, np.nan)

    factored = []

    def factor(jacobian):
        factored.append(jacobian)
        return Nothing()
    result = newton(SQUARE, np.array([1.0]), 2.0, TARGET, tau_floor=-np.inf, test=Halting(),
                    factor=factor)
    assert result.outcome == "no solve in iteration 1" and len(factored) == 1
    assert (result.iterations, result.last_iteration) == (0, 1)
    result = newton(SQUARE, np.array([1.0]), 2.0, TARGET, tau_floor=-np.inf, test=Halting())
    assert result.outcome == "halted at 0.25 after 1" and not result.converged
    assert (result.iterations, result.last_iteration) == (1, 1)


def test_a_step_test_decides_convergence_from_the_iterate():
    class Relative(FullSteps):
        def converged(self, F, x, target):
            return bool(abs(F[0]) <= 1e-3 * abs(x[0]))

    result = newton(SQUARE, np.array([1.0]), 2.0, TARGET, tau_floor=-np.inf, test=Relative())
    assert result.converged and 1e-14 < abs(result.x[0] ** 2 - 2.0) <= 1e-3 * result.x[0]
