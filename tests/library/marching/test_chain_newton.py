"""The compiled march's Newton for many unknowns (solvers/marching/chain_newton.py): its sparse
elimination solves the bordered step system, gives DenseLU's bits in the natural order, fills
only what a chain's band fills; the chain of iterations finds the step's root; a march of a
chain on the compiled path follows the careful path's nodes."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import Compilation, Scene, Scheme, march
from ddvp_nlp.solvers.marching.chain_newton import SparseLU, chain_newton, elimination_cost
from ddvp_nlp.solvers.marching.chunk import unroll_options
from ddvp_nlp.solvers.marching.step_newton import NEWTON_OPTIONS, DenseLU
from ddvp_nlp.solvers.marching.steps import StepFunctions

VDDVP = Scheme.coerce("vddvp")


def alpha_fpu(n: int, *, tau0: float = 0.05, t_end: float = 5.0) -> Scene:
    """n unit masses between fixed walls, springs d^2/2 + alpha d^3/3 (nearest neighbours),
    started in the first normal mode."""
    def hamiltonian(q, p, t, alpha):
        x = ca.vertcat(0, q, 0)
        d = x[1:] - x[:-1]
        return ca.sumsqr(p) / 2 + ca.sum1(d ** 2 / 2 + alpha * d ** 3 / 3)
    i = np.arange(1, n + 1)
    omega = 2 * np.sin(np.pi / (2 * (n + 1)))
    q0 = 2 / (omega * np.sqrt(n + 1)) * np.sin(np.pi * i / (n + 1))
    return Scene(hamiltonian, n=n, params={"alpha": 0.25}, q0=q0, p0=np.zeros(n), tau0=tau0,
                 t_end=t_end, name=f"alpha_fpu_{n}")


def _jacobian(functions: StepFunctions) -> ca.Function:
    return ca.rootfinder("r", "fast_newton", functions.energy_residual,
                         dict(NEWTON_OPTIONS)).get_function("jac_g_x")


def _solve_function(solver) -> ca.Function:
    J, g = ca.SX.sym("J", solver.pattern), ca.SX.sym("g", solver.ncol)
    x = solver.solve(solver.factor([J.nz[k] for k in range(J.nnz())]),
                     [g[i] for i in range(solver.ncol)])
    return ca.Function("solve", [J, g], [ca.vertcat(*x)])


def _step_matrix(pattern, rng) -> np.ndarray:
    """Random values on the step Jacobian's pattern, the canonical block near the identity (as
    a step's is: I + O(tau))."""
    J = np.array(ca.DM(pattern, 0.1 * rng.standard_normal(pattern.nnz())))
    m = pattern.size1() - 1
    J[:m, :m] += np.eye(m)
    return np.array(ca.DM(pattern, _nonzeros(pattern, J)))  # only the pattern's entries


def _nonzeros(pattern, J: np.ndarray) -> np.ndarray:
    rows, cols = pattern.get_triplet()
    return J[np.array(rows), np.array(cols)]


@pytest.mark.parametrize("n", [1, 3, 8])
@pytest.mark.parametrize("ordering", ["auto", "natural", "amd"])
def test_the_elimination_solves_the_bordered_step_system(n, ordering):
    pattern = _jacobian(StepFunctions(alpha_fpu(n).system, VDDVP)).sparsity_out(0)
    solve = _solve_function(SparseLU(pattern, border=1, ordering=ordering))
    rng = np.random.default_rng(n)
    for _ in range(3):
        J = _step_matrix(pattern, rng)
        b = rng.standard_normal(pattern.size1())
        x = np.array(solve(ca.DM(pattern, _nonzeros(pattern, J)), b)).ravel()
        # backward stable to the conditioning of J: the residual relative to |J| |x|
        scale = np.abs(J) @ np.abs(x) + np.abs(b)
        assert np.max(np.abs(J @ x - b) / scale) <= 1e3 * np.finfo(float).eps


def test_the_natural_order_is_dense_lus_to_the_bit():
    """The same operations in the same order: the linear solve of the small systems and of the
    large ones differ only in the order of elimination (a documented property)."""
    pattern = _jacobian(StepFunctions(alpha_fpu(4).system, VDDVP)).sparsity_out(0)
    sparse = _solve_function(SparseLU(pattern, border=1, ordering="natural"))
    dense = _solve_function(DenseLU(pattern))
    rng = np.random.default_rng(7)
    for _ in range(5):
        J = ca.DM(pattern, _nonzeros(pattern, _step_matrix(pattern, rng)))
        b = rng.standard_normal(pattern.size1())
        assert np.array_equal(np.array(sparse(J, b)), np.array(dense(J, b)))


def test_a_chains_elimination_grows_linearly_with_its_length():
    """Operations counted on the structure (fill included): a chain's step Jacobian
    eliminates in O(n) with tau last; the dense elimination grows like n^3."""
    costs = {}
    for n in (8, 16, 32, 64):
        pattern = _jacobian(StepFunctions(alpha_fpu(n).system, VDDVP)).sparsity_out(0)
        costs[n] = elimination_cost(pattern, SparseLU(pattern, border=1).perm)
    assert costs[64] / costs[8] <= 8 * 1.25  # 8 times the masses, about 8 times the work
    assert costs[64] / costs[32] <= 2 * 1.25


@pytest.mark.parametrize("n", [2, 8])
def test_the_chain_finds_the_steps_root(n):
    """From a perturbed root, the chain converges to the step's root to Newton's tolerance
    (the careful rootfinder's root from the same start) and returns the check at it."""
    system = alpha_fpu(n).system
    functions = StepFunctions(system, VDDVP)
    scene = alpha_fpu(n)
    theta = system.parameter_vector(scene.params)
    z0 = np.concatenate([scene.q0, scene.p0])
    step = march(system, scene.q0, scene.p0, (0.0, 0.2), tau0=0.05, accuracy=None,
                 compilation=Compilation(fast=False))
    z = np.column_stack([step.q, step.p])
    w = np.concatenate([[step.t[0], step.t[1]], z[0], z[1], theta, [0.0]])
    x_root = np.concatenate([z[2], [step.t[2] - step.t[1]]])
    newton = chain_newton("fast_energy_step", functions.energy_residual, NEWTON_OPTIONS,
                          border=1)
    start = x_root + 1e-4 * np.random.default_rng(n).standard_normal(x_root.size)
    x = np.array(newton(start, w)).ravel()
    assert np.max(np.abs(x - x_root)) <= 1e-10 * max(1.0, np.max(np.abs(z0)))
    g = np.array(functions.energy_residual(x, w)).ravel()
    assert np.max(np.abs(g)) <= 1e-12


def test_a_long_chain_takes_the_chain_newton():
    assert unroll_options(2 * 6 + 1) != {"chain": True}  # fpu's 13 unknowns: unrolled
    assert unroll_options(2 * 7 + 1) == {"chain": True}


@pytest.mark.slow(why="repetition")
def test_a_chain_marches_on_the_compiled_path_like_the_careful_one():
    """n = 8 (17 unknowns): the compiled chunk with the chain Newton against the careful path,
    node for node to Newton's tolerance propagated over the run."""
    scene = alpha_fpu(8)
    config = scene.resolve({})
    runs = [march(scene.system, config.q0, config.p0, (0.0, config.t_end), tau0=config.tau0,
                  params=config.params, accuracy=None, compilation=Compilation(fast=fast))
            for fast in (True, False)]
    fast, careful = runs
    assert fast.success and careful.success
    assert fast.stats["fast_steps"] >= 0.9 * fast.steps
    assert fast.steps == careful.steps
    scale = np.max(np.abs(np.column_stack([careful.q, careful.p])))
    assert np.max(np.abs(fast.t - careful.t)) <= 1e-9 * config.t_end
    assert np.max(np.abs(fast.q - careful.q)) <= 1e-9 * scale


def test_a_long_chains_compiled_recheck_gives_the_virtual_machines_bits():
    """Past WIDE_PIECE degrees of freedom the recheck maps one interval a call over the block
    (three shifted views of the nodes): the same bits as the separate mapped functions."""
    from ddvp_nlp.discrete import equations
    from ddvp_nlp.solvers.compiler import find_compiler
    from ddvp_nlp.solvers.marching.recheck import WIDE_PIECE, recheck_residuals

    compiler = find_compiler("auto")
    if compiler is None:
        pytest.skip("no C compiler")
    n = WIDE_PIECE + 2
    scene = alpha_fpu(n)
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.05, 0.1, 1300))
    q, p = rng.uniform(-1, 1, (1300, n)), rng.uniform(-1, 1, (1300, n))
    theta = scene.system.parameter_vector(scene.params)
    expected = equations.grid_residuals(scene.system, VDDVP, t, q, p, theta)
    found = recheck_residuals(scene.system, VDDVP, t, q, p, theta, compiler=compiler,
                           cache_dir=None)
    for a, b in zip(found, expected, strict=True):
        assert np.array_equal(a, b)
