"""Derivatives of a transfer at a prescribed energy (``bvp/transfer_derivatives.py``): the
transfer time's and end momenta's derivatives in the ends, the energy and the parameters
against central differences of whole transfers solved again, each input's own check, a time
offset; bad inputs refused by name."""

import functools

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import AtEnergy, HamiltonianSystem, InputError, solve_bvp
from ddvp_nlp.solvers import transfer_derivatives, transfer_gradient

NAMES = ("q_start", "q_end", "energy", "params")
# Central differences of whole transfers at a relative step of 1e-5: truncation about 1e-10
# of the derivative, and each transfer's verification allows its rows 2e-13, /1e-5 of the
# step: about 1e-7 of the quotient. Measured: agreement to 2e-9 or better.
STEP = 1e-5
AGREEMENT = 1e-6
# ... and a quotient cannot be closer than the round-off of what it differences: a few units in
# the last place of the end momentum over the step (the momentum's derivative in q_start is
# 4.6e-5 while p_end is about 1: one ulp of p_end over 2h is 2e-6 of it)
ULPS = 4


def _quotient_floor(p_end, h):
    return ULPS * np.finfo(float).eps * np.max(np.abs(p_end)) / (2 * h)


def _swing():
    def H(q, p, t, w):
        return p[0] ** 2 / 2 + w ** 2 * (1 - ca.cos(q[0]))
    return HamiltonianSystem(H, 1, {"w": 1.0}, name="pendulum_swing_transfer")


SWING = _swing()


@functools.cache
def _transfer(q_start=0.1, q_end=0.5, energy=1.0, w=1.0, t0=0.0):
    """The swing's transfer, solved once per set of arguments for the module (read only)."""
    return solve_bvp(SWING, [q_start], [q_end], AtEnergy(energy, t0=t0), nodes=41,
                     params={"w": w})


def test_transfer_derivatives_match_resolved_transfers():
    sol = _transfer()
    D = transfer_derivatives(sol)
    assert sol.status.code == "success"
    base = {"q_start": 0.1, "q_end": 0.5, "energy": 1.0, "w": 1.0}
    for name, key in zip(NAMES, ("q_start", "q_end", "energy", "w"), strict=True):
        h = STEP * abs(base[key])
        plus, minus = _transfer(**{**base, key: base[key] + h}), \
            _transfer(**{**base, key: base[key] - h})
        dT = (plus.transfer.transfer_time - minus.transfer.transfer_time) / (2 * h)
        dp = (plus.p[-1] - minus.p[-1]) / (2 * h)
        assert abs(D["transfer_time"][name][0] - dT) <= AGREEMENT * abs(dT), name
        assert np.max(np.abs(D["p_end"][name][:, 0] - dp)) <= AGREEMENT * np.max(np.abs(dp)) \
            + _quotient_floor(sol.p[-1], h), name
        assert D["checks"][name]["verdict"] == "agrees", name
    assert not D["ill_conditioned"]
    assert D["nodes"]["energy"].shape == (41, 3, 1) and D["p_start"]["q_end"].shape == (1, 1)


def test_a_time_offset_leaves_the_derivatives():
    a = transfer_derivatives(_transfer(), ("q_end", "energy"))
    b = transfer_derivatives(_transfer(t0=4.2), ("q_end", "energy"))
    for name in ("q_end", "energy"):
        size = abs(a["transfer_time"][name][0])
        assert abs(a["transfer_time"][name][0] - b["transfer_time"][name][0]) <= 1e-8 * size


def test_refusals_name_the_argument():
    fixed = solve_bvp(SWING, [0.1], [0.5], (0.0, 1.0), nodes=21)
    with pytest.raises(InputError, match="sol must be a transfer at an energy"):
        transfer_derivatives(fixed)
    sol = _transfer()
    with pytest.raises(InputError, match="unknown name 'period'"):
        transfer_derivatives(sol, ("period",))

    def H(q, p, t):
        return p[0] ** 2 / 2 + q[0] ** 2 / 2
    plain = HamiltonianSystem(H, 1, name="oscillator_transfer")
    other = solve_bvp(plain, [0.1], [0.5], AtEnergy(1.0), nodes=41)
    with pytest.raises(InputError, match="'params' asked, but system"):
        transfer_derivatives(other, ("params",))


def test_reverse_equals_forward_contracted():
    """``transfer_gradient(sol, c)`` (one transposed solve) equals ``c`` contracted with the
    forward derivatives, for a random cotangent on the transfer time, the end momenta and every
    node, to 1e-10 of its size."""
    sol = _transfer()
    D = transfer_derivatives(sol)
    rng = np.random.default_rng(47)
    c = {"transfer_time": rng.normal(), "p_start": rng.normal(size=1),
         "p_end": rng.normal(size=1), "nodes": rng.normal(size=(41, 3))}
    g = transfer_gradient(sol, c)
    for name in NAMES:
        forward = (c["transfer_time"] * D["transfer_time"][name]
                   + c["p_start"] @ D["p_start"][name] + c["p_end"] @ D["p_end"][name]
                   + np.einsum("ij,ijk->k", c["nodes"], D["nodes"][name]))
        assert np.max(np.abs(g[name] - forward)) <= 1e-10 * np.max(np.abs(forward)), name
    assert not g.ill_conditioned


@pytest.mark.parametrize("cotangent, message", [
    ({}, "is empty"),
    ({"period": 1.0}, "unknown name 'period'"),
    ({"p_end": [1.0, 2.0]}, "must have shape"),
    ({"transfer_time": float("nan")}, "must be finite"),
    ([1.0], "must be a mapping"),
])
def test_a_bad_cotangent_is_refused_by_name(cotangent, message):
    with pytest.raises(InputError, match=message):
        transfer_gradient(_transfer(), cotangent)
