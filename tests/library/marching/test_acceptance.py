"""Each chunk step's verdict, computed in the chunk, is the acceptance test's numpy predicates
on the step's outputs (acceptance.py), bounds and tolerance included."""

import numpy as np

from ddvp_nlp import Compilation, load_scene, march
from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.solvers.marching.acceptance import Acceptance
from ddvp_nlp.solvers.marching.chunk import FastChunk
from ddvp_nlp.solvers.marching.steps import step_functions

ACCEPTANCES = [Acceptance(1e-10), Acceptance(1e-10, 0.0495, 0.0505, 1.002),
               Acceptance(1e-10, None, None, None), Acceptance(1e-16), Acceptance(1e-10, 0.05)]


def _numpy_verdict(acceptance, steps, t_prev, t_mid):
    """The predicates as the march applied them before the chunk computed them."""
    finite = np.all(np.isfinite(np.column_stack(
        [steps.t_next, steps.z_next, steps.canonical, steps.energy, steps.size,
         steps.H_interval, steps.H_node, steps.w_node])), axis=1)
    before = np.concatenate([[t_mid], steps.t_next[:-1]])
    tau = steps.t_next - before
    tau_prev = np.concatenate([[t_mid - t_prev], tau[:-1]])
    return (finite & (tau > 0)
            & acceptance.residuals_ok(steps.canonical, steps.size, steps.energy,
                                      steps.H_interval)
            & acceptance.bounds_ok(tau, tau_prev))


def test_the_chunk_verdict_is_the_acceptance_test():
    scene = load_scene("henon_heiles")
    system = scene.system
    scheme = Scheme.coerce("vddvp")
    theta = system.parameter_vector(None)
    start = march(
        system,
        [0.0, 0.1],
        [0.3, 0.0],
        (0.0, 0.1),
        tau0=0.05,
        accuracy=None,
        compilation=Compilation(fast=False),
    )
    z = np.column_stack([start.q, start.p])
    chunk = FastChunk(system, scheme, step_functions(system, scheme), chunk=48, compiler=None,
                      cache_dir=None)
    verdicts = []
    for acceptance in ACCEPTANCES:
        steps = chunk.energy_steps(start.t[0], start.t[1], z[0], z[1], 0.0, theta, acceptance)
        expected = _numpy_verdict(acceptance, steps, start.t[0], start.t[1])
        assert np.array_equal(steps.good, expected)
        verdicts.append(expected)
    verdicts = np.concatenate(verdicts)
    assert verdicts.any() and not verdicts.all()  # the bounds and tol=1e-16 reject steps


def test_the_fixed_chunk_verdict_is_the_residual_test():
    scene = load_scene("henon_heiles")
    system = scene.system
    scheme = Scheme.coerce("fixed")
    theta = system.parameter_vector(None)
    chunk = FastChunk(system, scheme, step_functions(system, scheme), chunk=32, compiler=None,
                      cache_dir=None)
    found = []
    for acceptance in (Acceptance(1e-10), Acceptance(1e-17)):
        steps = chunk.fixed_steps(0, np.array([0.0, 0.1, 0.3, 0.0]), theta, acceptance, t0=0.0,
                                  tau=0.05, t_end=1.6, total=32)
        finite = np.all(np.isfinite(np.column_stack(
            [steps.t_next, steps.z_next, steps.canonical, steps.size, steps.H_node,
             steps.w_node])), axis=1)
        expected = finite & acceptance.residuals_ok(steps.canonical, steps.size)
        assert np.array_equal(steps.good, expected)
        found.append(expected)
    assert found[0].all() and not found[1].all()
