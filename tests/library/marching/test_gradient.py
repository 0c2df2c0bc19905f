"""Reverse mode of a march's derivatives (``solvers/marching/adjoint.py``): ``gradient(sol,
cotangent)`` equals the cotangent contracted with the forward derivatives, on drawn cotangents
and on Kepler marches from e = 0.3 to 0.9; ``derivatives_mode``; the derivative's own check
(``derivative_check.py``); the cotangent reader and what is refused by name; time offsets and
units; ``march_ensemble`` with derivatives."""

import re
import warnings

import casadi as ca
import numpy as np
import pytest
from helpers.parametrized import kepler_mu, pendulum_w
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from ddvp_nlp import (
    DerivativeOptions,
    HamiltonianSystem,
    InputError,
    Output,
    StepControl,
    gradient,
    march,
)
from ddvp_nlp.solvers.marching import march_ensemble
from ddvp_nlp.solvers.marching.adjoint import check_cotangent, reverse_derivatives
from ddvp_nlp.solvers.marching.derivative_check import (
    MONITOR_LIMIT,
    NEAR,
    check_record,
    conditioning,
    remarch_function,
)
from ddvp_nlp.solvers.marching.derivatives import march_derivatives

NAMES = ("q0", "p0", "params")
# Reverse equals forward (issue 47): both are the same chain of the same Jacobians, composed in
# blocks of 32 steps the other way round; measured 1e-15 (fixed rule) to 2e-11 (vddvp, 11000
# steps) of the contraction's size.
AGREEMENT = 1e-10




PENDULUM, KEPLER = pendulum_w(), kepler_mu()


def kepler_start(e):
    """From the apocentre of the ``mu = 1``, ``a = 1`` orbit of eccentricity ``e`` (period
    2 pi, pericentre at t = pi)."""
    return [1 + e, 0.0], [0.0, np.sqrt((1 - e) / (1 + e))]


# (e, scheme, tau0, t_end, t_eval): vddvp up to e = 0.7, fixed above (issue 47)
KEPLER_CASES = {
    "e=0.0 vddvp": (0.0, "vddvp", 0.01, 7.0, [0.5, 3.0, 6.5]),
    "e=0.3 vddvp": (0.3, "vddvp", 0.01, 7.0, [0.5, 3.0, 3.3, 6.5]),
    "e=0.7 vddvp": (0.7, "vddvp", 0.001, 4.5, [0.0, 0.5, 3.0, 3.14, 3.3, 4.2]),
    "e=0.9 fixed": (0.9, "fixed", 0.002, 4.0, [0.5, 3.0, 3.1, 3.3, 3.9]),
}


def kepler_march(name, derivatives=NAMES, mode=None):
    e, scheme, tau0, t_end, t_eval = KEPLER_CASES[name]
    q0, p0 = kepler_start(e)
    return march(KEPLER, q0, p0, (0.0, t_end), tau0=tau0, scheme=scheme, params={"mu": 1.0},
                 accuracy=None, output=Output(t_eval=t_eval),
                 derivatives=derivatives if mode is None else DerivativeOptions(derivatives, mode))


def contracted(cotangent, derivatives):
    return {name: np.einsum("ij,ijk->k", cotangent, derivatives[name]) for name in NAMES}


def relative_gap(found, expected):
    size = max(np.max(np.abs(value)) for value in expected.values())
    return max(np.max(np.abs(found[name] - expected[name])) for name in expected) / size


@pytest.mark.parametrize("name", list(KEPLER_CASES))
def test_reverse_equals_forward_on_kepler(name):
    solution = kepler_march(name)
    assert solution.success and solution.derivatives.mode == "forward"
    cotangent = np.random.default_rng(3).normal(size=solution.z_eval.shape)
    found = gradient(solution, cotangent, check=False)
    assert found.check is None
    assert relative_gap(found, contracted(cotangent, solution.derivatives)) <= AGREEMENT
    every = reverse_derivatives(KEPLER, solution.scheme, [1.0], solution.t,
                                np.hstack([solution.q, solution.p]), solution.t_eval, NAMES)
    assert relative_gap(every, solution.derivatives) <= AGREEMENT


@pytest.fixture(scope="module")
def pendulum_solution():
    return march(PENDULUM, [1.0], [0.0], (0.0, 10.0), tau0=0.05, params={"w": 1.3},
                 accuracy=None, output=Output(t_eval=[0.0, 0.3, 2.71, 6.0, 9.5]),
                 derivatives=NAMES)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(cotangent=hnp.arrays(float, (5, 2), elements=st.floats(-1e3, 1e3)))
def test_reverse_equals_forward_for_drawn_cotangents(pendulum_solution, cotangent):
    expected = contracted(cotangent, pendulum_solution.derivatives)
    found = gradient(pendulum_solution, cotangent, check=False)
    size = max(np.max(np.abs(value)) for value in expected.values())
    if size == 0.0:
        assert all(np.all(found[name] == 0.0) for name in NAMES)
        return
    assert relative_gap(found, expected) <= AGREEMENT


def test_a_march_without_derivatives_has_the_same_gradient(pendulum_solution):
    plain = march(PENDULUM, [1.0], [0.0], (0.0, 10.0), tau0=0.05, params={"w": 1.3},
                  accuracy=None, output=Output(t_eval=pendulum_solution.t_eval))
    assert plain.derivatives is None
    cotangent = np.arange(10.0).reshape(5, 2)
    one, other = gradient(plain, cotangent), gradient(pendulum_solution, cotangent)
    for name in NAMES:
        assert np.array_equal(one[name], other[name]), name
    assert one.check.verdict == "agrees", one.check


@pytest.mark.parametrize("mode", ["forward", "reverse", "auto"])
def test_the_modes_give_the_same_derivatives(mode):
    forward = kepler_march("e=0.3 vddvp", mode="forward")
    other = kepler_march("e=0.3 vddvp", mode=mode)
    # auto: 4 times x 4 rows = 16 outputs against 5 inputs: forward
    assert other.derivatives.mode == ("reverse" if mode == "reverse" else "forward")
    assert relative_gap(other.derivatives, forward.derivatives) <= AGREEMENT


def test_auto_chooses_reverse_for_few_outputs():
    # one output time: 4 outputs against 5 inputs
    solution = march(KEPLER, *kepler_start(0.3), (0.0, 3.0), tau0=0.01, accuracy=None,
                     output=Output(t_eval=[2.5]), derivatives=NAMES)
    assert solution.derivatives.mode == "reverse"
    forward = march(KEPLER, *kepler_start(0.3), (0.0, 3.0), tau0=0.01, accuracy=None,
                    output=Output(t_eval=[2.5]),
                    derivatives=DerivativeOptions(NAMES, "forward"))
    assert relative_gap(solution.derivatives, forward.derivatives) <= AGREEMENT


# --- the derivative's own check ----------------------------------------------------------------

@pytest.mark.parametrize("name", ["e=0.3 vddvp", "e=0.9 fixed"])
def test_every_derivative_carries_a_check_that_agrees(name):
    check = kepler_march(name).derivatives.check
    assert check.verdict == "agrees", check
    assert check.error <= 1e-6 and not check.ill_conditioned, check
    assert set(check.direction) == set(NAMES)


def test_the_check_catches_the_frozen_step_derivative():
    """The frozen-step derivative (what peers report: ``dtau = 0``) fed to the same check
    disagrees: on the pendulum at tau0 = 0.25 it is off by 1e-3 to 4e-3."""
    solution = march(PENDULUM, [1.0], [0.0], (0.0, 10.0), tau0=0.25, params={"w": 1.3},
                     accuracy=None, output=Output(t_eval=[0.3, 2.71, 6.0, 9.5]),
                     derivatives=NAMES)
    assert solution.derivatives.check.verdict == "agrees"
    frozen = march_derivatives(PENDULUM, solution.scheme, [1.3], solution.t,
                               np.hstack([solution.q, solution.p]), solution.t_eval, NAMES,
                               frozen_steps=True)
    remarch = remarch_function(march, PENDULUM, solution.scheme, (0.0, 10.0), 0.25, StepControl(),
                               None, solution.t_eval)
    base = {"q0": np.array([1.0]), "p0": np.array([0.0]), "params": np.array([1.3])}
    record = check_record(remarch, base, NAMES,
                          lambda v: sum(frozen[name] @ v[name] for name in NAMES),
                          solution.q, solution.p, base["params"], solution.t.size,
                          (False, 0.0))
    assert record.verdict == "disagrees" and record.error > 10 * record.tolerance, record


def test_near_a_lost_root_the_derivative_says_it_is_ill_conditioned():
    """The pendulum from the bottom at p0 = 2 (the separatrix): the energy row nearly loses its
    root near the top (the monitor warns at t = 1.51, |ln(w_k / w_k-1)| = 0.51); outputs before
    that are not flagged, outputs after it are."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        early = march(PENDULUM, [0.0], [2.0], (0.0, 3.0), tau0=0.05, accuracy=None,
                      output=Output(t_eval=[0.3]), derivatives=NAMES)
        late = march(PENDULUM, [0.0], [2.0], (0.0, 3.0), tau0=0.05, accuracy=None,
                     output=Output(t_eval=[0.3, 2.0]), derivatives=NAMES)
    assert late.march.solvability_warning is not None
    assert not early.derivatives.check.ill_conditioned
    assert early.derivatives.check.solvability_jump <= NEAR * MONITOR_LIMIT
    assert late.derivatives.check.ill_conditioned
    assert late.derivatives.check.solvability_jump > MONITOR_LIMIT


@pytest.mark.parametrize("c, expected", [
    ([1.0, 1.1, 1.2], False), ([1.0, 1.0 * np.exp(0.45)], True), ([1.0, -1.0], True),
    ([1.0, 0.0], True), ([1.0], False)])
def test_conditioning_reads_the_monitor_weights(c, expected):
    assert conditioning(np.array(c), len(c) - 1, None)[0] is expected


def test_a_warning_past_the_nodes_used_does_not_flag():
    assert not conditioning(np.ones(5), 2, {"step": 4})[0]
    assert conditioning(np.ones(5), 2, {"step": 2})[0]


# --- the cotangent and the solution: refused by name -----------------------------------------

def expect(message):
    return pytest.raises(InputError, match="^" + re.escape(message) + "$")


@pytest.mark.parametrize("cotangent, message", [
    (np.ones((4, 2)), "cotangent must have shape (len(sol.t_eval), 2n) = (5, 2), got (4, 2)"),
    (np.ones(10), "cotangent must have shape (len(sol.t_eval), 2n) = (5, 2), got (10,)"),
    (np.ones((5, 2, 1)), "cotangent must have shape (len(sol.t_eval), 2n) = (5, 2), got "
                         "(5, 2, 1)"),
    ([[1.0, np.nan]] * 5, "cotangent must be finite, got nan at [0, 1]"),
    (np.where(np.eye(5, 2) > 0, np.inf, 0.0), "cotangent must be finite, got inf at [0, 0]"),
    ("abc", "cotangent must be an array of real numbers of shape (5, 2), got 'abc'"),
])
def test_a_bad_cotangent_is_refused(pendulum_solution, cotangent, message):
    with expect(message):
        gradient(pendulum_solution, cotangent)


@settings(max_examples=40, deadline=None)
@given(shape=st.lists(st.integers(0, 6), min_size=0, max_size=3),
       fill=st.sampled_from([0.0, 1.5, -2.0, np.nan, np.inf, -np.inf]))
def test_the_cotangent_reader_accepts_exactly_finite_arrays_of_its_shape(shape, fill):
    value = np.full(shape, fill)
    good = tuple(shape) == (3, 4) and np.isfinite(fill)
    if good:
        assert np.array_equal(check_cotangent(value, 3, 4), value)
    else:
        with pytest.raises(InputError, match="^cotangent must"):
            check_cotangent(value, 3, 4)


def _plain(**options):
    span = options.pop("t_span", (0.0, 2.0))
    return march(PENDULUM, [0.5], [0.1], span, tau0=0.05, accuracy=None, **options)


@pytest.mark.parametrize("options, message", [
    ({}, "gradient is of the states at fixed times: march with output=Output(t_eval=...)"),
    ({"output": Output(t_eval=[1.0], keep_every=2)},
     "gradient is not supported for a thinned march (kept: 2 every, keep='nodes')"),
    ({"t_span": (2.0, 0.0), "output": Output(t_eval=[1.0])},
     "gradient is not supported for a backward march (t_end < t0)"),
])
def test_a_solution_it_cannot_differentiate_is_refused(options, message):
    solution = _plain(**options)
    with expect(message):
        gradient(solution, np.ones((1, 2)))


def test_a_solution_must_be_a_march():
    with expect("sol must be a Solution of march, solve_bvp or solve_periodic, got dict"):
        gradient({"t": [0.0]}, np.ones((1, 2)))


# --- metamorphic: time offsets and units -----------------------------------------------------

def test_a_time_offset_gives_the_same_gradient():
    """An autonomous system marched from ``t0 = 100`` at ``t_eval + 100``: the same discrete
    map, up to the round-off of the shifted times."""
    times = np.array([0.3, 2.71, 6.0, 9.5])
    cotangent = np.random.default_rng(5).normal(size=(4, 2))
    one = march(PENDULUM, [1.0], [0.0], (0.0, 10.0), tau0=0.05, params={"w": 1.3},
                accuracy=None, output=Output(t_eval=times))
    other = march(PENDULUM, [1.0], [0.0], (100.0, 110.0), tau0=0.05, params={"w": 1.3},
                  accuracy=None, output=Output(t_eval=times + 100.0))
    assert one.t.size == other.t.size
    expected = gradient(one, cotangent, check=False)
    assert relative_gap(gradient(other, cotangent, check=False), expected) <= 1e-9


def test_the_gradient_scales_with_the_units():
    """``Q = q / a``, ``P = p / b``, ``s = t / c``, ``K = c / (a b) H(a Q, b P)``: the same
    motion; a cotangent ``C = c u`` on the scaled states (``u``: ``a`` on q, ``b`` on p) gives
    ``dL/dQ0 = a dL/dq0``, ``dL/dP0 = b dL/dp0``, ``dL/dw`` unchanged."""
    a, b, c = 3.0, 0.7, 2.5

    def K(q, p, t, w):
        return c / (a * b) * ((b * p[0]) ** 2 / 2 + w ** 2 * (1 - ca.cos(a * q[0])))
    scaled = HamiltonianSystem(K, 1, {"w": 1.0}, name="pendulum_w_units_gradient")
    times = np.array([0.3, 2.71, 6.0, 9.5])
    cotangent = np.random.default_rng(6).normal(size=(4, 2))
    one = march(PENDULUM, [1.0], [0.0], (0.0, 10.0), tau0=0.05, params={"w": 1.3},
                accuracy=None, output=Output(t_eval=times))
    other = march(scaled, [1.0 / a], [0.0], (0.0, 10.0 / c), tau0=0.05 / c,
                  params={"w": 1.3}, accuracy=None, output=Output(t_eval=times / c))
    expected = gradient(one, cotangent, check=False)
    found = gradient(other, cotangent * np.array([a, b]), check=False)
    predicted = {"q0": expected["q0"] * a, "p0": expected["p0"] * b,
                 "params": expected["params"]}
    assert relative_gap(found, predicted) <= 1e-9


# --- ensembles ---------------------------------------------------------------------------------

@pytest.mark.parametrize("workers", [1, 2])
def test_an_ensemble_gives_each_orbit_what_its_march_gives(workers):
    starts = [kepler_start(e) for e in (0.1, 0.3, 0.5)]
    q0s, p0s = np.array([s[0] for s in starts]), np.array([s[1] for s in starts])
    times = [0.5, 3.0, 5.5]
    orbits = march_ensemble(KEPLER, q0s, p0s, (0.0, 6.0), tau0=0.02, accuracy=None,
                            workers=workers, t_eval=times, derivatives=NAMES)
    for i, orbit in enumerate(orbits):
        alone = march(KEPLER, q0s[i], p0s[i], (0.0, 6.0), tau0=0.02, accuracy=None,
                      output=Output(t_eval=times), derivatives=NAMES)
        assert orbit.derivatives.mode == alone.derivatives.mode
        assert relative_gap(orbit.derivatives, alone.derivatives) <= 1e-12
        assert orbit.derivatives.check.verdict == alone.derivatives.check.verdict == "agrees"


def test_an_ensemble_refuses_derivatives_without_times():
    with expect("derivatives are of the states at fixed times: give t_eval"):
        march_ensemble(KEPLER, [[1.0, 0.0]], [[0.0, 1.0]], (0.0, 1.0), tau0=0.01,
                       derivatives=NAMES)
    with expect("derivatives: unknown name 'mu' in ('mu',) (choose from q0, p0, v0, params)"):
        march_ensemble(KEPLER, [[1.0, 0.0]], [[0.0, 1.0]], (0.0, 1.0), tau0=0.01,
                       t_eval=[0.5], derivatives=("mu",))


def test_a_bad_mode_is_refused():
    with expect("DerivativeOptions.mode must be one of auto, forward, reverse, got 3"):
        DerivativeOptions(NAMES, 3)
    with expect("derivatives: unknown name 'x' in ('x',) (choose from q0, p0, v0, params)"):
        DerivativeOptions(("x",))


@pytest.mark.parametrize("field, value, message", [
    ("least_squares", [{"step": 3}], "gradient is not supported for replaced (least-squares) "
                                     "steps (1 of them)"),
    ("target_error", {"tau0": 0.05}, "gradient is not supported for target_error (its first "
                                     "step is chosen by a pilot march)"),
])
def test_a_march_with_replaced_steps_or_a_pilot_is_refused(field, value, message):
    """The records such marches carry (their own tests make them: test_breakdown.py,
    test_target_error.py), set on a plain march's record."""
    solution = _plain(output=Output(t_eval=[1.0]))
    setattr(solution.march, field, value)
    with expect(message):
        gradient(solution, np.ones((1, 2)))


def test_the_gradient_check_runs_the_fixed_rule_again_with_its_step_count():
    solution = march(KEPLER, *kepler_start(0.5), (0.0, 3.0), tau0=0.01, scheme="fixed",
                     accuracy=None, output=Output(t_eval=[1.0, 2.9]))
    found = gradient(solution, np.ones((2, 4)))
    assert found.check.verdict == "agrees" and found.check.error <= 1e-7, found.check
