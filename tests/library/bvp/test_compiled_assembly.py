"""The fixed-endpoint assembly compiled (``Compilation(compiler="auto")``, gcc through
``compiler.py``) and on CasADi's virtual machine (``compiler=None``, the fallback): the same
residuals, Jacobian and nodes, one compiled library for every node count, the fallback when the
compiler fails, and the band store reused across evaluations and in-place factorisations. The
compiled banded LU (``grid/band.py``) against LAPACK's through scipy: the same pivots, and
factors and solutions within the rounding the two orders of operations allow (OpenBLAS's
kernels round differently on different CPUs: bit equality is not a property of the path)."""

import warnings

import numpy as np
import pytest
from scipy.linalg import lapack

from ddvp_nlp import Compilation, GridOptions, StepControl, load_scene, march, solve_bvp
from ddvp_nlp.cache import PROBLEMS
from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.solvers import compiler
from ddvp_nlp.solvers.bvp.interleaved import Ends, GridAssembly
from ddvp_nlp.solvers.grid import band
from ddvp_nlp.solvers.grid.maps import WINDOW, evaluate_blocks, window_map

EPS = np.finfo(float).eps
COMPILED = Compilation()
NOTHING_COMPILED = Compilation(compiler=None, band_lu="lapack")

needs_compiler = pytest.mark.skipif(compiler.find_compiler("auto") is None,
                                    reason="no C compiler on this machine")


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A fresh compiled-code cache: for the tests of what a cache holds or builds, and of a
    compiler that fails."""
    monkeypatch.setenv("DDVP_NLP_CACHE", str(tmp_path))
    return tmp_path


@pytest.fixture(scope="module")
def module_cache(tmp_path_factory):
    """One compiled-code cache, fresh for this module, for the tests that compare the compiled
    path with the virtual machine or LAPACK: each system and rule compiles once here, not once
    a test (a library's hash names its code, compiler and flags: what is loaded is what a fresh
    cache would build)."""
    return tmp_path_factory.mktemp("compiled")


@pytest.fixture
def shared_cache(module_cache, monkeypatch):
    monkeypatch.setenv("DDVP_NLP_CACHE", str(module_cache))
    return module_cache


def _point(system, rule, nodes, seed=1):
    """A grid near a motion (increasing times, random states) and its data."""
    n = system.n
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 2.0, nodes) + 1e-3 * rng.random(nodes) / nodes
    q, p = rng.random((nodes, n)), rng.random((nodes, n))
    theta = np.asarray(system.parameter_vector({}), float)
    times = np.array([t[0], t[-1]]) if rule != "fixed" else t + 1e-4
    return t, q, p, Ends(q[0] + 0.1, q[-1] - 0.1, times, theta, 2.0 / (nodes - 1))


def _both(system, rule, nodes, x, ends):
    """``(F, band)`` of each path, compiled first."""
    out = []
    for setting in ("auto", None):
        grid = GridAssembly(system, Scheme(rule), nodes, Compilation(compiler=setting))
        assert grid.path == ("compiled" if setting else "vm")
        F, blocks = grid.evaluate(x, ends)
        out.append((F, grid.banded(blocks).copy(), grid.evaluate(x, ends, False)[0]))
    return out


@needs_compiler
@pytest.mark.parametrize("name", ["pendulum", "kepler"])
@pytest.mark.parametrize("rule", ["vddvp", "fixed"])
@pytest.mark.parametrize("nodes", [5, 300, WINDOW + 9])
def test_compiled_and_vm_assemble_the_same_system(shared_cache, name, rule, nodes):
    """Grids shorter than a window (padded), and longer (a shifted last window): the residual,
    with and without the Jacobian, and every band entry agree to round-off."""
    system = load_scene(name).system
    t, q, p, ends = _point(system, rule, nodes)
    x = GridAssembly(system, Scheme(rule), nodes).layout.pack(t, q, p)
    (F_c, band_c, R_c), (F_v, band_v, R_v) = _both(system, rule, nodes, x, ends)
    assert np.all(np.isfinite(F_c)) and np.all(np.isfinite(band_c))
    assert np.max(np.abs(F_c - F_v)) <= 1e-13
    assert np.array_equal(F_c, R_c) and np.array_equal(F_v, R_v)
    w = (band_c.shape[0] - 1) // 3
    assert np.max(np.abs(band_c[w:] - band_v[w:])) <= 1e-12 * max(1.0, np.max(np.abs(band_v)))


def test_the_band_store_is_rewritten_whole_after_an_in_place_factorisation(shared_cache):
    """The store is reused: after ``gbtrf`` overwrote it, the next evaluation restores every
    entry of the band (LAPACK's fill-in rows aside, which it clears itself), so the second
    factorisation solves exactly as a fresh one."""
    system = load_scene("kepler").system
    nodes = 40
    t, q, p, ends = _point(system, "vddvp", nodes)
    grid = GridAssembly(system, Scheme("vddvp"), nodes)
    x = grid.layout.pack(t, q, p)
    w = grid.layout.bandwidth
    F, blocks = grid.evaluate(x, ends)
    fresh = np.asfortranarray(grid.banded(blocks).copy())
    lapack.dgbtrf(grid.banded(blocks), w, w, overwrite_ab=1)
    assert not np.array_equal(grid.banded(blocks)[w:], fresh[w:])  # the LU is in the store
    F_again, blocks = grid.evaluate(x, ends)
    assert np.array_equal(F_again, F)
    assert np.array_equal(grid.banded(blocks)[w:], fresh[w:])
    lu, pivots, info = lapack.dgbtrf(grid.banded(blocks), w, w, overwrite_ab=1)
    fresh[:w] = 0.0
    lu_fresh, pivots_fresh, _ = lapack.dgbtrf(fresh, w, w)
    assert info == 0
    assert np.array_equal(lapack.dgbtrs(lu, w, w, F, pivots)[0],
                          lapack.dgbtrs(lu_fresh, w, w, F, pivots_fresh)[0])


@needs_compiler
def test_one_compile_serves_every_node_count(cache):
    """The window is WINDOW blocks whatever N: a second grid size compiles nothing, and a new
    process would load the libraries from the cache folder."""
    system = load_scene("pendulum").system
    GridAssembly(system, Scheme("vddvp"), 50)
    built = compiler.build_count()
    libraries = sorted(p.name for p in cache.glob("bvp_*.so"))
    assert libraries  # residual-and-band rows, residual rows, action
    for nodes in (7, 1000, 3 * WINDOW + 1):
        GridAssembly(load_scene("pendulum").system, Scheme("vddvp"), nodes)
    assert compiler.build_count() == built
    assert sorted(p.name for p in cache.glob("bvp_*.so")) == libraries


def test_a_failing_compiler_falls_back_to_the_virtual_machine(cache, monkeypatch):
    """A compiler that exits with an error: one warning, the virtual machine, the same nodes."""
    system = load_scene("pendulum").system
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        grid = GridAssembly(system, Scheme("vddvp"), 30, Compilation(compiler="false"))
    assert grid.path == "vm"
    assert any("running on CasADi's virtual machine instead" in str(w.message) for w in caught)
    t, q, p, ends = _point(system, "vddvp", 30)
    F, blocks = grid.evaluate(grid.layout.pack(t, q, p), ends)
    assert np.all(np.isfinite(F)) and np.all(np.isfinite(grid.banded(blocks)))


def _solve(name, compilation, nodes, nudge=0.0):
    """The default-start Newton solve of a pendulum swing or of kepler e = 0.5 over one period
    (endpoints from a fixed-step march), with the assembly and the band LU of
    ``compilation``; ``nudge``: ``q_end`` moved by that many units of its round-off."""
    if name == "pendulum":
        system = load_scene("pendulum").system
        reference = march(system, [0.5], [0.5], (0.0, 9.0), tau0=0.01, scheme="fixed")
        q_end = reference.q[-1] + nudge * EPS * np.maximum(1.0, np.abs(reference.q[-1]))
        return solve_bvp(system, [0.5], q_end, (0.0, 9.0), nodes=nodes,
                         options=GridOptions(solver="newton"), compilation=compilation)
    system = load_scene("kepler").system
    e, T = 0.5, 2 * np.pi
    q0, p0 = [1 - e, 0.0], [0.0, np.sqrt((1 + e) / (1 - e))]
    reference = march(system, q0, p0, (0.0, T), tau0=T / (nodes - 1), scheme="fixed",
                      params={"e": e}, steps=StepControl(max_steps=nodes))
    q_end = reference.q[-1] + nudge * EPS * np.maximum(1.0, np.abs(reference.q[-1]))
    return solve_bvp(system, q0, q_end, (0.0, T), nodes=nodes, params={"e": e},
                     guess=reference, options=GridOptions(solver="newton"),
                     compilation=compilation)


def _largest_difference(a, b) -> float:
    return max(float(np.max(np.abs(getattr(a, key) - getattr(b, key)))) for key in "tqp")


@pytest.mark.slow(why="repetition")
@needs_compiler
@pytest.mark.parametrize("name, nodes, most", [("pendulum", 2000, 10), ("kepler", 1500, 8)])
def test_compiled_and_vm_newton_return_the_same_nodes(cache, name, nodes, most):
    """Compiled (blocks and band LU) and not (CasADi's VM, LAPACK through scipy): both verify,
    take a bounded number of iterations in every phase (the same, give or take one where the
    last one lands near the round-off target), and return the same nodes within four times
    the problem's own sensitivity to round-off: how far the nodes move when ``q_end`` moves by
    four ulps (the two paths evaluate the same rows with a few ulps of different rounding;
    the problem's condition, ``~N^2``, carries that to the nodes: 8e-12 at N = 1500 on kepler,
    where a 4-ulp nudge of ``q_end`` moves them 1e-11; measured)."""
    compiled = _solve(name, COMPILED, nodes)
    vm = _solve(name, NOTHING_COMPILED, nodes)
    for solution in (compiled, vm):
        assert solution.success, solution.message
    counts = [[ph.iterations for ph in s.ends.stages] for s in (compiled, vm)]
    assert len(counts[0]) == len(counts[1])
    assert all(abs(a - b) <= 1 for a, b in zip(*counts, strict=True))
    assert sum(counts[0]) <= most
    sensitivity = _largest_difference(compiled, _solve(name, COMPILED, nodes, nudge=4))
    assert 0 < sensitivity < 1e-9
    assert _largest_difference(compiled, vm) <= 4 * sensitivity


def _random_band(size, w, seed):
    """A random matrix of bandwidth ``w`` in ``gbtrf`` storage, with pivoting needed (the
    diagonal is not dominant) and garbage in the fill-in rows (both LU must clear them: the
    assembly's store holds the previous factors there)."""
    return np.asfortranarray(np.random.default_rng(seed).standard_normal((3 * w + 1, size)))


def _dense(ab: np.ndarray, w: int) -> np.ndarray:
    """The matrix of a ``gbtrf`` store (its band rows ``w .. 3w``)."""
    size = ab.shape[1]
    A = np.zeros((size, size))
    for j in range(size):
        for i in range(max(0, j - w), min(size, j + w + 1)):
            A[i, j] = ab[2 * w + i - j, j]
    return A


@needs_compiler
@pytest.mark.parametrize("w", [4, 7, 31])
def test_the_compiled_band_lu_is_lapacks(shared_cache, w):
    """Bandwidths of n = 1, 2 and 10: the same pivots as LAPACK's ``dgbtrf``/``dgbtrs``
    through scipy; factors and solutions that differ by no more than the two orders of
    operations can round apart (the loops are LAPACK's reference ones; OpenBLAS's kernels use
    FMA and vector updates on some CPUs): the factors by a few ulps of the largest product
    ``|L||U|`` entering each entry, the solutions by the matrix's condition number times that
    backward error."""
    kernel = band.kernel()
    assert kernel is not None
    size = 400
    ab = _random_band(size, w, seed=w)
    A = _dense(ab, w)
    rhs = np.random.default_rng(0).standard_normal(size)
    lu_lapack, pivots_lapack, info_lapack = lapack.dgbtrf(ab.copy(order="F"), w, w)
    lu = ab.copy(order="F")
    pivots, info = kernel.factor(lu, w, w)
    assert info == info_lapack == 0
    assert np.array_equal(pivots, pivots_lapack)
    assert np.any(pivots != np.arange(size))  # rows were exchanged
    solution = kernel.solve(lu, w, w, pivots, rhs.copy())
    expected = lapack.dgbtrs(lu_lapack, w, w, rhs, pivots_lapack)[0]
    # backward error of each: the computed solution solves a matrix within (3w + 1) eps |L||U|
    growth = float(np.max(np.abs(lu_lapack)))
    entry_bound = 4 * (3 * w + 1) * EPS * growth ** 2
    assert np.max(np.abs(lu[w:] - lu_lapack[w:])) <= entry_bound
    for x in (solution, expected):
        assert np.max(np.abs(A @ x - rhs)) <= entry_bound * size * np.max(np.abs(x))
    condition = np.linalg.cond(A, 1)
    assert np.max(np.abs(solution - expected)) <= 2 * condition * entry_bound * size \
        * np.max(np.abs(expected)) / max(1.0, np.max(np.abs(A)))


@needs_compiler
def test_the_compiled_band_lu_reports_a_singular_matrix_as_lapack_does(shared_cache):
    ab = _random_band(50, 4, seed=3)
    ab[:, 20] = 0.0  # a zero column
    _, _, info_lapack = lapack.dgbtrf(ab.copy(order="F"), 4, 4)
    _, info = band.kernel().factor(ab.copy(order="F"), 4, 4)
    assert info == info_lapack > 0


def test_without_a_compiler_the_band_lu_is_lapack(cache):
    """No compiler: no kernel; a compiler that fails: one warning, no kernel; Newton solves
    either way."""
    assert band.kernel(None) is None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert band.kernel("false") is None
    assert any("LAPACK through scipy instead" in str(w.message) for w in caught)
    # the swing of the solve below (its ends given: no march to compile in the fresh cache)
    solution = solve_bvp(load_scene("pendulum").system, [0.5], [-0.036], (0.0, 9.0), nodes=300,
                         options=GridOptions(solver="newton"), compilation=NOTHING_COMPILED)
    assert solution.success, solution.message


@pytest.mark.parametrize("setting", ["auto", None])
def test_evaluate_blocks_gives_what_a_map_over_the_grid_gives(shared_cache, setting):
    """The helper offered to the starts (``site_weights``): the same values as the function
    mapped over the whole grid, compiled or not, for a grid longer than a window."""
    from ddvp_nlp.physics.hamiltonian import site_density_weight_function

    compilation = Compilation(compiler=setting)
    system = load_scene("kepler").system
    function = site_density_weight_function(system)
    count = WINDOW + 13
    rng = np.random.default_rng(5)
    q, p, t = rng.random((count, 2)) + 0.5, rng.random((count, 2)), rng.random((count, 1))
    theta = np.asarray(system.parameter_vector({}), float)
    expected = np.asarray(function.map(count)(q.T, p.T, t.T, theta[:, None])).ravel()
    (got,) = evaluate_blocks(system, ("site_weights",), function, [q, p, t], theta, compilation)
    assert got.shape == (count, 1)
    path = window_map(system, ("site_weights",), function, compilation).path
    assert path == ("vm" if setting is None or compiler.find_compiler("auto") is None
                    else "compiled")
    assert np.max(np.abs(got.ravel() - expected)) <= 1e-12 * np.max(np.abs(expected))


def test_a_solve_leaves_no_band_store_in_the_cached_assemblies(shared_cache):
    """The assemblies stay cached per system for the next solve; their band stores (the size
    of the band, 312 MB at N = 1e6) are dropped when Newton ends."""
    system = load_scene("pendulum").system
    PROBLEMS.clear()
    solution = solve_bvp(system, [0.5], [-0.036], (0.0, 9.0), nodes=400,
                         options=GridOptions(solver="newton"))
    assert solution.success
    grids = [PROBLEMS.get(system, key, lambda: None) for key in PROBLEMS.keys(system)
             if key[0] == "bvp_assembly"]
    assert len(grids) == 2  # fixed (the start) and vddvp
    assert all(grid._flat is None for grid in grids)
