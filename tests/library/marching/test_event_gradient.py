"""What issue 47 left open, closed: the event times' own check (``derivative_check.event_check``),
reverse mode on event times (``gradient(sol, {"event_times": ...})``), ``gradient`` on every
solution kind (a grid solution dispatched to its family's reverse mode), and a march from ``v0``
differentiated in ``v0`` (``velocity_start.py``). Each with what it refuses by name and
metamorphic checks: a time offset, a change of time units, relabelled coordinates."""

import functools

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from ddvp_nlp import (
    AtEnergy,
    HamiltonianSystem,
    InputError,
    LagrangianSystem,
    Output,
    gradient,
    march,
    solve_bvp,
    solve_periodic,
)
from ddvp_nlp.solvers import bvp_gradient, orbit_gradient, transfer_gradient
from ddvp_nlp.solvers.marching.derivative_check import STEP, TRUNCATION, event_check
from ddvp_nlp.solvers.marching.event_derivatives import (
    GRAZING,
    TANGENCY,
    EventDerivatives,
    transversality_of,
)

NAMES = ("q0", "p0", "params")
V_NAMES = ("q0", "v0", "params")
# Reverse equals forward: both are the same chain of the same Jacobians (issue 47's 1e-10).
AGREEMENT = 1e-10
# Against central differences of re-marched crossing times and states, relative step 1e-6: the
# noise is 1e-14 sqrt(N) / 1e-6 for the ~200 steps here, below 1e-6 of the derivative.
RELATIVE_STEP = 1e-6
TOLERANCE = 1e-6


def _pendulum(c=1.0, name="pendulum_events_gradient"):
    def H(q, p, t, w):
        return c * (p[0] ** 2 / 2 + w ** 2 * (1 - ca.cos(q[0])))
    return HamiltonianSystem(H, 1, {"w": 1.3}, name=name)


def _coupled(swap=False):
    def H(q, p, t, a, b):
        x, y = (q[1], q[0]) if swap else (q[0], q[1])
        return (p[0] ** 2 + p[1] ** 2) / 2 + a * x ** 2 / 2 + b * y ** 2 / 2 + x ** 2 * y ** 2 / 4
    return HamiltonianSystem(H, 2, {"a": 1.0, "b": 2.0},
                             name="coupled_events_gradient" + ("_swapped" if swap else ""))


def _lagrangian(swap=False, c=1.0):
    def L(q, v, t, w, k):
        x, y, vx, vy = (q[1], q[0], v[1], v[0]) if swap else (q[0], q[1], v[0], v[1])
        return c * ((vx ** 2 + 2 * vy ** 2) / 2 + 0.3 * vx * vy * ca.cos(y)
                    - w ** 2 * (1 - ca.cos(x)) - k * y ** 2 / 2)
    return LagrangianSystem(L, 2, {"w": 1.3, "k": 0.7}, name="lagrangian_v0" + (
        "_swapped" if swap else "") + ("" if c == 1.0 else "_scaled"))


PENDULUM, COUPLED, LAGRANGIAN = _pendulum(), _coupled(), _lagrangian()


def crossing(t, q, p):
    return q[0] - 0.3


def on_first(t, q, p):
    return q[0] - 0.1


def on_second(t, q, p):
    return q[1] - 0.1


on_first.direction = on_second.direction = 1


def _march(system=PENDULUM, q0=(1.0,), p0=(0.0,), *, t_span=(0.0, 8.0), t_eval=(1.0, 5.0),
           events=crossing, derivatives=NAMES, tau0=0.05, params=None, v0=None):
    start = {"v0": list(v0)} if v0 is not None else {"p0": list(p0)}
    return march(system, list(q0), t_span=t_span, tau0=tau0, params=params, accuracy=None,
                 output=Output(t_eval=t_eval, events=events), derivatives=derivatives, **start)


@functools.cache
def _pendulum_march():
    return _march()


def _contracted(sol, states, event_times, name):
    """The forward derivatives contracted with the cotangent."""
    total = 0.0
    if states is not None:
        total = total + np.einsum("ij,ijk->k", states, sol.derivatives[name])
    for c, record in zip(event_times or (), sol.derivatives.events or (), strict=False):
        total = total + c @ record.times[name]
    return total


def _agree(found, sol, states, event_times, name):
    """Reverse equals forward to AGREEMENT of the contraction's scale, ``sum |c| max |D|``
    (the contraction itself can cancel: on the Lagrangian march below, 2.2e-10 of the
    contraction's size is 4e-11 of that scale; both modes compose the step maps 32 at a time,
    which there differs from the step-by-step chain by 1.8e-10 (forward) and 2.4e-10
    (reverse) of the derivative, measured)."""
    forward = _contracted(sol, states, event_times, name)
    scale = 0.0 if states is None else np.sum(np.abs(states)) * np.max(
        np.abs(sol.derivatives[name]))
    for c, record in zip(event_times or (), sol.derivatives.events or (), strict=False):
        scale += np.sum(np.abs(c)) * np.max(np.abs(np.nan_to_num(record.times[name])))
    assert found.shape == forward.shape
    assert np.max(np.abs(found - forward)) <= AGREEMENT * max(scale, 1e-300)


# --- 1. the event times' own check -------------------------------------------------------


def test_event_times_check_agrees_beside_the_states_check():
    sol = _pendulum_march()
    record = sol.derivatives.events[0]
    assert sol.derivatives.check.verdict == "agrees"
    assert record.check.verdict == "agrees" and record.check.error <= 1e-6
    assert not record.check.ill_conditioned and record.check.reason == ""
    # the same direction as the states' check: the two share their pair of marches
    for name in NAMES:
        assert np.array_equal(record.check.direction[name],
                              sol.derivatives.check.direction[name])
    assert TRUNCATION < record.check.tolerance < 2 * TRUNCATION


def test_event_times_check_with_events_alone_and_two_events():
    sol = _march(COUPLED, (0.5, 0.2), (0.1, 0.3), t_span=(0.0, 9.0), t_eval=None,
                 events=[on_first, on_second])
    assert sol.derivatives.check.verdict == "not checked"  # no output time: nothing to check
    assert [record.check.verdict for record in sol.derivatives.events] == ["agrees"] * 2


def _fake_record(times, weights=None):
    K = times.size
    return EventDerivatives({"q0": np.ones((K, 1))}, {"q0": np.zeros((K, 2, 1))},
                            np.ones(K), np.zeros(K, bool),
                            np.ones((K, 2)) if weights is None else weights)


def test_event_check_verdicts_on_made_up_crossings():
    """``event_check`` alone: a quotient equal to the derivative agrees, a wrong one
    disagrees, a changed count of crossings and all-tangent crossings are not checked."""
    times = np.array([1.0, 2.0])
    base, direction = {"q0": np.array([1.0])}, {"q0": np.array([0.5])}

    def moved_by(slope, extra=0):
        def run(inputs):
            shift = (inputs["q0"][0] - 1.0) * slope
            return None, [np.concatenate([times + shift, np.ones(extra)])]
        return run
    args = (times, np.linspace(0.0, 3.0, 31), np.ones(2), (False, 0.01))
    assert event_check(moved_by(1.0), base, direction, _fake_record(times), 0, *args).verdict \
        == "agrees"
    wrong = event_check(moved_by(1.01), base, direction, _fake_record(times), 0, *args)
    assert wrong.verdict == "disagrees" and wrong.error > wrong.tolerance
    counted = event_check(moved_by(1.0, extra=1), base, direction, _fake_record(times), 0, *args)
    assert counted.verdict == "not checked" and "crossed 3 and 3 times, against 2" in \
        counted.reason
    tangent = _fake_record(times)
    tangent.times["q0"][:] = np.nan
    assert "tangency" in event_check(moved_by(1.0), base, direction, tangent, 0,
                                     *args).reason


def test_a_grazing_crossing_is_flagged_with_its_numbers_kept():
    """g = q - c crossed near the pendulum's turning point q = 1 (started there at rest):
    c = 1 - 1.1e-5 puts the transversality between TANGENCY and GRAZING (q' is 5.7e-3 there,
    the scaled slope about 1.1): the numbers are kept, flagged, and the check says so."""
    def grazing(t, q, p):
        return q[0] - (1.0 - 1.1e-5)
    grazing.direction = -1
    sol = _march(events=[grazing, crossing], t_span=(0.0, 3.0), t_eval=None)
    near, clean = sol.derivatives.events
    assert TANGENCY <= near.transversality[0] < GRAZING
    assert near.ill_conditioned[0] and np.isfinite(near.times["q0"][0]).all()
    assert near.check.ill_conditioned
    assert not clean.ill_conditioned.any() and not clean.check.ill_conditioned


def test_a_component_without_a_scale_gets_no_made_up_one():
    """A state component whose scale is 0 enters the transversality's size by its own
    |g_z_j z'_j|: at most 1 (Cauchy-Schwarz), here exactly 1. A unit scale put in its place
    (the old floor) gave 4.7, past the bound."""
    g_t, g_z = np.zeros(1), np.array([[1.0, 5.0]])
    slope = np.array([[2.0, 3.0]])
    rate = g_t + np.sum(g_z * slope, axis=1)
    found = transversality_of(g_t, g_z, slope, rate, np.array([1.0, 0.0]))
    assert found == pytest.approx([1.0])
    assert transversality_of(g_t, g_z, slope, rate, np.array([1.0, 1.0]))[0] < 1.0
    moving = transversality_of(g_t, g_z, slope, rate, np.array([2.0, 0.5]))
    assert 0 < moving[0] <= 1.0


# --- 2. reverse mode on event times ------------------------------------------------------


def test_event_time_gradient_equals_forward_and_its_check_agrees():
    sol = _pendulum_march()
    rng = np.random.default_rng(5)
    states, events = rng.normal(size=(2, 2)), [rng.normal(size=sol.t_events[0].size)]
    g = gradient(sol, {"states": states, "event_times": events})
    for name in NAMES:
        _agree(g[name], sol, states, events, name)
    assert g.check.verdict == "agrees"
    alone = gradient(sol, {"event_times": events}, check=False)
    for name in NAMES:
        _agree(alone[name], sol, None, events, name)
    assert alone.check is None


@settings(max_examples=20, deadline=None)
@given(hnp.arrays(float, (2, 2), elements=st.floats(-1e3, 1e3)),
       hnp.arrays(float, (3,), elements=st.floats(-1e3, 1e3)))
def test_drawn_cotangents_reverse_equals_forward(states, events):
    sol = _pendulum_march()
    assert sol.t_events[0].size == 3
    g = gradient(sol, {"states": states, "event_times": [events]}, check=False)
    for name in NAMES:
        forward = _contracted(sol, states, [events], name)
        scale = (np.sum(np.abs(states)) * np.max(np.abs(sol.derivatives[name]))
                 + np.sum(np.abs(events)) * np.max(np.abs(sol.derivatives.events[0]
                                                          .times[name])))
        assert np.max(np.abs(g[name] - forward)) <= AGREEMENT * max(scale, 1e-300)


def test_two_events_two_degrees_and_a_relabelling():
    """Two event functions on the coupled oscillator; the coordinates swapped (events and the
    Hamiltonian with them): the same gradient, q0 and p0 permuted."""
    q0, p0, span = (0.5, 0.2), (0.1, 0.3), (0.0, 9.0)
    sol = _march(COUPLED, q0, p0, t_span=span, t_eval=None, events=[on_first, on_second])
    events = [np.linspace(1.0, -1.0, t.size) for t in sol.t_events]
    g = gradient(sol, {"event_times": events}, check=False)
    for name in NAMES:
        _agree(g[name], sol, None, events, name)
    other = _march(_coupled(swap=True), q0[::-1], p0[::-1], t_span=span, t_eval=None,
                   events=[on_second, on_first])
    h = gradient(other, {"event_times": events}, check=False)
    size = max(np.max(np.abs(g[name])) for name in NAMES)
    for name in ("q0", "p0"):
        assert np.max(np.abs(h[name][::-1] - g[name])) <= 1e-9 * size
    assert np.max(np.abs(h["params"] - g["params"])) <= 1e-9 * size


def test_event_gradient_under_a_time_offset_and_time_units():
    """From t0 = 3.7 (autonomous): the same gradient. H scaled by c (time in units 1/c, the
    first step and span with it): crossing times / c, their gradient in q0, p0 / c."""
    sol = _pendulum_march()
    events = [np.array([1.0, -2.0, 0.5])]
    g = gradient(sol, {"event_times": events}, check=False)
    later = _march(t_span=(3.7, 11.7), t_eval=(4.7, 8.7))
    h = gradient(later, {"event_times": events}, check=False)
    c = 2.0
    fast = _march(_pendulum(c, "pendulum_events_fast"), t_span=(0.0, 4.0), t_eval=(0.5, 2.5),
                  tau0=0.05 / c)
    f = gradient(fast, {"event_times": events}, check=False)
    for name in NAMES:
        size = np.max(np.abs(g[name]))
        assert np.max(np.abs(h[name] - g[name])) <= 1e-9 * size, name
    for name in ("q0", "p0"):
        assert np.max(np.abs(f[name] * c - g[name])) <= 1e-7 * np.max(np.abs(g[name])), name


def test_bad_event_cotangents_are_refused_by_name():
    sol = _pendulum_march()
    cases = [
        ({"event_time": [np.zeros(3)]}, "'states' and/or 'event_times'"),
        ({}, "'states' and/or 'event_times'"),
        ({"event_times": np.zeros(3)}, r"must be a list of 1 arrays"),
        ({"event_times": [np.zeros(3), np.zeros(3)]}, r"must be a list of 1 arrays"),
        ({"event_times": [np.zeros(2)]}, r"\[0\] must have shape \(3,\)"),
        ({"event_times": [[0.0, np.inf, 0.0]]},
         r"cotangent\['event_times'\]\[0\] must be finite, got inf at \[1\]"),
        ({"event_times": [["a", "b", "c"]]}, r"\[0\] must be 3 real numbers"),
        ({"states": np.zeros((3, 2))}, r"must have shape \(len\(sol.t_eval\), 2n\)"),
    ]
    for cotangent, message in cases:
        with pytest.raises(InputError, match=message):
            gradient(sol, cotangent)
    plain = march(PENDULUM, [1.0], [0.0], (0.0, 8.0), tau0=0.05, accuracy=None,
                  output=Output(t_eval=[1.0], events=crossing))
    with pytest.raises(InputError, match="needs the march's event derivatives"):
        gradient(plain, {"event_times": [np.zeros(plain.t_events[0].size)]})
    with pytest.raises(InputError, match="takes check, steps, compilation, got system="):
        gradient(sol, np.zeros((2, 2)), system=PENDULUM)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.one_of(
    st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=2)),
             max_size=4),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=3, max_size=3),
    st.lists(st.text(max_size=2), min_size=3, max_size=3)), max_size=3))
def test_the_event_cotangent_reader_answers_any_value(drawn):
    """Whatever is given as ``event_times``: a gradient when it is one list of 3 finite
    numbers (as numpy reads them), else an InputError naming ``cotangent['event_times']``,
    never another error."""
    sol = _pendulum_march()
    try:  # what numpy reads as 3 finite numbers ("1" included) is a valid cotangent
        valid = len(drawn) == 1 and bool(np.all(np.isfinite(np.asarray(drawn[0], float)))) \
            and len(drawn[0]) == 3
    except ValueError:
        valid = False
    try:
        g = gradient(sol, {"event_times": drawn}, check=False)
    except InputError as error:
        assert not valid and "cotangent['event_times']" in str(error)
    else:
        assert valid
        # a finite cotangent near the largest double may overflow the product (IEEE's inf,
        # drawn once from the replayed example [[0, 0, 2.58e305]]); below that, finite
        if np.max(np.abs(np.asarray(drawn[0], float))) < 1e290:
            assert all(np.all(np.isfinite(value)) for value in g.values())


def test_a_cotangent_on_a_tangent_crossing_gives_nan_not_a_number():
    def grazing(t, q, p):
        return q[0] - (1.0 - 1e-7)
    grazing.direction = -1
    sol = _march(events=[grazing], t_span=(0.0, 3.0), t_eval=None)
    assert np.isnan(sol.derivatives.events[0].weights[0]).all()
    count = sol.t_events[0].size
    g = gradient(sol, {"event_times": [np.eye(count)[0]]})
    assert all(np.isnan(value).all() for value in g.values())
    assert g.check.verdict == "not checked" and "tangency" in g.check.reason


# --- 3. gradient() on grid solutions -----------------------------------------------------


def test_gradient_dispatches_to_each_grid_family():
    rng = np.random.default_rng(7)
    bvp = solve_bvp(PENDULUM, [0.1], [0.5], (0.0, 2.0), nodes=41)
    c = {"p_end": rng.normal(size=1), "nodes": rng.normal(size=(41, 3))}
    a, b = gradient(bvp, c), bvp_gradient(bvp, c)
    assert type(a) is type(b) and a.keys() == b.keys()
    for name in a:
        assert np.array_equal(a[name], b[name])
    transfer = solve_bvp(PENDULUM, [0.1], [0.5], AtEnergy(1.0), nodes=41)
    c = {"transfer_time": 1.0, "p_start": [0.5]}
    a, b = gradient(transfer, c), transfer_gradient(transfer, c)
    assert all(np.array_equal(a[name], b[name]) for name in b) and a.keys() == b.keys()
    orbit = solve_periodic(PENDULUM, energy=0.5, nodes=41)
    a = gradient(orbit, {"period": 1.0}, system=PENDULUM)
    b = orbit_gradient(orbit, {"period": 1.0}, system=PENDULUM)
    assert all(np.array_equal(a[name], b[name]) for name in b) and a.keys() == b.keys()
    with pytest.raises(InputError, match="takes compilation, got check=False"):
        gradient(bvp, {"p_end": [1.0]}, check=False)
    with pytest.raises(InputError, match="needs system="):
        gradient(orbit, {"period": 1.0})
    with pytest.raises(InputError, match="takes system, params, integrals, got steps="):
        gradient(orbit, {"period": 1.0}, system=PENDULUM, steps=None)
    with pytest.raises(InputError, match="must be a mapping"):
        gradient(bvp, np.zeros(3))
    with pytest.raises(InputError, match="march, solve_bvp or solve_periodic, got object"):
        gradient(object(), np.zeros(3))


# --- 4. a march from v0 ------------------------------------------------------------------


LAG_Q0, LAG_V0, LAG_PARAMS = (0.4, -0.2), (0.3, 0.5), {"w": 1.3, "k": 0.7}


def _v0_march(system=LAGRANGIAN, q0=LAG_Q0, v0=LAG_V0, params=LAG_PARAMS, **kwargs):
    kwargs.setdefault("events", on_first)
    return _march(system, q0, v0=v0, params=params, t_span=(0.0, 6.0), t_eval=(1.5, 5.0),
                  derivatives=V_NAMES, **kwargs)


@functools.cache
def _lagrangian_march():
    return _v0_march()


def test_v0_derivatives_match_differences_of_marches_from_v0():
    sol = _lagrangian_march()
    assert sol.derivatives["v0"].shape == (2, 4, 2) and set(sol.derivatives) == set(V_NAMES)
    assert sol.derivatives.check.verdict == "agrees"
    assert sol.derivatives.events[0].check.verdict == "agrees"
    base = {"q0": np.array(LAG_Q0), "v0": np.array(LAG_V0),
            "params": np.array(list(LAG_PARAMS.values()))}
    for name, value in base.items():
        for j in range(value.size):
            h = RELATIVE_STEP * max(abs(value[j]), 0.1)
            found = []
            for sign in (1.0, -1.0):
                moved = {k: v.copy() for k, v in base.items()}
                moved[name][j] += sign * h
                other = march(LAGRANGIAN, moved["q0"], v0=moved["v0"], t_span=(0.0, 6.0),
                              tau0=0.05, params=dict(zip(LAG_PARAMS, moved["params"], strict=True)),
                              accuracy=None, output=Output(t_eval=(1.5, 5.0), events=on_first))
                found.append((other.z_eval, other.t_events[0]))
            dz = (found[0][0] - found[1][0]) / (2 * h)
            dt = (found[0][1] - found[1][1]) / (2 * h)
            D, T = sol.derivatives[name][:, :, j], sol.derivatives.events[0].times[name][:, j]
            assert np.max(np.abs(D - dz)) <= TOLERANCE * np.max(np.abs(dz)), (name, j)
            assert np.max(np.abs(T - dt)) <= TOLERANCE * np.max(np.abs(dt)), (name, j)


def test_v0_gradient_is_in_v0_and_equals_forward():
    sol = _lagrangian_march()
    rng = np.random.default_rng(11)
    states, events = rng.normal(size=(2, 4)), [rng.normal(size=sol.t_events[0].size)]
    g = gradient(sol, {"states": states, "event_times": events})
    assert set(g) == set(V_NAMES) and g.check.verdict == "agrees"
    for name in V_NAMES:
        _agree(g[name], sol, states, events, name)
    plain = march(LAGRANGIAN, list(LAG_Q0), v0=list(LAG_V0), t_span=(0.0, 6.0), tau0=0.05,
                  params=LAG_PARAMS, accuracy=None, output=Output(t_eval=(1.5, 5.0)))
    h = gradient(plain, states, check=False)
    for name in V_NAMES:
        _agree(h[name], sol, states, None, name)


def test_v0_derivatives_relabelled_and_offset_in_time():
    """The coordinates swapped (the Lagrangian with them): rows and columns permuted. From
    t0 = 2.5 (autonomous): the same derivatives."""
    sol = _lagrangian_march()
    swapped = _v0_march(_lagrangian(swap=True), LAG_Q0[::-1], LAG_V0[::-1],
                        events=on_second)
    rows = [1, 0, 3, 2]
    for name in ("q0", "v0"):
        other = swapped.derivatives[name][:, rows][:, :, ::-1]
        assert np.max(np.abs(other - sol.derivatives[name])) <= \
            1e-9 * np.max(np.abs(sol.derivatives[name])), name
    later = march(LAGRANGIAN, list(LAG_Q0), v0=list(LAG_V0), t_span=(2.5, 8.5), tau0=0.05,
                  params=LAG_PARAMS, accuracy=None, output=Output(t_eval=(4.0, 7.5)),
                  derivatives=V_NAMES)
    for name in V_NAMES:
        assert np.max(np.abs(later.derivatives[name] - sol.derivatives[name])) <= \
            1e-9 * np.max(np.abs(sol.derivatives[name])), name


def test_v0_derivatives_in_scaled_units_of_the_action():
    """L scaled by c = 3: the same motion (the discrete Euler-Lagrange and energy equations are
    homogeneous in L), momenta times c: the q rows of every derivative unchanged, the p rows
    times c; the crossing times' derivatives unchanged."""
    c = 3.0
    sol, other = _lagrangian_march(), _v0_march(_lagrangian(c=c))
    assert np.allclose(other.t_events[0], sol.t_events[0], rtol=0, atol=1e-12)
    for name in V_NAMES:
        a, b = sol.derivatives[name], other.derivatives[name]
        size = np.max(np.abs(a))
        assert np.max(np.abs(b[:, :2] - a[:, :2])) <= 1e-9 * size, name
        assert np.max(np.abs(b[:, 2:] - c * a[:, 2:])) <= 1e-9 * c * size, name
        a, b = sol.derivatives.events[0].times[name], other.derivatives.events[0].times[name]
        assert np.max(np.abs(b - a)) <= 1e-9 * np.max(np.abs(a)), name


def test_v0_and_p0_refused_where_they_are_not_the_start():
    with pytest.raises(InputError, match="'p0' is not an input of a march started from v0"):
        march(LAGRANGIAN, list(LAG_Q0), v0=list(LAG_V0), t_span=(0.0, 1.0), tau0=0.05,
              output=Output(t_eval=[0.5]), derivatives=("q0", "p0"))
    with pytest.raises(InputError, match="'v0' needs a march started from v0"):
        march(LAGRANGIAN, list(LAG_Q0), [0.1, 0.2], (0.0, 1.0), tau0=0.05,
              output=Output(t_eval=[0.5]), derivatives="v0")
    with pytest.raises(InputError, match="'v0' needs a march started from v0"):
        march(PENDULUM, [1.0], [0.0], (0.0, 1.0), tau0=0.05,
              output=Output(t_eval=[0.5]), derivatives=("v0", "params"))
    with pytest.raises(InputError, match="choose from|must be"):
        march(PENDULUM, [1.0], [0.0], (0.0, 1.0), tau0=0.05,
              output=Output(t_eval=[0.5]), derivatives="w0")


def test_check_step_constant_is_the_grazing_bound():
    """GRAZING is where the check's quotient, off by h^2 / transversality^4 of the derivative
    near a tangency, reaches the check's allowance (event_derivatives.py's docstring)."""
    assert STEP ** 2 / GRAZING ** 4 == pytest.approx(TRUNCATION)
