"""The march: its equations recomputed independently, order, conservation, gauge, steps > 0."""

import numpy as np
import pytest
from helpers.common import fitted_order

from ddvp_nlp import HamiltonianSystem, Scheme, Status, StepControl, Tolerance, load_scene, march

EPS, OMEGA = 0.1, 0.02


def paper_H(q, p, t):
    return p**2 / 2 + (1 - np.cos(q)) * (1 - EPS * np.sin(OMEGA * t))


def paper_H_q(q, p, t):
    return np.sin(q) * (1 - EPS * np.sin(OMEGA * t))


def paper_H_p(q, p, t):
    return p


def paper_H_t(q, p, t):
    return -(1 - np.cos(q)) * EPS * OMEGA * np.cos(OMEGA * t)


def numpy_residuals(solution, scheme):
    """The scheme's equations from t, q, p alone, with numpy and hand-written derivatives."""
    t, q, p = solution.t, solution.q[:, 0], solution.p[:, 0]
    a, b = scheme.alpha, scheme.beta
    tau = np.diff(t)
    Q = a * q[:-1] + b * q[1:]
    P = a * p[1:] + b * p[:-1]
    s = t[:-1] + tau / 2 if scheme.clock == "midpoint" else t[:-1]
    canonical = np.concatenate([q[1:] - q[:-1] - tau * paper_H_p(Q, P, s),
                                p[1:] - p[:-1] + tau * paper_H_q(Q, P, s)])
    if scheme.rule == "vddvp":
        energy = paper_H(Q[1:], P[1:], s[:-1]) - paper_H(Q[:-1], P[:-1], s[:-1])
    else:  # lee: dS_D/dt_k with S_k = P_k (q_{k+1} - q_k) - tau_k H(Q_k, P_k, s_k)
        H = paper_H(Q, P, s)
        H_t = paper_H_t(Q, P, s)
        if scheme.clock == "midpoint":
            energy = H[1:] - H[:-1] - (tau[1:] * H_t[1:] + tau[:-1] * H_t[:-1]) / 2
        else:
            energy = H[1:] - H[:-1] - tau[1:] * H_t[1:]
    return canonical, energy


@pytest.mark.slow_when(
    lambda scheme, **_: scheme.rule == "fixed" or scheme.clock == "left",
    why="repetition")
@pytest.mark.parametrize("scheme", [Scheme("vddvp"), Scheme("lee"), Scheme("fixed"),
                                    Scheme("fixed", alpha=0.3), Scheme("lee", clock="left"),
                                    Scheme("vddvp", clock="left")])
def test_equations_hold_when_recomputed_with_numpy(scene_of, scheme):
    paper = scene_of("paper_pendulum")
    config = paper.resolve({"t_end": 300.0})
    # alpha = 0.3 at tau0 = 0.5 is beyond the accuracy check's default tolerance (accuracy.py);
    # the equations, which this test is about, hold all the same
    solution = march(paper.system, config.q0, config.p0, (0.0, 300.0), tau0=0.5, scheme=scheme,
                     accuracy=Tolerance(stop=False))
    assert solution.success, solution.message
    canonical, energy = numpy_residuals(solution, scheme)
    assert np.max(np.abs(canonical)) < 1e-10
    if scheme.variable_steps:
        assert np.max(np.abs(energy)) < 1e-10
    else:
        # fixed steps do not enforce the energy balance: it must visibly fail, and the
        # result reports exactly that balance
        assert np.max(np.abs(energy)) > 1e-6
        np.testing.assert_allclose(solution.energy_residual, energy, atol=1e-12)
    assert np.all(solution.tau > 0)


def test_paper_example_to_t_10000(run_shared):
    """docs/theory.md section 8: about 20150 steps, tau between 0.458 and 0.535."""
    _, _, solution = run_shared("paper_pendulum")
    assert solution.success
    assert 20100 <= solution.steps <= 20200
    assert 0.455 < solution.tau.min() < 0.461
    assert 0.532 < solution.tau.max() < 0.537
    assert 10000 <= solution.t[-1] < 10000 + solution.tau.max()
    assert np.max(np.abs(solution.energy_residual)) < 1e-13


@pytest.mark.parametrize("rule", ["vddvp", "lee", "fixed"])
def test_midpoint_rule_is_second_order_on_harmonic(scene_of, rule):
    scene = scene_of("harmonic")
    config = scene.resolve()
    steps, errors = [], []
    for tau0 in (0.2, 0.1, 0.05, 0.025):
        solution = march(scene.system, config.q0, config.p0, (0.0, 10.0), tau0=tau0, scheme=rule)
        q, p = scene.exact(solution.t, config.q0, config.p0, 0.0, **config.params)
        steps.append(tau0)
        errors.append(max(np.max(np.abs(solution.q - q)), np.max(np.abs(solution.p - p))))
    assert 1.9 < fitted_order(steps, errors) < 2.1, errors


@pytest.mark.slow_when(lambda rule, name, **_: rule == "vddvp" and name == "fpu", why="repetition")
@pytest.mark.parametrize("name", ["pendulum", "harmonic", "kepler", "henon_heiles", "fpu"])
@pytest.mark.parametrize("rule", ["vddvp", "lee"])
def test_midpoint_energy_conserved_over_ten_thousand_steps(run_shared, name, rule):
    scene, config, solution = run_shared(
        name, {"t_end": 1e9}, scheme=rule, steps=StepControl(max_steps=10_000)
    )
    assert solution.status is Status.MAX_STEPS and solution.steps == 10_000
    from ddvp_nlp.discrete.equations import interval_energies
    H = interval_energies(scene.system, Scheme(rule), solution.t, solution.q, solution.p,
                          scene.system.parameter_vector(config.params))
    assert np.max(np.abs(H - H[0])) <= 1e-12 * max(1.0, abs(H[0]))


@pytest.mark.parametrize("name", ["pendulum", "kepler", "henon_heiles"])
def test_lee_and_vddvp_agree_on_autonomous_scenes(run_shared, name):
    _, _, vddvp = run_shared(name, {"t_end": 20.0}, scheme="vddvp")
    _, _, lee = run_shared(name, {"t_end": 20.0}, scheme="lee")
    assert vddvp.success and lee.success and vddvp.steps == lee.steps
    assert np.max(np.abs(vddvp.t - lee.t)) < 1e-10
    assert np.max(np.abs(vddvp.q - lee.q)) < 1e-10
    assert np.max(np.abs(vddvp.p - lee.p)) < 1e-10


def test_gauge_term_changes_lee_but_not_vddvp(scene_of):
    """Adding f(t) to H leaves the paper's equations unchanged (its energy equation compares both
    intervals at one clock) but not the lee rule (docs/theory.md sections 3 and 8)."""
    import casadi as ca

    base = scene_of("paper_pendulum")
    gauged = HamiltonianSystem(
        lambda q, p, t, eps, omega: base.hamiltonian(q, p, t, eps, omega) + 0.05 * ca.sin(0.5 * t)
        + 0.01 * t, n=1, params=dict(base.params), name="gauged")
    for rule, same in (("vddvp", True), ("lee", False)):
        a = march(base.system, [0.5], [0.5], (0.0, 100.0), tau0=0.5, scheme=rule)
        b = march(gauged, [0.5], [0.5], (0.0, 100.0), tau0=0.5, scheme=rule)
        assert a.success and b.success
        n = min(a.t.size, b.t.size)
        difference = max(np.max(np.abs(a.t[:n] - b.t[:n])), np.max(np.abs(a.q[:n] - b.q[:n])))
        if same:
            # equal up to the round-off of evaluating the larger H, amplified by the
            # O(tau) conditioning of the energy equation
            assert a.steps == b.steps and difference < 1e-10
        else:
            assert difference > 1e-3


def test_time_dependence_is_found_out():
    assert load_scene("paper_pendulum").system.time_dependent
    assert not load_scene("pendulum").system.time_dependent


def test_fixed_steps_end_on_t_end(run_shared):
    _, _, solution = run_shared("harmonic", {"t_end": 1.0, "tau0": 0.3}, scheme="fixed")
    assert solution.success and solution.steps == 4 and solution.t[-1] == 1.0
    np.testing.assert_allclose(solution.tau, 0.25, rtol=1e-14)


def test_breakdown_keeps_every_accepted_step_and_never_a_reversed_one(scene_of):
    """The rotating pendulum (H = 2.5) has no positive step once c(z) changes sign."""
    scene = scene_of("pendulum")
    solution = march(scene.system, [0.0], [np.sqrt(5.0)], (0.0, 100.0), tau0=0.05)
    assert not solution.success
    assert solution.status in (Status.NEWTON_FAILED, Status.NO_ADMISSIBLE_STEP)
    assert solution.steps > 5 and np.all(solution.tau > 0)
    assert np.all(np.isfinite(solution.q)) and np.all(np.isfinite(solution.p))
    assert f"step {solution.steps} from t = " in solution.message
    # every kept node satisfies its equations
    assert np.max(solution.canonical_residual) < 1e-10
    assert np.max(np.abs(solution.energy_residual)) < 1e-10


def test_step_bounds_end_the_march_with_their_status(run_shared):
    _, _, low = run_shared("paper_pendulum", {"t_end": 50.0}, steps=StepControl(tau_min=0.49))
    assert low.status is Status.STEP_BELOW_MIN and np.all(low.tau >= 0.49)
    _, _, high = run_shared("paper_pendulum", {"t_end": 50.0}, steps=StepControl(tau_max=0.51))
    assert high.status is Status.STEP_ABOVE_MAX and np.all(high.tau[1:] <= 0.51)
    _, _, ratio = run_shared(
        "paper_pendulum", {"t_end": 50.0}, steps=StepControl(max_step_ratio=1.01)
    )
    assert ratio.status is Status.STEP_RATIO
    ratios = ratio.tau[1:] / ratio.tau[:-1]
    assert np.all(np.maximum(ratios, 1 / ratios) <= 1.01)


def test_an_interrupt_inside_the_monitors_keeps_only_the_nodes_all_of_them_saw(monkeypatch,
                                                                            scene_of):
    """A Ctrl-C that lands while the driver's monitors look at a batch (here in the solvability
    monitor, before the accuracy check has seen it, on its third call) drops that batch: the
    nodes kept are those every monitor saw, and the per-node arrays agree with them."""
    from ddvp_nlp.solvers.marching import monitors

    scene = scene_of("henon_heiles")
    watch = monitors.SolvabilityMonitor.watch
    calls = []

    def interrupted(self, nodes, first, advance):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return watch(self, nodes, first, advance)

    monkeypatch.setattr(monitors.SolvabilityMonitor, "watch", interrupted)
    solution = march(scene.system, [0.0, 0.1], [0.35, 0.0], (0.0, 1e5), tau0=0.05)
    monkeypatch.setattr(monitors.SolvabilityMonitor, "watch", watch)
    assert solution.status is Status.INTERRUPTED
    assert solution.local_error.size == solution.steps
    assert solution.solvability.size == solution.t.size
    before = march(
        scene.system,
        [0.0, 0.1],
        [0.35, 0.0],
        (0.0, 1e5),
        tau0=0.05,
        steps=StepControl(max_steps=solution.steps),
    )
    assert solution.steps > 1000 and before.steps == solution.steps  # two whole calls kept
    assert np.array_equal(solution.t, before.t)
