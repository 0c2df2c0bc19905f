"""Derivatives of a march's event times (``solvers/marching/event_derivatives.py``): against
fourth-order central differences of the located crossing times of marches run again from
perturbed inputs, under a time offset and relabelled coordinates; a crossing at a tangency
refused (``nan``, flagged), not passed off."""

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import HamiltonianSystem, InputError, Output, march
from ddvp_nlp.solvers.dense import check_events
from ddvp_nlp.solvers.marching.event_derivatives import (
    TANGENCY,
    event_partials,
    hermite_slope,
)

NAMES = ("q0", "p0", "params")
# Relative step of the differences and the agreement asked for: the crossing time is located
# to round-off (a bracket of adjacent numbers) on nodes solved to 1e-14, so the fourth-order
# stencil's noise is about 1.5e-14 sqrt(N) / 1e-6, below 1e-6 for these few hundred steps.
RELATIVE_STEP = 1e-6
TOLERANCE = 1e-6


def _pendulum():
    def H(q, p, t, w):
        return p[0] ** 2 / 2 + w ** 2 * (1 - ca.cos(q[0]))
    return HamiltonianSystem(H, 1, {"w": 1.3}, name="pendulum_w_events")


def _oscillator2():
    def H(q, p, t, a, b):
        return (p[0] ** 2 + p[1] ** 2) / 2 + a * q[0] ** 2 / 2 + b * q[1] ** 2 / 2 \
            + q[0] ** 2 * q[1] ** 2 / 4
    return HamiltonianSystem(H, 2, {"a": 1.0, "b": 2.0}, name="coupled_events")


PENDULUM, COUPLED = _pendulum(), _oscillator2()


def _crossing(t, q, p):
    return q[0] - 0.3


def _run(system, q0, p0, params, events, t_span=(0.0, 8.0), tau0=0.05, derivatives=NAMES):
    return march(system, q0, p0, t_span, tau0=tau0, params=params, accuracy=None,
                 output=Output(events=events), derivatives=derivatives)


def _differences(system, q0, p0, params, events, index=0, **kwargs):
    """Fourth-order central differences of the crossing times, by input name; each input's
    step relative to its size in the problem (the largest |q|, |p| the march reached, the
    parameter's value)."""
    base = {"q0": np.asarray(q0, float), "p0": np.asarray(p0, float),
            "params": np.array([params[k] for k in system.params], float)}
    sol = _run(system, q0, p0, params, events, derivatives=None, **kwargs)
    scales = {"q0": np.max(np.abs(sol.q), axis=0), "p0": np.max(np.abs(sol.p), axis=0),
              "params": np.abs(base["params"])}
    found = {}
    for name, value in base.items():
        columns = []
        for j in range(value.size):
            h = RELATIVE_STEP * scales[name][j]
            times = []
            for shift in (2.0, 1.0, -1.0, -2.0):
                moved = {k: v.copy() for k, v in base.items()}
                moved[name][j] += shift * h
                sol = _run(system, moved["q0"], moved["p0"],
                           dict(zip(system.params, moved["params"], strict=True)), events,
                           derivatives=None, **kwargs)
                times.append(sol.t_events[index])
            columns.append((8 * (times[1] - times[2]) - (times[0] - times[3])) / (12 * h))
        found[name] = np.stack(columns, axis=1)
    return found


@pytest.mark.parametrize("scheme_tau0", [0.05, 0.2])
def test_pendulum_event_times_match_differences(scheme_tau0):
    sol = _run(PENDULUM, [1.0], [0.0], {"w": 1.3}, _crossing, tau0=scheme_tau0)
    found = sol.derivatives.events[0]
    assert sol.t_events[0].size == 3
    assert found.times["q0"].shape == (3, 1) and found.times["params"].shape == (3, 1)
    assert found.states["p0"].shape == (3, 2, 1)
    assert not found.ill_conditioned.any() and np.all(found.transversality > 0.1)
    reference = _differences(PENDULUM, [1.0], [0.0], {"w": 1.3}, _crossing, tau0=scheme_tau0)
    for name in NAMES:
        size = np.max(np.abs(reference[name]))
        assert np.max(np.abs(found.times[name] - reference[name])) <= TOLERANCE * size, name


def test_state_at_crossing_derivative_keeps_the_event_function_zero():
    """g(z(t*)) = 0 for every input: the crossing state's derivative is tangent to the
    surface, g_z . dz(t*) = 0 (here dq(t*) = 0), and its p row matches differences."""
    sol = _run(PENDULUM, [1.0], [0.0], {"w": 1.3}, _crossing)
    found = sol.derivatives.events[0]
    for name in NAMES:
        assert np.max(np.abs(found.states[name][:, 0, :])) <= 1e-9


def test_two_degrees_of_freedom_and_a_relabelling():
    """A coupled oscillator, the event on q[1]; with the coordinates swapped (the Hamiltonian's
    parameters swapped with them) the same crossings, derivatives permuted."""
    def on_second(t, q, p):
        return q[1] - 0.1
    on_second.direction = 1

    def on_first(t, q, p):
        return q[0] - 0.1
    on_first.direction = 1

    def swapped_H(q, p, t, a, b):
        return (p[0] ** 2 + p[1] ** 2) / 2 + b * q[0] ** 2 / 2 + a * q[1] ** 2 / 2 \
            + q[0] ** 2 * q[1] ** 2 / 4
    swapped = HamiltonianSystem(swapped_H, 2, {"a": 1.0, "b": 2.0}, name="coupled_swapped")
    q0, p0, params = [0.5, 0.2], [0.1, 0.3], {"a": 1.0, "b": 2.0}
    sol = _run(COUPLED, q0, p0, params, on_second, t_span=(0.0, 9.0))
    found = sol.derivatives.events[0]
    assert sol.t_events[0].size >= 2
    reference = _differences(COUPLED, q0, p0, params, on_second, t_span=(0.0, 9.0))
    for name in NAMES:
        size = np.max(np.abs(reference[name]))
        assert np.max(np.abs(found.times[name] - reference[name])) <= TOLERANCE * size, name
    other = _run(swapped, q0[::-1], p0[::-1], params, on_first, t_span=(0.0, 9.0))
    assert np.allclose(other.t_events[0], sol.t_events[0], rtol=0, atol=1e-12)
    moved = other.derivatives.events[0].times
    for name in ("q0", "p0"):
        assert np.allclose(moved[name][:, ::-1], found.times[name], rtol=0, atol=1e-9)
    assert np.allclose(moved["params"], found.times["params"], rtol=0, atol=1e-9)


def test_time_offset_gives_the_same_derivatives():
    """An autonomous system marched from t0 = 3.7: crossings shifted, derivatives the same."""
    sol = _run(PENDULUM, [1.0], [0.0], {"w": 1.3}, _crossing)
    later = _run(PENDULUM, [1.0], [0.0], {"w": 1.3}, _crossing, t_span=(3.7, 11.7))
    assert np.allclose(later.t_events[0] - 3.7, sol.t_events[0], rtol=0, atol=1e-12)
    for name in NAMES:
        a, b = sol.derivatives.events[0].times[name], later.derivatives.events[0].times[name]
        assert np.max(np.abs(a - b)) <= 1e-9 * np.max(np.abs(a)), name


def test_time_units_scale_the_derivatives():
    """H scaled by c (time in units 1/c): crossings at t/c; dt*/dq0 scales by 1/c."""
    c = 2.0

    def H(q, p, t, w):
        return c * (p[0] ** 2 / 2 + w ** 2 * (1 - ca.cos(q[0])))
    fast = HamiltonianSystem(H, 1, {"w": 1.3}, name="pendulum_w_fast")
    sol = _run(PENDULUM, [1.0], [0.0], {"w": 1.3}, _crossing, tau0=0.05,
               derivatives=("q0", "p0"))
    other = _run(fast, [1.0], [0.0], {"w": 1.3}, _crossing, t_span=(0.0, 4.0), tau0=0.025,
                 derivatives=("q0", "p0"))
    assert np.allclose(other.t_events[0] * c, sol.t_events[0], rtol=0, atol=1e-9)
    for name in ("q0", "p0"):
        a, b = sol.derivatives.events[0].times[name], other.derivatives.events[0].times[name]
        assert np.max(np.abs(b * c - a)) <= 1e-7 * np.max(np.abs(a)), name


def test_a_crossing_at_a_tangency_is_refused_not_passed_off():
    """g = q - c crossed 3.8e-4 after the turning point q = 1 of the pendulum started there at
    rest, c = 1 - 1e-7: q' is 5e-4, p' is 1.4 (transversality 4.7e-4, measured); the crossing's
    derivatives are nan and flagged. A crossing away from it keeps its numbers."""
    def grazing(t, q, p):
        return q[0] - (1.0 - 1e-7)
    grazing.direction = -1

    sol = _run(PENDULUM, [1.0], [0.0], {"w": 1.3}, [grazing, _crossing], t_span=(0.0, 3.0))
    near, clean = sol.derivatives.events
    assert sol.t_events[0].size >= 1 and sol.t_events[0][0] < 1e-3
    assert near.transversality[0] < TANGENCY and near.ill_conditioned[0]
    assert np.isnan(near.times["q0"][0]).all() and np.isnan(near.states["params"][0]).all()
    assert np.all(np.isnan(near.times["p0"][:, 0]) == near.ill_conditioned)
    assert not clean.ill_conditioned.any() and np.isfinite(clean.times["q0"]).all()


def test_no_events_no_event_derivatives_and_events_alone_suffice():
    sol = march(PENDULUM, [1.0], [0.0], (0.0, 2.0), tau0=0.05, accuracy=None,
                output=Output(t_eval=[1.0]), derivatives="q0")
    assert sol.derivatives.events is None
    sol = _run(PENDULUM, [1.0], [0.0], {"w": 1.3}, _crossing, derivatives="p0")
    assert sol.t_eval is None and set(sol.derivatives.events[0].times) == {"p0"}


def test_no_crossing_gives_empty_rows():
    def never(t, q, p):
        return q[0] - 5.0
    sol = _run(PENDULUM, [1.0], [0.0], {"w": 1.3}, never, t_span=(0.0, 1.0))
    found = sol.derivatives.events[0]
    assert found.times["q0"].shape == (0, 1) and found.states["params"].shape == (0, 2, 1)


def test_bad_inputs_refused_before_work():
    with pytest.raises(InputError, match="give output=Output"):
        march(PENDULUM, [1.0], [0.0], (0.0, 1.0), tau0=0.05, derivatives="q0")
    with pytest.raises(InputError, match="events\\[0\\] must be a function"):
        march(PENDULUM, [1.0], [0.0], (0.0, 1.0), tau0=0.05, derivatives="q0",
              output=Output(events=[3.0]))


@settings(max_examples=25, deadline=None)
@given(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0), st.floats(-1.0, 1.0),
       st.floats(0.1, 3.0))
def test_partials_and_slope_read_any_rows(a, b, c, scale):
    """The readers of g and of the interpolant on drawn rows: a linear g's partials are its
    coefficients, and the slope of a cubic's Hermite interpolant is the cubic's slope."""
    def g(t, q, p):
        return a * t + b * q[0] + c * p[0]
    event = check_events(g)[0]
    times = np.array([0.3, 1.1]) * scale
    states = np.array([[0.2, -0.4], [1.5, 0.7]]) * scale
    g_t, g_z = event_partials(event, times, states, np.array([scale, scale, scale]))
    assert np.allclose(g_t, a, atol=1e-10) and np.allclose(g_z, [[b, c]] * 2, atol=1e-10)
    t = np.array([0.0, 0.4, 1.0]) * scale
    z = np.stack([t ** 3, -t ** 2], axis=1)
    f = np.stack([3 * t ** 2, -2 * t], axis=1)
    at = np.array([0.1, 0.7]) * scale
    assert np.allclose(hermite_slope(t, z, f, at), np.stack([3 * at ** 2, -2 * at], 1),
                       atol=1e-10 * (1 + scale ** 2))
