"""The contract of a grid problem (``solvers/grid/__init__.py``), checked on every implementation
of ``grid.problem.GridProblem`` in the package (found in the source, checked for every method the
protocol class declares), and the grid options reaching every family that takes them."""

import ast
import functools
import importlib
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import ddvp_nlp
from ddvp_nlp import (
    Compilation,
    GridOptions,
    InputError,
    Status,
    load_scene,
    solve_bvp,
    solve_bvp_higher,
    solve_periodic,
)
from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.solvers.bvp.end_continuation import Hyperplane, _Path
from ddvp_nlp.solvers.bvp.first_guess import Aim, ShootingProblem
from ddvp_nlp.solvers.bvp.interleaved import Ends, GridAssembly
from ddvp_nlp.solvers.bvp.phases import Boundary
from ddvp_nlp.solvers.grid.linear import Factorization
from ddvp_nlp.solvers.grid.problem import GridLayout, GridProblem, GridRequest
from ddvp_nlp.solvers.higher.windows import HigherAssembly, HigherEnds
from ddvp_nlp.solvers.periodic.arclength import ArclengthSystem, _Arc
from ddvp_nlp.solvers.periodic.closed_grid import Closure, PeriodicAssembly


def _members(protocol) -> set:
    """The public methods and attributes a protocol class declares (read from the class)."""
    names = {name for name, value in vars(protocol).items()
             if not name.startswith("_") and (callable(value) or isinstance(value, property))}
    return names | set(getattr(protocol, "__annotations__", {}))


PROTOCOL = _members(GridProblem)
LAYOUT = _members(GridLayout)
# The protocol's docstring of `banded`: an assembly whose Jacobian is not banded (its layout's
# bandwidth is its size) need not have it.
BANDED_ONLY = {"banded"}


def _implementations() -> set:
    """``(module, class name)`` of every class of the package with an ``evaluate(self, x, data,
    jacobian)``: the grid problems, whatever they call themselves."""
    found = set()
    root = Path(ddvp_nlp.__file__).parent
    for path in root.rglob("*.py"):
        module = ".".join(("ddvp_nlp", *path.relative_to(root).with_suffix("").parts))
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ClassDef):
                continue
            for item in node.body:
                if isinstance(item, ast.FunctionDef) and item.name == "evaluate" \
                        and "jacobian" in [a.arg for a in item.args.args]:
                    found.add((module, node.name))
    found.discard((GridProblem.__module__, GridProblem.__name__))
    return found


def test_the_protocol_is_read_from_its_class():
    assert PROTOCOL >= {"layout", "evaluate", "sparse", "release", "parameter_jacobian", "banded"}
    assert LAYOUT >= {"size", "bandwidth", "time_index"}


def test_every_grid_problem_of_the_package_is_in_the_contract_sample():
    """A new implementation must join `_assemblies`, so that every check below runs on it."""
    sampled = {(type(problem).__module__, type(problem).__name__)
               for _, problem, _, _ in _assemblies(0)}
    found = _implementations()
    assert len(found) >= 6
    assert found == sampled, found ^ sampled
    for module, name in found:
        assert hasattr(importlib.import_module(module), name), (module, name)


@pytest.mark.parametrize("seed", range(2))
def test_every_grid_problem_has_every_method_of_the_protocol(seed):
    for name, problem, x, _data in _assemblies(seed):
        layout = problem.layout
        for member in LAYOUT:
            assert hasattr(layout, member), (name, member)
        banded = layout.bandwidth < layout.size
        for member in PROTOCOL - (set() if banded else BANDED_ONLY):
            assert hasattr(problem, member), (name, member)
            if member != "layout":
                assert callable(getattr(problem, member)), (name, member)
        assert np.all(np.diff(x[layout.time_index()]) > 0), name


@pytest.mark.parametrize("seed", range(2))
def test_every_grid_problem_gives_its_derivatives_and_a_transposed_solve(seed):
    """``dF/dtheta`` is ``(size, len(theta))`` and sparse; the band storage is the sparse
    Jacobian's band; ``J^T y = b`` is solved beside ``J y = b`` from the same factors, to the
    backward error of LU."""
    eps = np.finfo(float).eps
    rng = np.random.default_rng(seed)
    for name, problem, x, data in _assemblies(seed):
        size = problem.layout.size
        F, jacobian = problem.evaluate(x, data, jacobian=True)
        matrix = problem.sparse(jacobian).toarray()
        derivative = problem.parameter_jacobian(x, data)
        assert sp.issparse(derivative) and derivative.shape[0] == size, name
        w = problem.layout.bandwidth
        if w < size:
            ab = problem.banded(jacobian)
            rows, cols = np.nonzero(np.abs(np.subtract.outer(np.arange(size),
                                                             np.arange(size))) <= w)
            assert np.array_equal(ab[2 * w + rows - cols, cols], matrix[rows, cols]), name
            F, jacobian = problem.evaluate(x, data, jacobian=True)  # banded may be factored
        factors = Factorization(problem, jacobian, "sparse")
        b = rng.normal(size=size)
        for solve, operator in ((factors.solve, matrix), (factors.solve_transposed, matrix.T)):
            y = solve(b.copy())
            bound = 10 * size * eps * np.max(np.abs(matrix)) * np.max(np.abs(y)) * size
            assert np.max(np.abs(operator @ y - b)) <= bound, name
        problem.release()


@functools.cache
def _scene(name: str):
    """A scene loaded once for the module: the problems sampled below are built anew at every
    call, on systems whose compiled functions are then made once (no test changes a system)."""
    return load_scene(name)


def _with_parameters(name: str):
    system = _scene(name).system
    return system, np.asarray(system.parameter_vector({}), float)


def _request(system, theta, nodes, q_start, q_end, t1):
    times = np.linspace(0.0, t1, nodes)
    return GridRequest(system, Scheme("fixed"), nodes, theta,
                       Boundary(np.asarray(q_start, float), np.asarray(q_end, float), 0.0, t1,
                                times), GridOptions())


def _assemblies(seed: int):
    """``(name, problem, x, data)`` of every grid problem of the package at a random point."""
    rng = np.random.default_rng(seed)
    found = []
    for name, rule, compiler in (("kepler", "vddvp", "auto"), ("pendulum", "fixed", None),
                                 ("henon_heiles", "lee", "auto")):
        system = _scene(name).system
        nodes = int(rng.integers(5, 40))
        grid = GridAssembly(system, Scheme(rule), nodes, Compilation(compiler=compiler))
        t = np.sort(rng.random(nodes)) + np.arange(nodes)
        q, p = rng.normal(size=(nodes, system.n)), rng.normal(size=(nodes, system.n))
        theta = np.asarray(system.parameter_vector({}), float)
        times = t[[0, -1]] if rule != "fixed" else t + 1e-3
        found.append((f"bvp {name} {rule}", grid, grid.layout.pack(t, q, p),
                      Ends(q[0] + 0.1, q[-1], times, theta, 0.7)))
    henon = _scene("henon_heiles").system
    intervals = int(rng.integers(4, 30))
    periodic = PeriodicAssembly(henon, Scheme("vddvp"), intervals)
    x = rng.normal(size=periodic.layout.size)
    x[periodic.layout.time_index()] = np.sort(rng.random(intervals + 1)) + np.arange(
        intervals + 1)
    found.append(("periodic henon_heiles", periodic, x,
                  Closure(0.1, 2, 0.0, np.zeros(0), shift=0.0)))
    spline = _scene("spline")
    nodes = int(rng.integers(9, 40))
    higher = HigherAssembly(spline.system, "vddvp", nodes, 0.1)
    x = rng.normal(size=higher.layout.size)
    x[higher.layout.time_index()] = np.sort(rng.random(nodes)) + np.arange(nodes)
    found.append(("higher spline", higher, x, HigherEnds(x + rng.normal(size=x.size),
                                                          np.zeros(0))))
    arc = ArclengthSystem(periodic)
    y = np.r_[found[-2][2], 0.1 + rng.normal()]
    found.append(("periodic arclength", arc, y,
                  _Arc(found[-2][3], rng.normal(size=y.size), y + rng.normal(size=y.size), 0.2)))
    return found + _bvp_problems(rng) + [_constrained(rng), _constrained_closed(rng)]


def _constrained(rng):
    """The constrained fixed ends' grid (``bvp/constrained_grid.py``) on the Cartesian pendulum
    with its gravity and length as parameters."""
    from ddvp_nlp import HamiltonianSystem
    from ddvp_nlp.solvers.bvp.constrained_grid import ConstrainedData, ConstrainedGrid

    def H(q, p, t, b, L):
        return (p[0] ** 2 + p[1] ** 2) / 2 + b * q[1]

    def rod(q, t, b, L):
        return q[0] ** 2 + q[1] ** 2 - L ** 2
    system = HamiltonianSystem(H, 2, {"b": 1.0, "L": 1.0}, name="rod", constraints=rod)
    nodes = int(rng.integers(5, 30))
    grid = ConstrainedGrid(system, Scheme("vddvp"), nodes)
    x = rng.normal(size=grid.layout.size)
    x[grid.layout.time_index()] = np.sort(rng.random(nodes)) + np.arange(nodes)
    data = ConstrainedData(rng.normal(size=2), rng.normal(size=2), np.array([0.0, 1.0]),
                           np.array([1.0, 1.2]), 0.7)
    return ("bvp constrained", grid, x, data)


def _constrained_closed(rng):
    """The closed grid of a constrained system (``periodic/constrained_closed.py``) on the
    spherical pendulum, with one first integral (an unfolding column and a phase row)."""
    from ddvp_nlp import HamiltonianSystem
    from ddvp_nlp.solvers.periodic.constrained_closed import (
        ConstrainedClosedGrid,
        ConstrainedClosure,
    )

    def H(q, p, t, b):
        return (p[0] ** 2 + p[1] ** 2 + p[2] ** 2) / 2 + b * q[2]

    def rod(q, t, b):
        return q[0] ** 2 + q[1] ** 2 + q[2] ** 2 - 1
    system = HamiltonianSystem(H, 3, {"b": 1.0}, name="sphere", constraints=rod)
    intervals = int(rng.integers(4, 30))
    grid = ConstrainedClosedGrid(system, Scheme("vddvp"), intervals,
                                 (lambda q, p: q[0] * p[1] - q[1] * p[0],))
    x = rng.normal(size=grid.layout.size)
    x[grid.layout.time_index()] = np.sort(rng.random(intervals + 1)) + np.arange(intervals + 1)
    data = ConstrainedClosure(-0.5, 2, 0.0, np.array([1.2]), rng.normal(size=6),
                              rng.normal(size=(1, 6)))
    return ("periodic constrained", grid, x, data)


def _bvp_problems(rng):
    """The fixed-endpoint start's problems: the continuation's path in ``(x, s)`` and the end
    map of shooting (harmonic: a parameter to differentiate in)."""
    system, theta = _with_parameters("harmonic")
    nodes = int(rng.integers(5, 30))
    request = _request(system, theta, nodes, [1.0], [0.5], 3.0)
    grid = GridAssembly(system, Scheme("fixed"), nodes, Compilation(compiler=None))
    path = _Path(request, grid, request.data.grid_times, np.array([0.2]))
    q, p = rng.normal(size=(nodes, 1)), rng.normal(size=(nodes, 1))
    y = np.r_[grid.layout.pack(request.data.grid_times, q, p), rng.random()]
    plane = Hyperplane(y + rng.normal(size=y.size), rng.normal(size=y.size))
    shooting = ShootingProblem(request, Scheme("fixed"))
    return [("bvp continuation path", path, y, plane),
            ("bvp shooting", shooting, rng.normal(size=1), Aim(np.array([0.5]), theta))]


# seeds 0 and 1 (other node counts and points, every problem) keep the rule in the default run
@pytest.mark.slow_when(lambda seed, **_: seed >= 2, why="repetition")
@pytest.mark.parametrize("seed", range(4))
def test_every_grid_problem_gives_the_same_residual_with_and_without_its_jacobian(seed):
    """Rule 3: the grid's Newton takes F from the Jacobian's evaluation and from the line
    search's, so the two must be the same numbers."""
    for name, assembly, x, data in _assemblies(seed):
        with_jacobian, jacobian = assembly.evaluate(x, data, jacobian=True)
        without, nothing = assembly.evaluate(x, data, jacobian=False)
        assert nothing is None, name
        assert np.array_equal(with_jacobian, without, equal_nan=True), name
        assert with_jacobian.shape == (assembly.layout.size,), name
        matrix = assembly.sparse(jacobian)
        assert matrix.shape == (assembly.layout.size,) * 2, name
        assembly.release()


def test_the_periodic_jacobian_carries_its_own_problems_data():
    """Rule 2: one assembly serves every problem of its shape; the Jacobian of an evaluation
    holds the constant rows of that evaluation's problem (its section), not of another's."""
    henon = load_scene("henon_heiles").system
    assembly = PeriodicAssembly(henon, Scheme("vddvp"), 10)
    x = np.random.default_rng(0).normal(size=assembly.layout.size)
    matrices = [assembly.sparse(assembly.evaluate(x, Closure(0.1, index, 0.0, np.zeros(0)))[1])
                .toarray() for index in (1, 3)]
    assert matrices[0][1, 1] == 1.0 and matrices[0][1, 3] == 0.0
    assert matrices[1][1, 3] == 1.0 and matrices[1][1, 1] == 0.0


def _higher(options):
    spline = load_scene("spline")
    config = spline.resolve()
    t_a, q_a, t_b, q_b = spline.ends(config, 41, spline.boundary.t_span)
    return solve_bvp_higher(spline.system, t_a, q_a, t_b, q_b, nodes=41, scheme="vddvp",
                            options=options)


# One pendulum for every family's solve below: its assemblies and IPOPT builds are made once and
# kept with it, as in a session (a new system object builds them again); no test mutates it.
PENDULUM = load_scene("pendulum").system
FAMILIES = {
    "bvp": lambda options: solve_bvp(PENDULUM, [0.5], [-0.036], (0.0, 9.0), nodes=181,
                                     options=options),
    "periodic": lambda options: solve_periodic(PENDULUM, energy=0.5, nodes=101,
                                               options=options),
    "higher": _higher,
}


@pytest.mark.parametrize("family", sorted(FAMILIES))
@pytest.mark.parametrize("solver", ["newton", "ipopt"])
def test_a_time_limit_reaches_every_grid_family(family, solver):
    solution = FAMILIES[family](GridOptions(solver=solver, time_limit=1e-9))
    assert solution.status is Status.TIME_LIMIT, solution.message
    assert "accurate" not in solution.message


def test_a_periodic_orbit_keeps_its_tau_floor_and_refuses_a_banded_lu():
    solution = FAMILIES["periodic"](GridOptions(tau_floor=0.02))
    assert solution.success and solution.orbit.tau_min >= 0.02
    with pytest.raises(InputError, match="^tau_floor must be < the start's mean step"):
        FAMILIES["periodic"](GridOptions(tau_floor=1.0))
    with pytest.raises(InputError, match="^linear must be 'auto' or 'sparse' for a periodic"):
        FAMILIES["periodic"](GridOptions(linear="banded"))
