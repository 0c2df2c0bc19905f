"""Issue 47's Kepler targets for a march's derivatives: ``d(q, p)(t_eval)/d(q0, p0, mu)`` within
1e-6 of central finite differences of the discrete map (step 1e-6 relative) for e from 0 to 0.9
(``vddvp`` up to e = 0.7, ``fixed`` above, where ``vddvp`` has no positive step); the
frozen-step derivative beside it, shown not to match; and the convergence at order 2 to the
exact flow's sensitivity (DOP853 on the variational equations, ``solvers/exact/variational.py``)
(slow)."""

import numpy as np
import pytest
from helpers.parametrized import kepler_mu

from ddvp_nlp import Output, StepControl, march
from ddvp_nlp.solvers.exact.variational import flow_with_derivatives
from ddvp_nlp.solvers.marching.derivative_check import check_record, remarch_function
from ddvp_nlp.solvers.marching.derivatives import march_derivatives

NAMES = ("q0", "p0", "params")
RELATIVE_STEP, TOLERANCE = 1e-6, 1e-6  # issue 47; why 1e-6 holds: test_derivatives.py



KEPLER = kepler_mu()


def start(e):
    """The apocentre of the ``mu = 1``, ``a = 1`` orbit of eccentricity ``e`` (period 2 pi,
    the pericentre at t = pi)."""
    return np.array([1 + e, 0.0]), np.array([0.0, np.sqrt((1 - e) / (1 + e))])


def run(e, scheme, tau0, t_end, t_eval, inputs=None, derivatives=NAMES):
    q0, p0 = start(e)
    inputs = inputs or {"q0": q0, "p0": p0, "params": np.array([1.0])}
    return march(KEPLER, inputs["q0"], inputs["p0"], (0.0, t_end), tau0=tau0, scheme=scheme,
                 params={"mu": float(inputs["params"][0])}, accuracy=None,
                 output=Output(t_eval=t_eval), derivatives=derivatives)


def finite_differences(e, scheme, tau0, t_end, t_eval):
    """Fourth-order central differences of the discrete map in each input, step 1e-6 relative
    (1e-6 where the input is zero); ``(M, 4, 5)``, columns ``q0, p0, mu``."""
    q0, p0 = start(e)
    base = np.concatenate([q0, p0, [1.0]])
    columns = []
    for j in range(5):
        h = RELATIVE_STEP * (abs(base[j]) if base[j] != 0 else 1.0)
        values = {}
        for multiple in (-2, -1, 1, 2):
            x = base.copy()
            x[j] += multiple * h
            solution = run(e, scheme, tau0, t_end, t_eval,
                           {"q0": x[:2], "p0": x[2:4], "params": x[4:]}, derivatives=None)
            assert solution.success and solution.t_eval.size == len(t_eval)
            values[multiple] = solution.z_eval
        columns.append((8 * (values[1] - values[-1]) - (values[2] - values[-2])) / (12 * h))
    return np.stack(columns, axis=2)


def stacked(derivatives):
    return np.concatenate([derivatives[name] for name in NAMES], axis=2)


def column_errors(found, reference):
    """Each column's largest error relative to that column's size."""
    return [np.max(np.abs(found[:, :, j] - reference[:, :, j])) / np.max(np.abs(reference[:, :, j]))
            for j in range(reference.shape[2])]


# (scheme, tau0, t_end, t_eval) by e; the default suite runs e = 0 (the circle: its energy
# steps are all the same length) and e = 0.5; test_derivatives.py runs 0.3, 0.7 and 0.9
CASES = {
    0.0: ("vddvp", 0.01, 7.0, [0.5, 3.0, 6.5]),
    0.5: ("vddvp", 0.01, 4.0, [0.5, 3.0, 3.3, 3.9]),
    0.6: ("vddvp", 0.005, 4.0, [1.0, 3.1, 3.5]),
    0.8: ("fixed", 0.002, 4.0, [0.5, 3.1, 3.3, 3.9]),
}


@pytest.mark.parametrize("e", [
    0.0, 0.5,
    pytest.param(0.6, marks=pytest.mark.slow(why="repetition")),
    pytest.param(0.8, marks=pytest.mark.slow(why="repetition"))])
def test_kepler_derivatives_match_finite_differences_of_the_discrete_map(e):
    scheme, tau0, t_end, t_eval = CASES[e]
    solution = run(e, scheme, tau0, t_end, t_eval)
    assert solution.success
    errors = column_errors(stacked(solution.derivatives),
                           finite_differences(e, scheme, tau0, t_end, t_eval))
    assert max(errors) <= TOLERANCE, errors
    assert solution.derivatives.check.verdict == "agrees"


@pytest.mark.parametrize("e", [0.3, 0.6])
def test_the_frozen_step_derivative_does_not_match_the_discrete_map(e):
    """The frozen-step derivative (the step lengths held, as peers report) beside the
    derivative on a Kepler march with vddvp: the same check (one random direction, central
    difference of two marches) passes the derivative and fails the frozen one by far."""
    tau0, t_end, t_eval = 0.05, 6.0, [0.5, 3.0, 5.5]
    solution = run(e, "vddvp", tau0, t_end, t_eval)
    z = np.hstack([solution.q, solution.p])
    frozen = march_derivatives(KEPLER, solution.scheme, [1.0], solution.t, z, solution.t_eval,
                               NAMES, frozen_steps=True)
    q0, p0 = start(e)
    base = {"q0": q0, "p0": p0, "params": np.array([1.0])}
    remarch = remarch_function(march, KEPLER, solution.scheme, (0.0, t_end), tau0,
                               StepControl(), None, solution.t_eval)
    records = {}
    for label, derivative in (("derivative", solution.derivatives), ("frozen", frozen)):
        records[label] = check_record(
            remarch, base, NAMES, lambda v, d=derivative: sum(d[n] @ v[n] for n in NAMES),
            solution.q, solution.p, base["params"], solution.t.size, (False, 0.0))
    assert records["derivative"].verdict == "agrees" and records["derivative"].error <= 1e-7
    assert records["frozen"].verdict == "disagrees", records["frozen"]
    assert records["frozen"].error > 10 * records["frozen"].tolerance


def exact_sensitivity(e, times):
    """``d(q, p)(t)/d(q0, p0, mu)`` of the exact Kepler flow at ``mu = 1``: the monodromy
    ``Y(t)`` of the variational equations (``flow_with_derivatives``, adaptive order 8) for the
    start, and for ``mu`` Kepler's scaling ``z(t; mu) = (Q, sqrt(mu) P)(sqrt(mu) t; q0, p0 /
    sqrt(mu))`` differentiated at ``mu = 1``: ``dz/dmu = t/2 f(z(t)) - Y(t)[:, p] p0/2 + (0,
    p(t)/2)``."""
    q0, p0 = start(e)
    z0 = np.concatenate([q0, p0])
    rows = []
    for t in times:
        flow = flow_with_derivatives(KEPLER, np.array([1.0]), z0, float(t), rtol=1e-13)
        assert flow.success, flow.message
        d_mu = t / 2 * flow.field - flow.monodromy[:, 2:] @ p0 / 2
        d_mu[2:] += flow.z[2:] / 2
        rows.append(np.hstack([flow.monodromy, d_mu[:, None]]))
    return np.stack(rows)


@pytest.mark.slow(why="study")
@pytest.mark.parametrize("e, scheme, steps", [
    (0.3, "vddvp", [0.02, 0.01, 0.005, 0.0025]),
    (0.7, "vddvp", [0.004, 0.002, 0.001, 0.0005]),
    (0.9, "fixed", [0.002, 0.001, 0.0005, 0.00025])])
def test_kepler_derivative_converges_to_the_exact_sensitivity_at_order_two(e, scheme, steps):
    """The discrete derivative's error against the exact flow's sensitivity falls like
    ``tau0^2`` (fitted slope 2 +- 0.1 over three halvings); the frozen-step derivative's error
    is reported beside it."""
    times = np.array([0.5, 3.0, 4.0])
    exact = exact_sensitivity(e, times)
    errors, frozen_errors = [], []
    for tau0 in steps:
        solution = run(e, scheme, tau0, 4.2, times)
        assert solution.success
        errors.append(np.max(np.abs(stacked(solution.derivatives) - exact)) /
                      np.max(np.abs(exact)))
        frozen = march_derivatives(KEPLER, solution.scheme, [1.0], solution.t,
                                   np.hstack([solution.q, solution.p]), solution.t_eval, NAMES,
                                   frozen_steps=True)
        frozen_errors.append(np.max(np.abs(stacked(frozen) - exact)) / np.max(np.abs(exact)))
    slope = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    print(f"e = {e} {scheme}: errors {errors}, frozen {frozen_errors}, slope {slope:.4f}")
    assert abs(slope - 2.0) <= 0.1, (slope, errors, frozen_errors)
