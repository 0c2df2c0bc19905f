"""The accuracy check: estimates that do not trust the scheme's own equations."""

import numpy as np
import pytest

from ddvp_nlp import load_scene, march
from ddvp_nlp.errors import InputError
from ddvp_nlp.solvers.accuracy import ErrorEstimates, Tolerance


def _exact_harmonic(t, z0, t0, w):
    """The harmonic oscillator H = (p^2 + w^2 q^2)/2 from z0 at t0."""
    c, s = np.cos(w * (t - t0)), np.sin(w * (t - t0))
    return np.array([c * z0[0] + s * z0[1] / w, -w * s * z0[0] + c * z0[1]])


@pytest.mark.parametrize("compiled", [False, True])
def test_local_error_estimate_is_the_true_local_error_on_harmonic(compiled):
    """delta_k against |z_{k+1} - exact flow from z_k|: equal up to the RK4 step's own error,
    a relative O(tau^2)."""
    scene = load_scene("harmonic")
    config = scene.resolve({"t_end": 5.0})
    solution = march(scene.system, config.q0, config.p0, tau0=0.1, t_end=config.t_end,
                     scheme="fixed", params=config.params)
    theta = scene.system.parameter_vector(config.params)
    z = np.hstack([solution.q, solution.p])
    from ddvp_nlp.solvers.compiler import find_compiler

    errors = ErrorEstimates(scene.system, compiler=find_compiler("auto") if compiled else None)
    delta, scale, H, _ = errors(solution.t, z, theta)
    w = config.params["w"]
    true = np.array([np.max(np.abs(z[k + 1] - _exact_harmonic(solution.t[k + 1], z[k],
                                                               solution.t[k], w)))
                     for k in range(solution.steps)])
    assert np.allclose(delta, true, rtol=0.02)
    assert np.allclose(scale, np.maximum(np.abs(z[:-1]).max(axis=1), np.abs(z[1:]).max(axis=1)))


@pytest.mark.parametrize("field, value", [("rtol", 0.0), ("atol", -1.0), ("energy_tol", np.nan),
                                          ("global_tol", 0.0)])
def test_tolerances_are_checked(field, value):
    with pytest.raises(InputError, match=field):
        Tolerance(**{field: value})


def test_propagated_global_error_is_the_true_error_on_harmonic():
    """e_{k+1} = M_k e_k + d_k is exact to first order: on the harmonic oscillator (linear flow)
    it is the true global error up to the RK4 reference's own error."""
    scene = load_scene("harmonic")
    config = scene.resolve({})
    solution = march(scene.system, config.q0, config.p0, tau0=0.05, t_end=config.t_end,
                     scheme="fixed", params=config.params)
    theta = scene.system.parameter_vector(config.params)
    z = np.hstack([solution.q, solution.p])
    _, _, _, estimate = ErrorEstimates(scene.system)(solution.t, z, theta)
    exact = np.array([_exact_harmonic(t, z[0], 0.0, config.params["w"]) for t in solution.t])
    true = np.max(np.abs(z - exact), axis=1)[1:]
    assert true[-1] > 1e-4  # a real error to track
    assert np.allclose(estimate, true, rtol=0.05, atol=1e-12)
