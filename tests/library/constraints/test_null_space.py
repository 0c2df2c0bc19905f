"""The constrained march's null-space form (``StepControl.constraint_method="null_space"``,
discrete/null_space.py, solvers/marching/null_space_steps.py): the same equations as the
multiplier form with the multipliers eliminated, so the same nodes to the solver's tolerance
(fixed and vddvp, the Cartesian pendulum and the double pendulum); its option read and refused
by name; metamorphic relations (time unit, rotated coordinates, relabelled links)."""

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import Compilation, HamiltonianSystem, LagrangianSystem, StepControl, march
from ddvp_nlp.discrete.null_space import null_space_basis
from ddvp_nlp.errors import InputError

VM = Compilation(fast=False)  # the virtual machine: no compiler in the default tier
# the two forms stop their Newton at 1e-14 of the unknowns' size (each on its own rows): the
# nodes agree to a few hundred units of that over the short runs here
AGREE = 1e-10


def pendulum(**params):
    values = {"a": 0.0, "b": 1.0}
    values.update(params)
    return HamiltonianSystem(lambda q, p, t, a, b: (p[0] ** 2 + p[1] ** 2) / 2 + a * q[0]
                             + b * q[1], 2, values, name="ns_pendulum",
                             constraints=lambda q, t, a, b: q[0] ** 2 + q[1] ** 2 - 1)


# one system for the module's pendulum tests (gravity along another axis or scaled: params): a
# march's functions are built once per system (ddvp_nlp/cache.py)
NS_PENDULUM = pendulum()


def double_pendulum(order=(0, 1, 2, 3)):
    """Two unit masses on unit rods, coordinates ``(x1, y1, x2, y2)`` stored in ``order``."""
    where = {name: order.index(k) for k, name in enumerate(("x1", "y1", "x2", "y2"))}

    def pick(q):
        return (q[where[name]] for name in ("x1", "y1", "x2", "y2"))

    def hamiltonian(q, p, t):
        _, y1, _, y2 = pick(q)
        return ca.dot(p, p) / 2 + y1 + y2

    def rods(q, t):
        x1, y1, x2, y2 = pick(q)
        return ca.vertcat(x1 ** 2 + y1 ** 2 - 1, (x2 - x1) ** 2 + (y2 - y1) ** 2 - 1)
    return HamiltonianSystem(hamiltonian, 4, name=f"ns_double{''.join(map(str, order))}",
                             constraints=rods)


def run(system, q0, p0, span, scheme, method, tau0=0.01, **params):
    return march(system, q0, p0, span, tau0=tau0, scheme=scheme, accuracy=None,
                 params=params or None, steps=StepControl(constraint_method=method),
                 compilation=VM)


def both(system, q0, p0, span, scheme, tau0=0.01, **params):
    return [run(system, q0, p0, span, scheme, method, tau0, **params)
            for method in ("multipliers", "null_space")]


def assert_same(a, b, tol=AGREE):
    assert a.success and b.success, (a.message, b.message)
    assert a.t.size == b.t.size
    for x, y in ((a.t, b.t), (a.q, b.q), (a.p, b.p),
                 (a.constraints.multipliers, b.constraints.multipliers)):
        assert np.abs(x - y).max() <= tol * max(1.0, np.abs(x).max())


PENDULUM = {"fixed": ([np.sin(1.0), -np.cos(1.0)], [0.0, 0.0]),
            "vddvp": ([0.0, -1.0], [3.0, 0.0])}


@pytest.mark.parametrize("scheme", ["fixed", "vddvp"])
def test_the_null_space_form_marches_the_multiplier_forms_nodes(scheme):
    q0, p0 = PENDULUM[scheme]
    multipliers, null_space = both(NS_PENDULUM, q0, p0, (0, 1.5), scheme)
    assert_same(multipliers, null_space)
    record = null_space.constraints
    assert record.constraint_residual.max() <= 1e-13
    assert record.hidden_residual.max() <= 1e-13
    assert record.newton_updates.max() <= 5
    if scheme == "vddvp":
        assert np.abs(null_space.energy_residual).max() <= 1e-12
    # fewer unknowns, no more Newton updates in all
    assert null_space.newton_iterations <= 1.1 * multipliers.newton_iterations


def test_the_double_pendulum_in_both_forms_and_relabelled_links():
    """Two constraints; the coordinates stored link 2 first (the rows of G and its columns
    permuted, so another null-space basis): the same motion, relabelled."""
    q0 = np.array([0.0, -1.0, 0.0, -2.0])
    p0 = np.array([5.0, 0.0, 1.0, 0.0])  # hanging, rates 5 and -4 (E = 10, chaotic)
    forms = both(double_pendulum(), q0, p0, (0, 0.6), "vddvp", tau0=0.005)
    assert_same(*forms)
    order = (2, 3, 0, 1)
    swapped = run(double_pendulum(order), q0[list(order)], p0[list(order)], (0, 0.6), "vddvp",
                  "null_space", tau0=0.005)
    assert_same(forms[1], _relabelled(swapped, order))


def _relabelled(solution, order):
    back = np.argsort(order)
    solution.q, solution.p = solution.q[:, back], solution.p[:, back]
    return solution


def test_time_unit_and_rotated_coordinates():
    """Time in units c times shorter: gravity c^2 g, momenta c p, steps tau / c, the same
    positions. Gravity along a rotated axis with rotated coordinates: the same motion rotated."""
    q0, p0 = PENDULUM["vddvp"]
    base = run(NS_PENDULUM, q0, p0, (0, 1.0), "vddvp", "null_space")
    c = 3.0
    scaled = run(NS_PENDULUM, q0, c * np.asarray(p0), (0, 1.0 / c), "vddvp", "null_space",
                 tau0=0.01 / c, a=0.0, b=c ** 2)
    assert scaled.t.size == base.t.size
    assert np.abs(scaled.t * c - base.t).max() <= AGREE
    assert np.abs(scaled.q - base.q).max() <= AGREE
    angle = 0.7
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    a, b = R @ np.array([0.0, 1.0])
    turned = run(NS_PENDULUM, R @ q0, R @ p0, (0, 1.0), "vddvp", "null_space", a=a, b=b)
    assert turned.t.size == base.t.size
    assert np.abs(turned.t - base.t).max() <= AGREE
    assert np.abs(turned.q - base.q @ R.T).max() <= AGREE


@settings(max_examples=30, deadline=None)
@given(st.one_of(st.text(max_size=12), st.integers(), st.none(), st.floats()))
def test_a_bad_constraint_method_is_refused_by_name(value):
    if value in ("multipliers", "null_space"):
        return
    with pytest.raises(InputError, match="constraint_method") as error:
        StepControl(constraint_method=value)
    assert repr(value) in str(error.value)


def test_where_the_null_space_form_does_not_apply_it_is_refused_before_the_march():
    q0, p0 = PENDULUM["vddvp"]
    with pytest.raises(InputError, match="constraint_method='null_space'.*'lee'"):
        run(NS_PENDULUM, q0, p0, (0, 1.0), "lee", "null_space")
    lagrangian = LagrangianSystem(lambda q, v, t: (v[0] ** 2 + v[1] ** 2) / 2 - q[1], 2,
                                  name="ns_lagrangian",
                                  constraints=lambda q, t: q[0] ** 2 + q[1] ** 2 - 1)
    with pytest.raises(InputError, match="LagrangianSystem"):
        run(lagrangian, q0, p0, (0, 1.0), "fixed", "null_space")


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 5), st.integers(0, 4), st.integers(0, 2 ** 32 - 1))
def test_the_null_space_basis_is_orthonormal_and_annihilated(m, extra, seed):
    """``G N = 0`` and ``N^T N = I`` for a random full-rank ``G``, also with zero leading
    entries (the reflections' sign choice)."""
    n = m + extra + 1
    G = np.random.default_rng(seed).normal(size=(m, n))
    G[:, 0] = 0.0 if seed % 2 else G[:, 0]
    N = np.asarray(null_space_basis(ca.DM(G)))
    assert N.shape == (n, n - m)
    assert np.abs(G @ N).max() <= 1e-12 * max(1.0, np.abs(G).max())
    assert np.abs(N.T @ N - np.eye(n - m)).max() <= 1e-12


def test_a_time_dependent_constraint_in_both_forms():
    """A rod whose length changes in time (``g_t != 0`` in the hidden constraint and the
    projection of ``p_b``): the same nodes, fixed steps."""
    system = HamiltonianSystem(lambda q, p, t: (p[0] ** 2 + p[1] ** 2) / 2 + q[1], 2,
                               name="ns_breathing",
                               constraints=lambda q, t: q[0] ** 2 + q[1] ** 2
                               - (1 + 0.1 * ca.sin(t)) ** 2)
    radial = np.array([np.sin(1.0), -np.cos(1.0)])  # the rod grows at 0.1 at t = 0
    multipliers, null_space = both(system, radial, 0.1 * radial, (0, 1.0), "fixed")
    assert_same(multipliers, null_space)
    assert null_space.constraints.hidden_residual.max() <= 1e-13


@pytest.mark.parametrize("method", ["multipliers", "null_space"])
def test_a_later_march_reuses_the_chunks_and_reports_no_build(method):
    """The chunks are built once per system, scheme, size, compiler and cache folder
    (``constrained_steps.constrained_chunk``): a reused one shares the built function and
    reports no build or compile time; the second march is the first's, node for node."""
    from ddvp_nlp.discrete.scheme import Scheme
    from ddvp_nlp.solvers.marching.constrained_steps import constrained_chunk
    from ddvp_nlp.solvers.marching.null_space_steps import NullSpaceChunk

    system = pendulum()
    kind = NullSpaceChunk if method == "null_space" else None
    options = {"chunk": 16, "compiler": None, "cache_dir": None}
    if kind is not None:
        options["chunk_class"] = kind
    first = constrained_chunk(system, Scheme.coerce("fixed"), "fixed", **options)
    again = constrained_chunk(system, Scheme.coerce("fixed"), "fixed", **options)
    assert again.function is first.function and first.build_s > 0
    assert again.build_s == 0 and again.compile_s == 0
    q0, p0 = PENDULUM["fixed"]
    a, b = (run(system, q0, p0, (0, 0.3), "fixed", method) for _ in range(2))
    assert np.array_equal(a.q, b.q) and np.array_equal(a.p, b.p)  # the same code, same bits
