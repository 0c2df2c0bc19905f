"""Reverse mode of grid solutions' derivatives (``bvp/end_gradient.py``,
``periodic/orbit_gradient.py``): one transposed solve on the same factorisation equals the
cotangent contracted with the forward derivatives to 1e-10, with or without ``derivatives=``;
a time offset leaves it; bad cotangents and mismatched problems refused by name."""

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import HamiltonianSystem, InputError, solve_bvp, solve_periodic
from ddvp_nlp.solvers import bvp_gradient, orbit_gradient
from ddvp_nlp.solvers.grid.implicit_derivatives import check_grid_cotangent

AGREEMENT = 1e-10
BVP_NAMES = ("q_start", "q_end", "params")


def _swing():
    def H(q, p, t, w):
        return p[0] ** 2 / 2 + w ** 2 * (1 - ca.cos(q[0]))
    return HamiltonianSystem(H, 1, {"w": 1.0}, name="pendulum_swing_gradient")


def _coupled():
    def H(q, p, t, a, b):
        return (p[0] ** 2 + p[1] ** 2) / 2 + a * q[0] ** 2 / 2 + b * q[1] ** 2 / 2 \
            + q[0] ** 2 * q[1] ** 2 / 4
    return HamiltonianSystem(H, 2, {"a": 1.0, "b": 2.0}, name="coupled_gradient")


SWING, COUPLED = _swing(), _coupled()


def _bvp_contracted(c, D, name):
    return (c["p_start"] @ D["p_start"][name] + c["p_end"] @ D["p_end"][name]
            + np.einsum("ij,ijk->k", c["nodes"], D["nodes"][name]))


def _drawn(rng, n, nodes):
    return {"p_start": rng.normal(size=n), "p_end": rng.normal(size=n),
            "nodes": rng.normal(size=(nodes, 2 * n + 1))}


@pytest.mark.parametrize("system, q_start, q_end, scheme", [
    (SWING, [0.1], [0.5], "vddvp"), (SWING, [0.1], [0.5], "fixed"),
    (COUPLED, [0.2, -0.1], [0.4, 0.3], "vddvp")])
def test_bvp_reverse_equals_forward(system, q_start, q_end, scheme):
    bvp = solve_bvp(system, q_start, q_end, (0.0, 2.0), nodes=61, scheme=scheme,
                    derivatives=BVP_NAMES)
    rng = np.random.default_rng(3)
    for _ in range(2):
        c = _drawn(rng, system.n, 61)
        g = bvp_gradient(bvp, c)
        assert not g.ill_conditioned and g.error_estimate < 1e-9
        for name in BVP_NAMES:
            forward = _bvp_contracted(c, bvp.derivatives, name)
            assert g[name].shape == forward.shape
            assert np.max(np.abs(g[name] - forward)) <= AGREEMENT * np.max(np.abs(forward))
    # one cotangent alone: the end momentum's row of the forward derivative
    g = bvp_gradient(bvp, {"p_end": np.eye(system.n)[0]})
    assert np.allclose(g["q_end"], bvp.derivatives["p_end"]["q_end"][0], rtol=0,
                       atol=AGREEMENT * np.max(np.abs(bvp.derivatives["p_end"]["q_end"])))


def test_bvp_reverse_without_derivatives_and_under_a_time_offset():
    """The same gradient from a solve without derivatives=, and from the span moved by 5.3
    (an autonomous system; the node-time rows of the cotangent read the same nodes)."""
    with_d = solve_bvp(SWING, [0.1], [0.5], (0.0, 2.0), nodes=61, derivatives=BVP_NAMES)
    plain = solve_bvp(SWING, [0.1], [0.5], (0.0, 2.0), nodes=61)
    later = solve_bvp(SWING, [0.1], [0.5], (5.3, 7.3), nodes=61)
    c = _drawn(np.random.default_rng(4), 1, 61)
    a, b, d = bvp_gradient(with_d, c), bvp_gradient(plain, c), bvp_gradient(later, c)
    for name in BVP_NAMES:
        size = np.max(np.abs(a[name]))
        assert np.max(np.abs(a[name] - b[name])) <= AGREEMENT * size
        assert np.max(np.abs(a[name] - d[name])) <= 1e-8 * size


def test_orbit_reverse_equals_forward():
    orbit = solve_periodic(SWING, energy=0.5, nodes=101, derivatives=("energy", "params"))
    D = orbit.derivatives
    g = orbit_gradient(orbit, {"period": 1.0}, system=SWING)
    assert abs(g["energy"] - D["period"]["energy"]) <= AGREEMENT * abs(D["period"]["energy"])
    assert np.allclose(g["params"], D["period"]["params"], rtol=AGREEMENT, atol=0)
    rng = np.random.default_rng(5)
    c = {"period": 0.7, "nodes": rng.normal(size=(101, 3))}
    g = orbit_gradient(orbit, c, system=SWING, params={"w": 1.0})
    energy = 0.7 * D["period"]["energy"] + np.sum(c["nodes"] * D["nodes"]["energy"])
    params = 0.7 * D["period"]["params"] + np.einsum("ij,ijk->k", c["nodes"],
                                                      D["nodes"]["params"])
    assert abs(g["energy"] - energy) <= AGREEMENT * abs(energy)
    assert np.max(np.abs(g["params"] - params)) <= AGREEMENT * np.max(np.abs(params))
    assert not g.ill_conditioned


def test_refusals_name_the_argument():
    bvp = solve_bvp(SWING, [0.1], [0.5], (0.0, 2.0), nodes=21)
    orbit = solve_periodic(SWING, energy=0.5, nodes=41)
    with pytest.raises(InputError, match="unknown name 'period'"):
        bvp_gradient(bvp, {"period": 1.0})
    with pytest.raises(InputError, match=r"cotangent\['nodes'\] must have shape \(21, 3\)"):
        bvp_gradient(bvp, {"nodes": np.zeros((20, 3))})
    with pytest.raises(InputError, match=r"cotangent\['p_end'\] must be finite"):
        bvp_gradient(bvp, {"p_end": [np.nan]})
    with pytest.raises(InputError, match="must be a solve_bvp Solution"):
        bvp_gradient(orbit, {"p_end": [1.0]})
    with pytest.raises(InputError, match="must be a solve_periodic Solution"):
        orbit_gradient(bvp, {"period": 1.0}, system=SWING)
    with pytest.raises(InputError, match="does not hold the equations"):
        orbit_gradient(orbit, {"period": 1.0}, system=SWING, params={"w": 1.01})
    with pytest.raises(InputError, match="system must be the HamiltonianSystem"):
        orbit_gradient(orbit, {"period": 1.0}, system=COUPLED)
    with pytest.raises(InputError, match="solved with 0 first integrals, got 1"):
        orbit_gradient(orbit, {"period": 1.0}, system=SWING,
                       integrals=[lambda q, p: p[0]])


@settings(max_examples=40, deadline=None)
@given(st.one_of(st.none(), st.integers(), st.text(max_size=5),
                 st.dictionaries(st.sampled_from(["p_start", "p_end", "nodes", "x"]),
                                 st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                                           st.lists(st.floats(), max_size=3)),
                                 max_size=3)))
def test_the_cotangent_reader_answers_anything_by_name(value):
    """Drawn cotangents: read, or refused with an InputError (never another exception)."""
    shapes = {"p_start": (1,), "p_end": (1,), "nodes": (2, 3)}
    try:
        found = check_grid_cotangent(value, shapes, "solve_bvp")
    except InputError:
        return
    for name, array in found.items():
        assert array.shape == shapes[name] and np.all(np.isfinite(array))
