"""First-order Lagrangian systems (the paper's case 2): the same solvers, the same results."""

import functools

import casadi as ca
import numpy as np
import pytest
from helpers.common import fitted_order

from ddvp_nlp import (
    InputError,
    Lagrangian,
    LagrangianSystem,
    Scene,
    Scheme,
    load_scene,
    march,
    solve_bvp,
)
from ddvp_nlp.cli import main
from ddvp_nlp.discrete.equations import interval_energies

# each built-in scene loaded once for the module: a solver's functions are built once per
# system (ddvp_nlp/cache.py), so the tests of one scene share them
SCENES = functools.cache(load_scene)


def _pendulum_l(q, v, t):
    return v[0] ** 2 / 2 - (1 - ca.cos(q[0]))


def _paper_l(q, v, t, eps, omega):
    return v[0] ** 2 / 2 - (1 - ca.cos(q[0])) * (1 - eps * ca.sin(omega * t))


def _harmonic_l(q, v, t):
    return (v[0] ** 2 - q[0] ** 2) / 2


# the pendulum's Lagrangian as one system for the module (its functions built once)
PENDULUM_L = LagrangianSystem(_pendulum_l, 1, name="pendulum_l")


def _same(a, b, tol):
    assert a.success and b.success and a.steps == b.steps
    for x, y in ((a.t, b.t), (a.q, b.q), (a.p, b.p)):
        assert np.max(np.abs(x - y)) < tol


@pytest.mark.slow_when(lambda alpha, **_: alpha != 0.5, why="repetition")
@pytest.mark.parametrize("alpha", [0.0, 0.25, 0.5, 1.0])
def test_fixed_steps_match_the_hamiltonian_scheme_for_every_alpha(alpha):
    """L = v^2/2 - V and H = p^2/2 + V: the same discrete trajectory (docs/theory.md section 4)."""
    hamiltonian = SCENES("pendulum").system
    lagrangian = PENDULUM_L
    scheme = Scheme(rule="fixed", alpha=alpha)
    _same(march(hamiltonian, [0.5], [0.5], (0.0, 20.0), tau0=0.05, scheme=scheme),
          march(lagrangian, [0.5], [0.5], (0.0, 20.0), tau0=0.05, scheme=scheme), 1e-10)


@pytest.mark.slow_when(lambda scene, **_: scene == "paper_pendulum", why="repetition")
@pytest.mark.parametrize("rule", ["vddvp", "lee"])
@pytest.mark.parametrize("scene, function, params, tau0, t_end", [
    ("pendulum", _pendulum_l, {}, 0.05, 2.0),
    ("paper_pendulum", _paper_l, {"eps": 0.1, "omega": 0.02}, 0.5, 50.0),
])
def test_energy_rules_match_the_hamiltonian_scheme(rule, scene, function, params, tau0, t_end):
    """Also with a time-dependent L, where vddvp and lee differ from each other. (Over longer
    runs the two forms part by round-off: the Lagrangian energy divides q differences by tau;
    measured 9e-10 in t after 403 pendulum steps.)"""
    hamiltonian = SCENES(scene).system
    lagrangian = LagrangianSystem(function, 1, params=params, name=f"{scene}_l")
    _same(march(hamiltonian, [0.5], [0.5], (0.0, t_end), tau0=tau0, scheme=rule),
          march(lagrangian, [0.5], [0.5], (0.0, t_end), tau0=tau0, scheme=rule), 1e-10)


@pytest.mark.slow_when(lambda alpha, **_: alpha != 1.0, why="study")
@pytest.mark.parametrize("alpha, order", [(0.0, 1), (1.0, 1), (0.5, 2)])
def test_fitted_order_by_alpha(alpha, order):
    system = LagrangianSystem(_harmonic_l, 1, name="harmonic_l")
    steps = [0.1 / 2**j for j in range(4)]
    errors = []
    for tau in steps:
        solution = march(
            system, [1.0], [0.0], (0.0, 5.0), tau0=tau, scheme=Scheme(rule="fixed", alpha=alpha)
        )
        exact_q, exact_p = np.cos(solution.t), -np.sin(solution.t)
        errors.append(max(np.max(np.abs(solution.q[:, 0] - exact_q)),
                          np.max(np.abs(solution.p[:, 0] - exact_p))))
    assert abs(fitted_order(steps, errors) - order) < 0.1, errors


def test_interval_energy_is_conserved_by_vddvp():
    system = PENDULUM_L
    solution = march(system, [0.5], [0.5], (0.0, 50.0), tau0=0.05)
    E = interval_energies(system, Scheme(), solution.t, solution.q, solution.p, [])
    assert solution.success and np.ptp(E) < 1e-12
    # E_k = v_k^2/2 + V(Q_k) with v_k = (q_{k+1} - q_k)/tau_k, recomputed with numpy
    v = np.diff(solution.q[:, 0]) / solution.tau
    Q = (solution.q[:-1, 0] + solution.q[1:, 0]) / 2
    np.testing.assert_allclose(E, v**2 / 2 + 1 - np.cos(Q), rtol=0, atol=1e-12)


@pytest.mark.parametrize("alpha", [0.5, 0.25])
def test_start_from_a_velocity(alpha):
    system = PENDULUM_L
    scheme = Scheme(rule="fixed", alpha=alpha)
    solution = march(system, [0.5], t_span=(0.0, 1.0), v0=[0.4], tau0=0.05, scheme=scheme)
    assert solution.success
    assert abs(solution.q[1, 0] - (0.5 + 0.05 * 0.4)) < 1e-14  # q_1 = q_0 + tau0 v0
    Q = alpha * 0.5 + (1 - alpha) * solution.q[1, 0]
    # p_0 = dL/dv - tau0 alpha dL/dq and p_1 = dL/dv + tau0 beta dL/dq on interval 0
    assert abs(solution.p[0, 0] - (0.4 + 0.05 * alpha * np.sin(Q))) < 1e-14
    assert abs(solution.p[1, 0] - (0.4 - 0.05 * (1 - alpha) * np.sin(Q))) < 1e-12


def test_fixed_endpoint_problem_matches_the_hamiltonian_one():
    hamiltonian, lagrangian = SCENES("pendulum"), SCENES("pendulum_lagrangian")
    for rule in ("vddvp", "fixed"):
        data = hamiltonian.resolve_boundary()
        a = solve_bvp(
            hamiltonian.system,
            data.q_start,
            data.q_end,
            (data.t_span[0], data.t_span[1]),
            nodes=data.nodes,
            scheme=rule,
        )
        b = solve_bvp(
            lagrangian.system,
            data.q_start,
            data.q_end,
            (data.t_span[0], data.t_span[1]),
            nodes=data.nodes,
            scheme=rule,
        )
        assert a.success and b.success, b.message
        for x, y in ((a.t, b.t), (a.q, b.q), (a.p, b.p)):
            assert np.max(np.abs(x - y)) < 1e-9


def test_command_line_on_a_lagrangian_scene(tmp_path, capsys):
    assert main(["march", "pendulum_lagrangian", "--set", "v0=0.4", "--set", "t_end=10",
                 "--out", str(tmp_path / "m"), "--no-progress", "--no-plot"]) == 0
    out = capsys.readouterr().out
    assert "interval energy E_k = v_k.dL/dv - L_k" in out
    result = np.load(tmp_path / "m" / "result.npz")
    assert result["p"].shape == result["q"].shape
    assert main(["bvp", "pendulum_lagrangian", "--out", str(tmp_path / "b"), "--no-plot"]) == 0
    assert main(["march", "pendulum", "--set", "v0=0.4"]) == 2
    assert "scene 'pendulum' has no parameter 'v0'" in capsys.readouterr().err


def test_singular_lagrangian_is_refused():
    message = ("lagrangian of 'bad' is singular in v: d2L/dv2 is not invertible (its smallest "
               "singular value is 0 at test points), so there is no Legendre transform and the "
               "discrete equations do not determine the motion")
    with pytest.raises(InputError, match="^" + message.replace("(", r"\(").replace(")", r"\)")):
        LagrangianSystem(lambda q, v, t: (v[0] + v[1]) ** 2 / 2 - ca.sumsqr(q) / 2, 2,
                         name="bad")
    with pytest.raises(InputError, match="is singular in v"):  # linear in v: d2L/dv2 = 0
        LagrangianSystem(lambda q, v, t: q[0] * v[0] - q[0] ** 2, 1, name="linear")


@pytest.mark.parametrize("function, message", [
    (lambda q, v, t: ca.vertcat(v[0], q[0]), "lagrangian of 'x' must be scalar, got shape 2x1"),
    (lambda q, v, t: v[0] ** 2 + ca.SX.sym("k") * q[0],
     "lagrangian of 'x' depends on symbols it was not given: k"),
    (lambda q, v, t: v[3], "lagrangian of 'x' failed on symbolic input: "),
])
def test_bad_lagrangian(function, message):
    with pytest.raises(InputError, match="^" + message.replace("(", r"\(")):
        LagrangianSystem(function, 1, name="x")


@pytest.mark.parametrize("kwargs, message", [
    ({"p0": [0.5], "v0": [0.4]}, "give exactly one of p0 and v0"),
    ({}, "give exactly one of p0 and v0"),
    ({"v0": [np.nan]}, "v0 must be finite, got [nan]"),
])
def test_bad_start(kwargs, message):
    system = PENDULUM_L
    with pytest.raises(InputError, match="^" + message.replace("[", r"\[").replace("]", r"\]")):
        march(system, [0.5], t_span=(0.0, 1.0), tau0=0.05, **kwargs)


def test_v0_needs_a_lagrangian():
    with pytest.raises(InputError, match="^v0 needs a Lagrangian system; 'pendulum' is "
                                         "Hamiltonian: give p0$"):
        march(SCENES("pendulum").system, [0.5], t_span=(0.0, 1.0), v0=[0.4], tau0=0.05)
    with pytest.raises(InputError, match="^v0 is for a scene declared by Lagrangian"):
        Scene(lambda q, p, t: p[0] ** 2, n=1, q0=[0.0], v0=[1.0], tau0=0.1, t_end=1.0)
    scene = Scene(Lagrangian(_pendulum_l), n=1, q0=[0.5], v0=[0.4], tau0=0.05, t_end=1.0)
    assert scene.system.lagrangian_form and scene.resolve().p0 is None
