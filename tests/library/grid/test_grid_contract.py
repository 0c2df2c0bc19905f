"""The contract of a grid problem (``solvers/grid/__init__.py``), checked on every assembly, and
the grid options reaching every family that takes them."""

import numpy as np
import pytest

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
from ddvp_nlp.solvers.bvp.interleaved import Ends, GridAssembly
from ddvp_nlp.solvers.higher.windows import HigherAssembly, HigherEnds
from ddvp_nlp.solvers.periodic.closed_grid import Closure, PeriodicAssembly

PROTOCOL = ("evaluate", "sparse", "release")


def _assemblies(seed: int):
    """``(name, assembly, x, data)`` of each family's assembly at a random point."""
    rng = np.random.default_rng(seed)
    found = []
    for name, rule, compiler in (("kepler", "vddvp", "auto"), ("pendulum", "fixed", None),
                                 ("henon_heiles", "lee", "auto")):
        system = load_scene(name).system
        nodes = int(rng.integers(5, 40))
        grid = GridAssembly(system, Scheme(rule), nodes, Compilation(compiler=compiler))
        t = np.sort(rng.random(nodes)) + np.arange(nodes)
        q, p = rng.normal(size=(nodes, system.n)), rng.normal(size=(nodes, system.n))
        theta = np.asarray(system.parameter_vector({}), float)
        times = t[[0, -1]] if rule != "fixed" else t + 1e-3
        found.append((f"bvp {name} {rule}", grid, grid.layout.pack(t, q, p),
                      Ends(q[0] + 0.1, q[-1], times, theta, 0.7)))
    henon = load_scene("henon_heiles").system
    intervals = int(rng.integers(4, 30))
    periodic = PeriodicAssembly(henon, Scheme("vddvp"), intervals)
    x = rng.normal(size=periodic.layout.size)
    x[periodic.layout.time_index()] = np.sort(rng.random(intervals + 1)) + np.arange(
        intervals + 1)
    found.append(("periodic henon_heiles", periodic, x,
                  Closure(0.1, 2, 0.0, np.zeros(0), shift=0.0)))
    spline = load_scene("spline")
    nodes = int(rng.integers(9, 40))
    higher = HigherAssembly(spline.system, "vddvp", nodes, 0.1)
    x = rng.normal(size=higher.layout.size)
    x[higher.layout.time_index()] = np.sort(rng.random(nodes)) + np.arange(nodes)
    found.append(("higher spline", higher, x, HigherEnds(x + rng.normal(size=x.size),
                                                          np.zeros(0))))
    return found


@pytest.mark.parametrize("seed", range(4))
def test_every_assembly_gives_the_same_residual_with_and_without_its_jacobian(seed):
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
        for method in PROTOCOL:
            assert callable(getattr(assembly, method)), (name, method)
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


FAMILIES = {
    "bvp": lambda options: solve_bvp(load_scene("pendulum").system, [0.5], [-0.036], (0.0, 9.0),
                                     nodes=181, options=options),
    "periodic": lambda options: solve_periodic(load_scene("pendulum").system, energy=0.5,
                                               nodes=101, options=options),
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
