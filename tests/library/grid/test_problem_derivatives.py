"""Derivatives of a grid problem: ``dF/dtheta`` against a finite difference of ``F`` in
``theta``, and the transposed solve beside the solve (``J^T y = b``), on random points."""

import casadi as ca
import numpy as np
import pytest
import scipy.sparse as sp
from helpers.random_cases import random_pair

from ddvp_nlp import Compilation
from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.solvers.bvp.interleaved import Ends, GridAssembly
from ddvp_nlp.solvers.grid.linear import Factorization
from ddvp_nlp.solvers.periodic.closed_grid import Closure, PeriodicAssembly

EPS = np.finfo(float).eps


def _system(rng):
    return random_pair(rng, "random_pair")


def _periodic(seed: int):
    rng = np.random.default_rng(seed)
    system = _system(rng)
    intervals = int(rng.integers(4, 20))
    assembly = PeriodicAssembly(system, Scheme("vddvp"), intervals)
    x = rng.normal(size=assembly.layout.size)
    x[assembly.layout.time_index()] = np.sort(rng.random(intervals + 1)) + np.arange(
        intervals + 1)
    theta = np.asarray(system.parameter_vector({}), float) + rng.random(2)
    return assembly, x, Closure(-0.4, 2, 0.0, theta, shift=0.0)


def _bvp(seed: int, compiler, rule="vddvp"):
    rng = np.random.default_rng(seed)
    system = _system(rng)
    nodes = int(rng.integers(5, 30))
    grid = GridAssembly(system, Scheme(rule), nodes, Compilation(compiler=compiler))
    t = np.sort(rng.random(nodes)) + np.arange(nodes)
    q, p = rng.normal(size=(nodes, system.n)), rng.normal(size=(nodes, system.n))
    theta = np.asarray(system.parameter_vector({}), float) + rng.random(2)
    times = t[[0, -1]] if rule != "fixed" else t + 1e-3
    return grid, grid.layout.pack(t, q, p), Ends(q[0] + 0.1, q[-1], times, theta, 0.7)


def _agrees_with_difference_quotient(assembly, x, data, with_theta, theta=None):
    """Central difference with step ``h``: truncation ``O(h^2 |F^(3)|)`` plus round-off
    ``eps |F| / h``; ``h = eps^(1/3) max(1, |theta|)`` balances them, so the agreement is
    ``~ eps^(2/3)`` times the residual's scale (factor 100 for the third derivative)."""
    derivative = assembly.parameter_jacobian(x, data)
    assert sp.issparse(derivative)
    derivative = derivative.toarray()
    theta = data.theta if theta is None else theta
    assert derivative.shape == (assembly.layout.size, theta.size)
    for j in range(theta.size):
        h = EPS ** (1 / 3) * max(1.0, abs(theta[j]))
        up, down = theta.copy(), theta.copy()
        up[j] += h
        down[j] -= h
        F_up = assembly.evaluate(x, with_theta(up), jacobian=False)[0]
        F_down = assembly.evaluate(x, with_theta(down), jacobian=False)[0]
        quotient = (F_up - F_down) / (2 * h)
        scale = max(1.0, np.max(np.abs(F_up)), np.max(np.abs(derivative[:, j])))
        assert np.max(np.abs(derivative[:, j] - quotient)) <= 100 * EPS ** (2 / 3) * scale
    assert np.any(derivative != 0.0)
    return derivative


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("rule", ["vddvp", "fixed", "lee"])
def test_fixed_ends_parameter_jacobian_is_the_difference_quotient_of_the_residual(seed, rule):
    grid, x, ends = _bvp(seed, None, rule)
    _agrees_with_difference_quotient(grid, x, ends, lambda theta: Ends(
        ends.q_start, ends.q_end, ends.times, theta, ends.energy_scale))


@pytest.mark.parametrize("seed", range(4))
def test_periodic_parameter_jacobian_is_the_difference_quotient_of_the_residual(seed):
    assembly, x, closure = _periodic(seed)
    _agrees_with_difference_quotient(assembly, x, closure,
                                     lambda theta: Closure(-0.4, 2, 0.0, theta))


@pytest.mark.parametrize("seed", range(4))
def test_arclength_parameter_jacobian_is_the_difference_quotient_of_the_residual(seed):
    """The family's system ``F(x; E) = 0`` with ``E`` an unknown and the arclength row, which
    does not depend on ``theta`` (its row of ``dF/dtheta`` is zero)."""
    from dataclasses import replace

    from ddvp_nlp.solvers.periodic.arclength import ArclengthSystem, _Arc
    assembly, x, closure = _periodic(seed)
    rng = np.random.default_rng(seed + 100)
    system = ArclengthSystem(assembly)
    y = np.r_[x, closure.energy + rng.normal()]
    row, origin = rng.normal(size=y.size), y + 0.1 * rng.normal(size=y.size)
    arc = _Arc(closure, row, origin, 0.3)
    derivative = _agrees_with_difference_quotient(
        system, y, arc, lambda theta: _Arc(replace(closure, theta=theta), row, origin, 0.3),
        theta=closure.theta)
    assert np.all(derivative[-1] == 0.0)
    base = assembly.parameter_jacobian(x, replace(closure, energy=float(y[-1]))).toarray()
    assert np.array_equal(derivative[:-1], base)


def _check_transposed(assembly, x, data, linear, kernel=None):
    """``J^T y = b`` to the backward-error bound of LU: ``|J^T y - b| <= c n eps |J| |y|``."""
    rng = np.random.default_rng(0)
    F, jacobian = assembly.evaluate(x, data)
    matrix = assembly.sparse(jacobian).toarray()
    factors = Factorization(assembly, jacobian, linear, kernel)
    assert not factors.singular
    b = rng.normal(size=F.size)
    y = factors.solve_transposed(b.copy())
    bound = 10 * F.size * EPS * np.max(np.abs(matrix)) * np.max(np.abs(y)) * F.size
    assert np.max(np.abs(matrix.T @ y - b)) <= bound
    assert np.max(np.abs(matrix @ y - b)) > bound  # not the plain solve: J is not symmetric


@pytest.mark.parametrize("seed", range(3))
def test_transposed_solve_sparse(seed):
    assembly, x, closure = _periodic(seed)
    _check_transposed(assembly, x, closure, "sparse")


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("compiled", [False, True])
def test_transposed_solve_banded(seed, compiled):
    from ddvp_nlp.solvers.grid.linear import band_kernel
    grid, x, ends = _bvp(seed, "auto" if compiled else None)
    kernel = band_kernel(Compilation()) if compiled else None
    _check_transposed(grid, x, ends, "banded", kernel)
    _check_transposed(grid, x, ends, "sparse")


@pytest.mark.parametrize("seed", range(3))
def test_higher_parameter_jacobian_is_the_difference_quotient_of_the_residual(seed):
    from ddvp_nlp import HigherOrderSystem
    from ddvp_nlp.solvers.higher.windows import HigherAssembly, HigherEnds
    rng = np.random.default_rng(seed)
    system = HigherOrderSystem(lambda q, v, t, lam, mu: v[1][0] ** 2 / 2 - lam * ca.exp(q[0])
                               + mu * v[0][0] ** 2 * q[0], 1, 2, {"lam": 1.0, "mu": 0.5},
                               name="random_higher")
    nodes = int(rng.integers(9, 30))
    assembly = HigherAssembly(system, "vddvp", nodes, 0.1)
    x = rng.normal(size=assembly.layout.size)
    x[assembly.layout.time_index()] = np.sort(rng.random(nodes)) + np.arange(nodes)
    theta = np.array([1.0, 0.5]) + rng.random(2)
    given = x + rng.normal(size=x.size)
    _agrees_with_difference_quotient(assembly, x, HigherEnds(given, theta),
                                     lambda value: HigherEnds(given, value))
    _check_transposed(assembly, x, HigherEnds(given, theta), "banded")
    _check_transposed(assembly, x, HigherEnds(given, theta), "sparse")


@pytest.mark.parametrize("seed", range(3))
def test_transfer_parameter_jacobian_is_the_difference_quotient_of_the_residual(seed):
    """The transfer at a prescribed energy: the last block's time row is ``H(Q, P) - E``."""
    from ddvp_nlp.solvers.bvp.interleaved import prescribed_energy_block
    rng = np.random.default_rng(seed)
    system = _system(rng)
    nodes = int(rng.integers(5, 30))
    scheme = Scheme("vddvp")
    grid = GridAssembly(system, scheme, nodes, Compilation(compiler=None),
                        last=prescribed_energy_block(system, scheme))
    t = np.sort(rng.random(nodes)) + np.arange(nodes)
    q, p = rng.normal(size=(nodes, system.n)), rng.normal(size=(nodes, system.n))
    theta = np.array([0.5, 0.5]) + rng.random(2)

    def ends(value):
        return Ends(q[0] + 0.1, q[-1], t[[0, -1]], value, 0.7, energy=0.3)
    x = grid.layout.pack(t, q, p)
    _agrees_with_difference_quotient(grid, x, ends(theta), ends)
    _check_transposed(grid, x, ends(theta), "banded")
