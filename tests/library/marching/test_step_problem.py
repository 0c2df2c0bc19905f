"""The march's one-step problem (``StepProblem``): its Jacobians in the new unknowns, the old
nodes and ``theta`` against central differences of its residual, on random systems and points."""

import numpy as np
import pytest
from helpers.random_cases import random_pair

from ddvp_nlp import InputError
from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.solvers.marching import StepProblem

EPS = np.finfo(float).eps


def _system(rng):
    return random_pair(rng, "random_step")


def _difference(function, point, j):
    """Central difference in coordinate ``j``; step ``eps^(1/3) max(1, |point_j|)``."""
    h = EPS ** (1 / 3) * max(1.0, abs(point[j]))
    up, down = point.copy(), point.copy()
    up[j] += h
    down[j] -= h
    return (function(up) - function(down)) / (2 * h)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("kind,rule", [("fixed", "fixed"), ("fixed", "vddvp"),
                                       ("energy", "vddvp"), ("energy", "lee")])
def test_step_jacobians_are_the_difference_quotients_of_the_residual(seed, kind, rule):
    """Agreement ``100 eps^(2/3)`` times the residual's and the derivative's scale (truncation
    ``h^2`` and round-off ``eps / h`` balanced by ``h = eps^(1/3)``)."""
    rng = np.random.default_rng(seed)
    system = _system(rng)
    theta = np.array([0.5, 0.5]) + rng.random(2)
    problem = StepProblem(system, Scheme(rule), theta, kind)
    n = system.n
    if kind == "fixed":
        times, old = [0.3, 0.4], rng.normal(size=2 * n)
        x = old + 0.01 * rng.normal(size=2 * n)
    else:
        times, old = [0.3, 0.4], rng.normal(size=(2, 2 * n))
        x = np.r_[old[1] + 0.01 * rng.normal(size=2 * n), 0.1]
    w = problem.parameters(times, old, drift=0.0)
    in_x, in_old, in_theta = problem.jacobians(x, w)
    assert in_x.shape == (x.size, x.size) and in_theta.shape == (x.size, 2)
    assert in_old.shape == (x.size, np.size(old))
    F = problem.residual(x, w)
    columns = [(in_x, lambda v: problem.residual(v, w), x, range(x.size)),
               (in_old, lambda v: problem.residual(x, v), w, range(2, 2 + np.size(old))),
               (in_theta, lambda v: problem.residual(x, v), w,
                range(2 + np.size(old), 4 + np.size(old)))]
    for derivative, function, point, indices in columns:
        for column, j in enumerate(indices):
            quotient = _difference(function, point, j)
            scale = max(1.0, np.max(np.abs(F)), np.max(np.abs(derivative[:, column])))
            assert np.max(np.abs(derivative[:, column] - quotient)) <= \
                100 * EPS ** (2 / 3) * scale
    assert np.any(in_theta != 0.0)


def test_energy_step_needs_an_energy_rule():
    system = _system(np.random.default_rng(0))
    with pytest.raises(InputError, match="has no energy step"):
        StepProblem(system, Scheme("fixed"), [1.0, 1.0], "energy")
