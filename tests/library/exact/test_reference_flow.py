"""The one exact flow (solvers/exact/): adaptive DOP853 compiled over whole spans against scipy's
DOP853 (the same algorithm) and exact solutions, its dense output, its reference's claimed error
against the true error, the batched short flows, multiple shooting and the variational
equations. Counted in steps and errors, never in seconds."""

import functools

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ddvp_nlp import load_scene
from ddvp_nlp.solvers.exact.flow import AdaptiveFlow, exact_flow, flow_field
from ddvp_nlp.solvers.exact.reference import reference
from ddvp_nlp.solvers.exact.shooting import banded_solve, shoot
from ddvp_nlp.solvers.exact.short_flows import LocalFlows, short_flows
from ddvp_nlp.solvers.exact.variational import flow_with_derivatives

# each built-in scene loaded once for the module: a solver's functions are built once per
# system (ddvp_nlp/cache.py), so the tests of one scene share them
SCENES = functools.cache(load_scene)


def _problem(name, overrides=None):
    scene = SCENES(name)
    config = scene.resolve(overrides or {})
    theta = scene.system.parameter_vector(config.params)
    z0 = np.concatenate([config.q0, config.p0])
    return scene, config, theta, z0


def _exact(scene, config):
    exact = scene.exact_states(config)
    assert exact is not None
    return exact


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.mark.slow_when(lambda name, **_: name != "kepler", why="repetition")
@pytest.mark.parametrize("name, overrides", [("kepler", {"e": 0.6}),
                                             ("henon_heiles", {}),
                                             ("paper_pendulum", {"t_end": 200.0})])
def test_the_same_steps_as_scipys_dop853(name, overrides, rng):
    """The same tableau, estimator, controller and first step: the same number of steps and
    the same states and dense output to round-off amplified along the orbit."""
    scene, config, theta, z0 = _problem(name, overrides)
    span = (config.t0, config.t_end)
    flow = exact_flow(scene.system)
    ours = flow.run(z0, *span, theta, rtol=1e-10, atol=1e-12)
    field = flow_field(scene.system)[0]
    theirs = solve_ivp(lambda t, z: np.asarray(field(z, t, theta)).ravel(), span, z0,
                       method="DOP853", rtol=1e-10, atol=1e-12, dense_output=True)
    assert ours.success and theirs.success
    assert ours.steps == theirs.t.size - 1
    times = rng.uniform(*span, 500)
    assert np.max(np.abs(ours.z(times) - theirs.sol(times).T)) < 1e-8
    assert np.max(np.abs(ours.z_end - theirs.y[:, -1])) < 1e-8


@pytest.mark.parametrize("overrides", [{"e": 0.6}, {"e": 0.9}])
def test_against_keplers_exact_solution_forward_and_backward(overrides, rng):
    scene, config, theta, z0 = _problem("kepler", overrides)
    exact = _exact(scene, config)
    span = (config.t0, config.t_end)
    flow = exact_flow(scene.system)
    run = flow.run(z0, *span, theta, rtol=1e-12, atol=1e-14)
    times = np.sort(rng.uniform(*span, 2000))
    assert run.success and run.t_reached == span[1]
    assert np.max(np.abs(run.z(times) - exact(times))) < 1e-6
    nodes_t, nodes_z = run.nodes()
    assert np.max(np.abs(nodes_z - exact(nodes_t))) < 1e-6
    back = flow.run(exact(np.array([span[1]]))[0], span[1], span[0], theta, rtol=1e-12,
                    atol=1e-14)
    assert back.success and np.all(back.h < 0) and back.t_reached == span[0]
    assert np.max(np.abs(back.z(times) - exact(times))) < 1e-6


def test_chunks_and_the_virtual_machine_give_the_same_run():
    """A chunk continues where the previous one stopped: 8 or 1024 attempts a call give the
    same run bit for bit; CasADi's virtual machine computes the same steps as the compiled
    chunk (the compiler's -ffp-contract=off keeps the arithmetic)."""
    scene, config, theta, z0 = _problem("henon_heiles")
    field = flow_field(scene.system)[0]
    big = exact_flow(scene.system).run(z0, 0.0, 50.0, theta, rtol=1e-9)
    small = AdaptiveFlow(field, slots=8).run(z0, 0.0, 50.0, theta, rtol=1e-9)
    vm = AdaptiveFlow(field, slots=64, compiler=None).run(z0, 0.0, 50.0, theta, rtol=1e-9)
    assert small.calls > 10 and big.calls == 1
    for other in (small, vm):
        assert np.array_equal(big.t_old, other.t_old)
        assert np.array_equal(big.w_end, other.w_end)


def test_a_tail_of_smaller_calls_gives_the_same_run_and_stops_after_as_many_attempts():
    """A run likely to end within part of a call makes its last attempts in calls of a flow
    with fewer slots (`AdaptiveFlow.run`'s ``tail``): the same run bit for bit (the
    documented invariant above), and a run cut by ``max_attempts`` stops after the same
    attempts as with whole calls of its own slots."""
    scene, config, theta, z0 = _problem("henon_heiles")
    field = flow_field(scene.system)[0]
    flow, tail = exact_flow(scene.system), AdaptiveFlow(field, slots=8)
    for t_end, h0, limit in ((50.0, 0.5, 10_000_000), (2000.0, 5.0, flow.slots)):
        whole = flow.run(z0, 0.0, t_end, theta, rtol=1e-9, h0=h0, max_attempts=limit)
        cut = flow.run(z0, 0.0, t_end, theta, rtol=1e-9, h0=h0, max_attempts=limit, tail=tail)
        assert whole.calls == 1 and cut.calls > 10
        assert (whole.attempts, whole.status, whole.t_reached) == \
            (cut.attempts, cut.status, cut.t_reached)
        for name in ("t_old", "h", "w_old", "F", "w_end"):
            assert np.array_equal(getattr(whole, name), getattr(cut, name))
    assert not cut.success and cut.attempts == flow.slots  # the second: cut by max_attempts


def test_a_blow_up_and_a_singular_start_end_as_failures_with_finite_states():
    z, t = ca.SX.sym("z", 2), ca.SX.sym("t")
    blow_up = ca.Function("f", [z, t, ca.SX.sym("theta", 0)], [ca.vertcat(z[0] ** 2, 0)])
    run = AdaptiveFlow(blow_up, slots=256).run([1.0, 0.0], 0.0, 2.0, rtol=1e-8)
    assert not run.success and 0.999 < run.t_reached < 1.001 and run.attempts < 20000
    assert np.all(np.isfinite(run.w_end)) and np.all(np.isfinite(run.w_old))
    singular = ca.Function("f", [z, t, ca.SX.sym("theta", 0)], [ca.vertcat(1 / z[0], 0)])
    run = AdaptiveFlow(singular, slots=64).run([0.0, 0.0], 0.0, 1.0, rtol=1e-8, h0=0.1)
    assert not run.success and run.steps == 0 and run.attempts < 100


@pytest.mark.parametrize("name, overrides, span", [("kepler", {"e": 0.9}, None),
                                                   ("pendulum", {"p0": 1.4}, (0.0, 60.0))])
@pytest.mark.parametrize("rtol", [1e-8, 1e-10])
def test_the_references_claimed_error_bounds_its_true_error(name, overrides, span, rtol):
    """Two runs, at rtol and rtol / 10: the finer is the reference, twice the envelope of
    their difference its claimed error; the claim holds at every time and is not absurdly
    loose."""
    scene, config, theta, z0 = _problem(name, overrides)
    span = span or (config.t0, config.t_end)
    times = np.linspace(*span, 5001)
    exact = scene.exact_states(config)
    truth = exact(times) if exact is not None else exact_flow(scene.system).run(
        z0, *span, theta, rtol=1e-13, atol=1e-15).z(times)
    scale = truth.max(axis=0) - truth.min(axis=0)
    ref = reference(exact_flow(scene.system), z0, *span, theta, scale, rtol=rtol)
    true_error = np.max(np.abs(ref.states(times) - truth) / scale, axis=1)
    claim = ref.error(times, scale)
    assert np.all(true_error <= claim)
    assert np.max(claim) < 100 * max(np.max(true_error), rtol)


def test_short_flows_hold_their_bounds(rng):
    """Many short intervals, each from its own state: the bound holds against tight adaptive
    runs; long steps are refined by step doubling where the budget asks."""
    scene, config, theta, z0 = _problem("paper_pendulum")
    flow = exact_flow(scene.system)
    run = flow.run(z0, 0.0, 100.0, theta, rtol=1e-12, atol=1e-14)
    t = np.sort(rng.uniform(0.0, 90.0, 300))
    z = run.z(t) + 1e-3 * rng.standard_normal((t.size, 2))
    tau = rng.uniform(0.2, 1.5, t.size)
    phi, bound, used = short_flows(scene.system)(t, z, tau, theta, 1e-9)
    truth = np.array([flow.run(z[k], t[k], t[k] + tau[k], theta, rtol=1e-13,
                               atol=1e-15).z_end for k in range(t.size)])
    assert np.all(used > 0) and np.all(bound <= 1e-9) and np.any(used > 1)
    assert np.all(np.abs(phi - truth) <= bound + 1e-14)
    field = flow_field(scene.system)[0]
    vm = LocalFlows(field, block=64, compiler=None)(t, z, tau, theta, 1e-9)
    assert np.array_equal(vm[0], phi)


def test_shooting_finds_the_pendulums_continuous_solution_and_refuses_a_conjugate_point():
    scene = SCENES("pendulum")
    data = scene.resolve_boundary()
    theta = scene.system.parameter_vector(data.params)
    t = np.linspace(*data.t_span, 2001)
    straight = np.stack([np.linspace(data.q_start[0], data.q_end[0], t.size),
                         np.full(t.size, (data.q_end[0] - data.q_start[0]) / t[-1])], axis=1)
    shot = shoot(scene.system, theta, t, straight, data.q_end, np.array([1.44, 1.41]))
    assert shot.trajectory is not None, shot.reason
    end = exact_flow(scene.system).run(np.concatenate([data.q_start, shot.p0]), t[0], t[-1],
                                       theta, rtol=1e-13, atol=1e-15).z_end
    assert abs(end[0] - data.q_end[0]) < 1e-9 and shot.cuts.size > 2
    harmonic = SCENES("harmonic")
    t = np.linspace(0.0, np.pi, 101)
    z = np.stack([np.cos(t) + 3 * np.sin(t), -np.sin(t) + 3 * np.cos(t)], axis=1)
    refused = shoot(harmonic.system, harmonic.system.parameter_vector({}), t, z, [0.5],
                    np.array([2.0, 2.0]))
    assert refused.trajectory is None and "conjugate" in refused.reason


def test_the_banded_solve_is_the_dense_one(rng):
    n, segments = 2, 5
    d = 2 * n
    tangents = rng.standard_normal((segments, d, d))
    residual = rng.standard_normal(n + d * (segments - 1))
    J = np.zeros((residual.size, residual.size))
    for j in range(segments):
        column = 0 if j == 0 else n + (j - 1) * d
        Y = tangents[j][:, n:] if j == 0 else tangents[j]
        if j < segments - 1:
            J[j * d:(j + 1) * d, column:column + Y.shape[1]] = Y
            J[j * d:(j + 1) * d, n + j * d:n + (j + 1) * d] = -np.eye(d)
        else:
            J[j * d:, column:column + d] = Y[:n]
    assert np.allclose(banded_solve(tangents, residual, n), np.linalg.solve(J, residual))


def test_the_variational_equations_are_the_flows_derivatives():
    """The tangent of one run against central differences of tight runs, and symplectic."""
    scene, config, theta, z0 = _problem("henon_heiles")
    flow = exact_flow(scene.system)
    result = flow_with_derivatives(scene.system, theta, z0, 20.0)
    J = np.empty((4, 4))
    for j in range(4):
        dz = np.zeros(4)
        dz[j] = 1e-6
        up = flow.run(z0 + dz, 0.0, 20.0, theta, rtol=1e-13, atol=1e-15).z_end
        down = flow.run(z0 - dz, 0.0, 20.0, theta, rtol=1e-13, atol=1e-15).z_end
        J[:, j] = (up - down) / 2e-6
    assert result.success
    assert np.max(np.abs(result.monodromy - J)) < 1e-6 * max(1.0, np.max(np.abs(J)))
    Jn = np.block([[np.zeros((2, 2)), np.eye(2)], [-np.eye(2), np.zeros((2, 2))]])
    Y = result.monodromy
    assert np.max(np.abs(Y.T @ Jn @ Y - Jn)) < 1e-8 * max(1.0, np.max(np.abs(Y)) ** 2)
