"""Constraints that cannot be used are refused by name before anything is built
(physics/constraints.py, the consistent start, the solvers that do not know constraints)."""

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import (
    HamiltonianSystem,
    InputError,
    Output,
    Scene,
    continue_march,
    march,
    solve_periodic,
)


def kinetic(q, p, t):
    return ca.dot(p, p) / 2 + q[1]


def make(constraints, n=2):
    return HamiltonianSystem(kinetic if n == 2 else lambda q, p, t: ca.dot(p, p) / 2, n,
                             name="bad", constraints=constraints)


@pytest.mark.parametrize("constraints, words", [
    (3.0, "must be a function"),
    (lambda q, t: ca.horzcat(q[0], q[1]).T @ ca.horzcat(q[0], q[1]), "must return a vector"),
    (lambda q, t: "x", "must return a CasADi vector"),
    (lambda q, t: ca.MX.sym("x"), "MX"),
    (lambda q, t: ca.sin(t), "row 0 .* does not depend on q"),
    (lambda q, t: 1.0, "does not depend on q"),
    (lambda q, t: q[0] + ca.SX.sym("stray"), "symbols they were not given"),
    (lambda q, t: ca.vertcat(q[0], q[1]), "at most n - 1"),
    (lambda q, t: [], "empty"),
    (lambda q, t: q[5], "failed on symbolic input"),
])
def test_a_constraint_of_the_wrong_kind_is_refused_by_name(constraints, words):
    with pytest.raises(InputError, match=words):
        make(constraints)


def test_a_singular_constraint_jacobian_at_the_start_is_refused():
    system = make(lambda q, t: q[0] ** 2 + q[1] ** 2)  # dg/dq = 0 at the origin
    with pytest.raises(InputError, match="singular Jacobian"):
        march(system, [0.0, 0.0], [0.0, 0.0], (0, 1), tau0=0.1)


def test_redundant_constraints_are_refused():
    def twice(q, t):
        g = q[0] ** 2 + q[1] ** 2 + q[2] ** 2 - 1
        return ca.vertcat(g, 2 * g)
    system = make(twice, n=3)
    with pytest.raises(InputError, match="redundant"):
        march(system, [0.0, 0.0, -1.0], [0.0, 0.0, 0.0], (0, 1), tau0=0.1)


def test_non_finite_constraints_at_the_start_are_refused():
    system = make(lambda q, t: ca.log(q[0]) + q[1])
    with pytest.raises(InputError, match="not finite"):
        march(system, [-1.0, 0.0], [0.0, 0.0], (0, 1), tau0=0.1)


def test_a_start_that_cannot_be_made_consistent_is_refused():
    # no real point of x^2 + y^2 = -1
    system = make(lambda q, t: q[0] ** 2 + q[1] ** 2 + 1)
    with pytest.raises(InputError, match="cannot be made consistent|singular"):
        march(system, [0.3, 0.2], [0.0, 0.0], (0, 1), tau0=0.1)


def circle(q, t):
    return q[0] ** 2 + q[1] ** 2 - 1


@pytest.mark.parametrize("call, words", [
    (lambda s: solve_periodic(s, energy=0.0, nodes=11), "solve_periodic"),
    (lambda s: march(s, [0.0, -1.0], None, (0, 1), tau0=0.1, v0=[1.0, 0.0]), "v0"),
    (lambda s: march(s, [0.0, -1.0], [1.0, 0.0], (0, 1), tau0=0.1, target_error=1e-6),
     "target_error"),
    (lambda s: march(s, [0.0, -1.0], [1.0, 0.0], (0, 1), tau0=0.1, derivatives="q0",
                     output=Output(t_eval=[0.5])), "derivatives"),
    (lambda s: march(s, [0.0, -1.0], [1.0, 0.0], (0, 1), tau0=0.1,
                     output=Output(keep_every=2)), "thinned"),
    (lambda s: continue_march(s, None, 1.0, tau0=0.1), "MarchState"),
])
def test_solvers_that_do_not_know_constraints_refuse_them(call, words):
    system = HamiltonianSystem(kinetic, 2, name="cp", constraints=circle)
    with pytest.raises(InputError, match=words):
        call(system)


def test_a_scene_carries_its_constraints():
    scene = Scene(kinetic, n=2, q0=[0.0, -1.0], p0=[1.0, 0.0], tau0=0.1, t_end=1.0,
                  constraints=circle)
    assert scene.system.n_constraints == 1
    assert scene.system.constraints is circle


ROWS = st.integers(0, 4)


@settings(max_examples=40, deadline=None)
@given(rows=ROWS, columns=st.integers(1, 3), n=st.integers(2, 4),
       uses=st.lists(st.booleans(), min_size=12, max_size=12))
def test_random_constraint_shapes_are_accepted_exactly_when_usable(rows, columns, n, uses):
    """A matrix of rows x columns entries, each a function of q or a constant: accepted iff it
    is a non-empty column of at most n - 1 rows, every row depending on q."""
    def constraints(q, t):
        entries = [[q[(i + j) % n] ** 2 - 0.5 if uses[(i * columns + j) % 12] else 1.0
                    for j in range(columns)] for i in range(rows)]
        return ca.SX(0, 1) if rows == 0 else ca.vertcat(*[ca.horzcat(*row) for row in entries])
    shape_ok = 1 <= rows and (columns == 1 or rows == 1)
    m = rows if columns == 1 else columns
    depends = all(uses[(i * columns + j) % 12] for i in range(rows) for j in range(columns))
    usable = shape_ok and m <= n - 1 and depends
    system = lambda: HamiltonianSystem(lambda q, p, t: ca.dot(p, p) / 2, n,  # noqa: E731
                                       name="random", constraints=constraints)
    if usable:
        assert system().n_constraints == m
    else:
        with pytest.raises(InputError):
            system()


def test_a_system_without_constraints_is_unchanged():
    system = HamiltonianSystem(kinetic, 2, name="free")
    assert system.constraints is None and system.n_constraints == 0
    assert system.G.shape == (0, 1)
    assert np.isfinite(march(system, [0.0, -1.0], [0.1, 0.0], (0, 1), tau0=0.1).t).all()
