"""Derivatives of periodic orbits and fixed-end solutions by the implicit-function theorem on
the verified grid solution (issue 47): against finite differences of the discrete solve, the
closed forms they converge to, the discrete Hamilton-Jacobi relations, and the edges."""

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import ellipe

from ddvp_nlp import (
    AtEnergy,
    GridOptions,
    HamiltonianSystem,
    InputError,
    solve_bvp,
    solve_periodic,
)
from ddvp_nlp.solvers.bvp.end_derivatives import BVP_DERIVATIVES
from ddvp_nlp.solvers.grid.implicit_derivatives import (
    ILL_CONDITIONED,
    DerivativesRefused,
    check_names,
)


def pendulum(scale=1.0, offset=0.0):
    def H(q, p, t, w):
        return scale * (p[0] ** 2 / 2 + w ** 2 * (1 - ca.cos(q[0]))) + offset
    return HamiltonianSystem(H, 1, {"w": 1.0}, name=f"pendulum_w_{scale}_{offset}")


PENDULUM = pendulum()


def kepler():
    def H(q, p, t, mu):
        return (p[0] ** 2 + p[1] ** 2) / 2 - mu / ca.sqrt(q[0] ** 2 + q[1] ** 2)
    return HamiltonianSystem(H, 2, {"mu": 1.0}, name="kepler_mu")


def period(energy, w, nodes, system=PENDULUM):
    return solve_periodic(system, energy=energy, nodes=nodes, params={"w": w}).orbit.period


# (0.5, 1.0) keeps the comparison in the default run; the other two points repeat it
@pytest.mark.slow_when(lambda energy, w, **_: (energy, w) != (0.5, 1.0), why="repetition")
@pytest.mark.parametrize("energy, w", [(0.5, 1.0), (1.0, 1.3), (0.3, 0.8)])
def test_period_derivative_matches_central_differences_of_the_discrete_period(energy, w):
    nodes = 201
    orbit = solve_periodic(PENDULUM, energy=energy, nodes=nodes, params={"w": w},
                           derivatives=("energy", "params"))
    d = orbit.derivatives
    h = 1e-4 * w
    fd_w = (period(energy, w + h, nodes) - period(energy, w - h, nodes)) / (2 * h)
    h = 1e-4 * energy
    fd_e = (period(energy + h, w, nodes) - period(energy - h, w, nodes)) / (2 * h)
    assert abs(d["period"]["params"][0] - fd_w) <= 1e-7 * abs(fd_w)
    assert abs(d["period"]["energy"] - fd_e) <= 1e-7 * abs(fd_e)
    assert {c["verdict"] for c in d["checks"].values()} == {"agrees"}
    assert not d["ill_conditioned"]
    assert d["nodes"]["params"].shape == (nodes, 3, 1)
    assert d["nodes"]["energy"].shape == (nodes, 3)


def test_period_derivative_in_w_converges_at_order_two_to_the_closed_form():
    energy, w = 0.5, 1.0
    m = energy / (2 * w ** 2)
    exact = -4 * ellipe(m) / (w ** 2 * (1 - m))
    sizes = np.array([100, 200, 400])
    errors = []
    for N in sizes:
        orbit = solve_periodic(PENDULUM, energy=energy, nodes=N + 1, params={"w": w},
                               derivatives="params")
        errors.append(abs(orbit.derivatives["period"]["params"][0] - exact))
    order = -np.polyfit(np.log(sizes), np.log(errors), 1)[0]
    assert abs(order - 2.0) <= 0.05, (order, errors)


def test_kepler_period_derivative_in_mu_at_fixed_energy():
    energy = -0.5
    exact = 2 * np.pi * (-2 * energy) ** -1.5   # T = 2 pi mu (-2E)^(-3/2)
    errors = []
    for N in (100, 200):
        orbit = solve_periodic(kepler(), energy=energy, nodes=N + 1, section="q2=0",
                               start=([1, 0], [0, 1]),
                               integrals=(lambda q, p: q[0] * p[1] - q[1] * p[0],),
                               derivatives=("energy", "params"))
        assert orbit.success
        errors.append(abs(orbit.derivatives["period"]["params"][0] - exact) / exact)
        # near the eccentricity family the discrete orbit's nodes are barely determined (said,
        # not hidden); the period does not see that direction. The nodes' estimate is a
        # round-off estimate near the flag's threshold (3.4e-7 at N = 100 on one machine, above
        # 1e-6 on others), so the test holds the separation and the flag's agreement with it
        d = orbit.derivatives
        assert not d["ill_conditioned"]
        assert d["nodes_error_estimate"] > 1e6 * d["error_estimate"]
        assert d["nodes_ill_conditioned"] == (d["nodes_error_estimate"] > ILL_CONDITIONED)
        assert {c["verdict"] for c in d["checks"].values()} == {"agrees"}
    assert errors[0] < 1e-3 and 3.5 < errors[0] / errors[1] < 4.5


def test_time_units_and_energy_offset_scale_the_derivatives():
    energy, nodes, s, c = 0.5, 101, 3.0, 0.7
    base = solve_periodic(PENDULUM, energy=energy, nodes=nodes, derivatives="energy")
    fast = solve_periodic(pendulum(scale=s), energy=s * energy, nodes=nodes,
                          derivatives="energy")
    shifted = solve_periodic(pendulum(offset=c), energy=energy + c, nodes=nodes,
                             derivatives="energy")
    dT = base.derivatives["period"]["energy"]
    # H -> s H runs the same discrete orbit s times faster at energy s E: T/s, dT/dE / s^2
    assert fast.derivatives["period"]["energy"] == pytest.approx(dT / s ** 2, rel=1e-8)
    assert shifted.derivatives["period"]["energy"] == pytest.approx(dT, rel=1e-8)


def solved_ends(q_end=0.5, q_start=0.1, nodes=101, **kwargs):
    return solve_bvp(PENDULUM, [q_start], [q_end], (0.0, 2.0), nodes=nodes,
                     options=GridOptions(tol=1e-12), **kwargs)


def test_discrete_hamilton_jacobi_and_the_action_hessian():
    bvp = solved_ends(derivatives=("q_start", "q_end", "params"))
    d = bvp.derivatives
    h = 1e-5
    dS_end = (solved_ends(0.5 + h).ends.action - solved_ends(0.5 - h).ends.action) / (2 * h)
    dS_start = (solved_ends(q_start=0.1 + h).ends.action
                - solved_ends(q_start=0.1 - h).ends.action) / (2 * h)
    assert dS_end == pytest.approx(bvp.p[-1, 0], rel=1e-8)
    assert dS_start == pytest.approx(-bvp.p[0, 0], rel=1e-8)
    # the momenta are the action's gradient: its Hessian is symmetric
    assert d["p_end"]["q_start"][0, 0] == pytest.approx(-d["p_start"]["q_end"][0, 0], rel=1e-9)
    fd = (solved_ends(0.5 + h).p[-1, 0] - solved_ends(0.5 - h).p[-1, 0]) / (2 * h)
    assert d["p_end"]["q_end"][0, 0] == pytest.approx(fd, rel=1e-7)
    assert {c["verdict"] for c in d["checks"].values()} == {"agrees"}
    assert d["nodes"]["q_end"].shape == (101, 3, 1)


def test_relabelled_coordinates_permute_the_end_derivatives():
    def H(q, p, t, a, b):
        return (p[0] ** 2 + p[1] ** 2) / 2 + a * q[0] ** 2 / 2 + b * q[1] ** 2 / 2 \
            + 0.1 * q[0] ** 2 * q[1]

    def swapped(q, p, t, a, b):
        return H(q[::-1], p[::-1], t, a, b)
    one = HamiltonianSystem(H, 2, {"a": 1.0, "b": 2.0}, name="coupled")
    two = HamiltonianSystem(swapped, 2, {"a": 1.0, "b": 2.0}, name="coupled_swapped")
    names = ("q_start", "q_end", "params")
    first = solve_bvp(one, [0.1, 0.2], [0.3, -0.1], (0.0, 1.0), nodes=41, derivatives=names)
    second = solve_bvp(two, [0.2, 0.1], [-0.1, 0.3], (0.0, 1.0), nodes=41, derivatives=names)
    d, e = first.derivatives, second.derivatives
    for end in ("p_start", "p_end"):
        for name in ("q_start", "q_end"):
            assert np.allclose(e[end][name], d[end][name][::-1, ::-1], rtol=1e-8, atol=1e-11)
        assert np.allclose(e[end]["params"], d[end]["params"][::-1], rtol=1e-8, atol=1e-11)


def test_bad_names_are_refused_listing_the_allowed_ones():
    with pytest.raises(InputError, match="choose from q_start, q_end, params"):
        solved_ends(derivatives=("q_end", "p_end"))
    with pytest.raises(InputError, match="choose from energy, params"):
        solve_periodic(PENDULUM, energy=0.5, nodes=51, derivatives="q0")
    free = HamiltonianSystem(lambda q, p, t: p[0] ** 2 / 2 + q[0] ** 2 / 2, 1, name="sho")
    with pytest.raises(InputError, match="has no parameters"):
        solve_periodic(free, energy=0.5, nodes=51, derivatives="params")
    with pytest.raises(InputError, match="transfer at an energy"):
        solve_bvp(PENDULUM, [0.1], [0.5], AtEnergy(0.3, 0.0), nodes=51, derivatives="q_end")


def test_a_failed_solve_gives_no_numbers():
    bvp = solve_bvp(PENDULUM, [0.1], [0.5], (0.0, 2.0), nodes=101,
                    options=GridOptions(max_iter=1, solver="newton"), derivatives="q_end")
    assert not bvp.success
    with pytest.raises(DerivativesRefused, match="failed"):
        bvp.derivatives["p_end"]


@settings(max_examples=60, deadline=None)
@given(st.one_of(st.none(), st.sampled_from(BVP_DERIVATIVES),
                 st.lists(st.sampled_from(BVP_DERIVATIVES + ("p0", "x", "")), max_size=4),
                 st.integers(), st.floats()))
def test_the_names_reader_keeps_the_allowed_order_or_names_the_wrong_one(value):
    try:
        names = check_names(value, BVP_DERIVATIVES, "solve_bvp")
    except InputError as error:
        assert "solve_bvp" in str(error)
        return
    assert names == tuple(n for n in BVP_DERIVATIVES if n in (
        (value,) if isinstance(value, str) else (value or ())))
