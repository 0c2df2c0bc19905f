"""The march's step problem differentiated (``StepProblem.solve_transposed``,
``StepProblem.sensitivity``): the transposed solve solves ``J^T y = b``, and the step's
sensitivity is the derivative of the step's root in ``theta``, on drawn systems, points and
schemes (the root solved by the careful path's own rootfinders)."""

from functools import cache

import casadi as ca
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import HamiltonianSystem
from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.solvers.marching import StepProblem
from ddvp_nlp.solvers.marching.step_newton import rootfinders
from ddvp_nlp.solvers.marching.steps import step_functions

EPS = np.finfo(float).eps
# Newton's absolute tolerance on the careful path (step_newton.NEWTON_OPTIONS)
NEWTON_TOL = 1e-14

draws = settings(max_examples=6, deadline=None, derandomize=True)
cases = st.fixed_dictionaries({
    "k": st.floats(0.5, 2.0), "c": st.floats(-0.5, 0.5), "n": st.integers(1, 2),
    "rule": st.sampled_from(["vddvp", "lee", "fixed"]), "energy": st.booleans(),
    "seed": st.integers(0, 2 ** 16)})


@cache
def _system(n: int) -> HamiltonianSystem:
    """``n`` degrees of freedom; ``H`` depends on both parameters ``k`` and ``c`` (one system per
    ``n``, so that its step functions are built once)."""
    def H(q, p, t, k, c):
        coupling = c * q[0] * q[n - 1] ** 2 if n > 1 else c * q[0] ** 3 / 3
        return ca.sumsqr(p) / 2 + k * ca.sumsqr(q) / 2 + coupling + ca.cos(q[0]) * k * c
    return HamiltonianSystem(H, n, {"k": 1.0, "c": 0.0}, name=f"drawn_step_{n}")


class Step:
    """A drawn step: its problem at ``theta``, old times and nodes consistent with a march (an
    energy step's ``z_k`` is the fixed step's root from ``z_{k-1}``), and its root."""

    def __init__(self, case):
        self.system, self.scheme = _system(case["n"]), Scheme(case["rule"])
        self.kind = "energy" if case["energy"] and self.scheme.variable_steps else "fixed"
        self.theta = np.array([case["k"], case["c"]])
        rng = np.random.default_rng(case["seed"])
        tau = 0.05 + 0.1 * rng.random()
        self.times = [0.3, 0.3 + tau]
        z = rng.normal(size=2 * self.system.n)
        self.old = (z if self.kind == "fixed" else
                    np.stack([z, self._root(self.theta, "fixed", z)]))

    def problem(self, theta) -> StepProblem:
        return StepProblem(self.system, self.scheme, theta, self.kind)

    def _root(self, theta, kind, old) -> np.ndarray:
        functions = step_functions(self.system, self.scheme)
        fixed, energy = rootfinders(self.system, self.scheme, functions)
        w = StepProblem(self.system, self.scheme, theta, kind).parameters(self.times, old)
        if kind == "fixed":
            return np.asarray(fixed(functions.fixed_predict(w), w), float).ravel()
        guess = functions.energy_predict(w, self.times[1] - self.times[0])
        return np.asarray(energy(guess, w), float).ravel()

    def root(self, theta) -> np.ndarray:
        """The step's root at ``theta`` (the old nodes held)."""
        return self._root(theta, self.kind, self.old)


@draws
@given(cases)
def test_step_transposed_solve_solves_the_transposed_system(case):
    """``|J^T y - b| <= 10 m^2 eps |J| |y|`` (LU's backward error), and ``y`` is not the plain
    solve's answer when ``J`` is not symmetric."""
    step = Step(case)
    problem = step.problem(step.theta)
    w = problem.parameters(step.times, step.old)
    x = step.root(step.theta)
    J = problem.jacobians(x, w)[0]
    b = np.random.default_rng(case["seed"] + 1).normal(size=x.size)
    y = problem.solve_transposed(x, w, b)
    bound = 10 * x.size ** 2 * EPS * np.max(np.abs(J)) * np.max(np.abs(y))
    assert np.max(np.abs(J.T @ y - b)) <= bound
    plain = problem.solve(x, w, b)
    assert np.max(np.abs(J @ plain - b)) <= 10 * x.size ** 2 * EPS * np.max(np.abs(J)) * \
        np.max(np.abs(plain))
    if not np.allclose(J, J.T):
        assert np.max(np.abs(J @ y - b)) > bound


@draws
@given(cases)
def test_step_sensitivity_is_the_derivative_of_the_root_in_theta(case):
    """``dx/dtheta = -(dF/dx)^-1 dF/dtheta`` against a central difference of the root solved
    again at ``theta +- h``, ``h = eps^(1/3) max(1, |theta_j|)``: truncation and round-off of
    the residual ``100 eps^(2/3)`` times the scale, plus the roots' own error (Newton's
    ``1e-14`` times the condition of ``dF/dx``) divided by ``h``."""
    step = Step(case)
    problem = step.problem(step.theta)
    w = problem.parameters(step.times, step.old)
    x = step.root(step.theta)
    assert np.max(np.abs(problem.residual(x, w))) <= 1e-12 * max(1.0, np.max(np.abs(x)))
    in_old, in_theta = problem.sensitivity(x, w)
    assert in_old.shape == (x.size, np.size(step.old)) and in_theta.shape == (x.size, 2)
    condition = np.linalg.cond(problem.jacobians(x, w)[0])
    for j in range(2):
        h = EPS ** (1 / 3) * max(1.0, abs(step.theta[j]))
        up, down = step.theta.copy(), step.theta.copy()
        up[j] += h
        down[j] -= h
        quotient = (step.root(up) - step.root(down)) / (2 * h)
        scale = max(1.0, np.max(np.abs(x)), np.max(np.abs(in_theta[:, j])))
        bound = 100 * EPS ** (2 / 3) * scale + condition * NEWTON_TOL * scale / h
        assert np.max(np.abs(in_theta[:, j] - quotient)) <= bound
    assert np.any(in_theta != 0.0)
