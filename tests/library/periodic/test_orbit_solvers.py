"""Periodic orbits, continued: IPOPT beside Newton, pendulum rotations (an angle coordinate
closing with a whole turn), Henon-Heiles orbits through x = 0 off the invariant plane, and the
refusals of bad input (solvers/periodic/orbit.py, solvers/periodic/orbit_nlp.py)."""

import json

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import ellipk

from ddvp_nlp import GridOptions, solve_periodic, solve_periodic_family
from ddvp_nlp.errors import InputError
from ddvp_nlp.scenes import load_scene
from ddvp_nlp.solvers.periodic.first_orbit import march_to_return, resample, section_point
from ddvp_nlp.solvers.periodic.refinement import node_levels, refine_by_index


def fitted_order(sizes, errors) -> float:
    return -np.polyfit(np.log(sizes), np.log(np.abs(errors)), 1)[0]


def midpoint_residuals(solution, force, hamiltonian, energy, turn=0.0):
    """The largest residual of the midpoint rule's equations for ``H = p^2/2 + V(q)``, of
    ``H(Q_k, P_k) = E`` and of the closure ``q_N = q_0 + turn``, ``p_N = p_0``, with numpy."""
    t, q, p = solution.t, solution.q[:, 0], solution.p[:, 0]
    tau = np.diff(t)
    Q, P = (q[:-1] + q[1:]) / 2, (p[:-1] + p[1:]) / 2
    assert np.all(tau > 0) and abs(t[0]) < 1e-12
    return max(np.max(np.abs(q[1:] - q[:-1] - tau * P)),
               np.max(np.abs(p[1:] - p[:-1] + tau * force(Q))),
               np.max(np.abs(hamiltonian(Q, P) - energy)),
               abs(q[-1] - q[0] - turn), abs(p[-1] - p[0]))


def pendulum_h(q, p):
    return p ** 2 / 2 + 1 - np.cos(q)


@pytest.mark.parametrize("scene, energy, nodes, params, force, hamiltonian", [
    ("pendulum", 0.5, 100, None, np.sin, pendulum_h),
    ("harmonic", 0.3, 80, {"w": 2.0}, lambda q: 4.0 * q, lambda q, p: (p ** 2 + 4 * q ** 2) / 2),
])
def test_ipopt_finds_the_orbit_newton_finds(scene, energy, nodes, params, force, hamiltonian):
    system = load_scene(scene).system
    orbits = {
        solver: solve_periodic(
            system, energy=energy, nodes=nodes + 1, params=params,
            options=GridOptions(solver=solver)
        )
        for solver in ("newton", "ipopt")
    }
    for solver, orbit in orbits.items():
        assert orbit.success, orbit.message
        assert orbit.stats["solver"] == solver and orbit.stats["attempts"][0]["solver"] == solver
        assert midpoint_residuals(orbit, force, hamiltonian, energy) < 1e-10
        assert orbit.verdict.name == "accurate"
    assert orbits["ipopt"].orbit.period == pytest.approx(orbits["newton"].orbit.period,
                                                            abs=1e-9)
    assert orbits["ipopt"].stats["iterations"] <= 10
    assert orbits["newton"].stats["iterations"] <= 10
    assert "ipopt: Solve_Succeeded" in orbits["ipopt"].message


def rotation_period(energy: float) -> float:
    """``T = int_0^{2 pi} dq / p(q)``, ``p = sqrt(2 (E - 1 + cos q))``; with ``q = 2 phi``,
    ``E - 1 + cos q = E (1 - (2 / E) sin^2 phi)``: ``T = 4 K(m) / sqrt(2 E)``, ``m = 2 / E``
    (scipy's parameter, ``m = k^2``), i.e. ``2 K(1/k) / k`` in the modulus ``k^2 = E / 2`` of the
    librations."""
    return 4 * ellipk(2 / energy) / np.sqrt(2 * energy)


def _rotation(N, system=None):
    return solve_periodic(system or load_scene("pendulum").system, energy=2.5, nodes=N + 1,
                          section="q1=0", angles=("q1",), options=GridOptions(solver="newton"))


@pytest.fixture(scope="module")
def rotations():
    """The rotation at E = 2.5 on 100, 200 and 400 intervals, by Newton (what ``auto`` tries
    first), for the tests of its period, its iterations and its refinement (read only)."""
    system = load_scene("pendulum").system
    return {N: _rotation(N, system) for N in (100, 200, 400)}


def test_rotation_period_formula_agrees_with_a_quadrature():
    for energy in (2.1, 2.5, 4.0, 10.0):
        turn, _ = quad(lambda q, e: 1 / np.sqrt(2 * (e - 1 + np.cos(q))), 0, 2 * np.pi,
                       args=(energy,), epsabs=1e-13, epsrel=1e-13)
        assert rotation_period(energy) == pytest.approx(turn, rel=1e-11)


def test_rotation_period_converges_at_order_two(rotations):
    exact = rotation_period(2.5)
    sizes = sorted(rotations)
    for N in sizes:
        orbit = rotations[N]
        assert orbit.success, orbit.message
        assert orbit.orbit.winding == (1,)
        assert midpoint_residuals(orbit, np.sin, pendulum_h, 2.5, turn=2 * np.pi) < 1e-10
        assert np.all(orbit.p[:, 0] > 0)  # a rotation: q only increases
        assert sum(a["iterations"] for a in orbit.stats["attempts"]) <= 200
    errors = [rotations[N].orbit.period - exact for N in sizes]
    assert fitted_order(sizes, errors) == pytest.approx(2.0, abs=0.05)
    assert abs(errors[-1]) < 2e-5


def test_newton_converges_on_rotations_in_as_many_iterations_at_every_n(rotations):
    """The rotation's steps have a spike where the level curve has an inflection (w = f' H_zz f
    changes sign). From the predicted grid (tau ~ |w|^(-1/3)) and then by continuation in N,
    Newton finds the orbit on every level in a number of iterations that does not grow with N
    (from uniform times it failed at every N, and IPOPT needed 13, 28, 69, 296 iterations)."""
    counts = {}
    for N in (100, 200, 400, 800):
        orbit = rotations[N] if N in rotations else _rotation(N)
        assert orbit.success, orbit.message
        levels = orbit.stats["levels"]
        assert [level["intervals"] for level in levels] == [100, 200, 400, 800][:len(levels)]
        assert levels[-1]["intervals"] == N and all(lv["status"] == "success" for lv in levels)
        assert all(level["iterations"] <= 8 for level in levels)
        counts[N] = levels[-1]["iterations"]
        tau = np.diff(orbit.t)
        assert np.max(tau) > 2.5 * np.median(tau)  # the spike is there
    assert counts[800] <= counts[100] + 1


def test_continuation_keeps_the_step_distribution(rotations):
    """Refined by node index, an orbit's nodes keep its steps' shape: each old step is split
    in two halves, the spike included."""
    orbit = rotations[100]
    t, z = refine_by_index(orbit.t, np.hstack([orbit.q, orbit.p]), 200, angles=(0,))
    assert t.size == 201 and z[-1, 0] == pytest.approx(z[0, 0] + 2 * np.pi, abs=1e-14)
    np.testing.assert_allclose(np.diff(t)[::2], np.diff(orbit.t) / 2, rtol=1e-12)
    t_open, z_open = refine_by_index(orbit.t, np.hstack([orbit.q, orbit.p]), 150,
                                     closed=False)
    assert np.array_equal(z_open[[0, -1]], np.hstack([orbit.q, orbit.p])[[0, -1]])
    assert t_open[0] == 0.0 and t_open[-1] == pytest.approx(orbit.t[-1] - orbit.t[0])
    assert node_levels(800) == [100, 200, 400, 800]
    assert node_levels(1000) == [125, 250, 500, 1000]
    assert node_levels(150) == [150] and node_levels(60) == [60]


def test_auto_tries_newton_first_and_reports_both():
    """From uniform times (the start without the step spike) Newton stalls on the rotation and
    IPOPT from the same start finds the orbit; the message names both."""
    system = load_scene("pendulum").system
    theta = system.parameter_vector(None)
    point = section_point(system, theta, 2.5, 1, 0.0, np.ones(2), "q1=0")
    t, z = resample(*march_to_return(system, theta, point, 1, 0.0, "vddvp", True), 100,
                    angles=(0,))
    orbit = solve_periodic(system, energy=2.5, nodes=101, section="q1=0", angles=("q1",),
                           guess={"t": t, "q": z[:, :1], "p": z[:, 1:]})
    attempts = orbit.stats["attempts"]
    assert [a["solver"] for a in attempts] == ["newton", "ipopt"]
    assert attempts[0]["status"] != "success" and attempts[1]["status"] == "success"
    assert orbit.stats["solver"] == "ipopt" and "newton also tried" in orbit.message


def test_rotation_without_an_angle_does_not_close():
    """Without ``angles`` q never returns to the section: a failure status, not an orbit."""
    orbit = solve_periodic(load_scene("pendulum").system, energy=2.5, nodes=51,
                           section="q1=0", options=GridOptions(solver="newton"))
    assert not orbit.success and "did not return" in orbit.message


@pytest.mark.parametrize("name, increasing", [("loop", False), ("across", True)])
def test_henon_heiles_families_through_x0_leave_the_invariant_plane(name, increasing):
    scene = load_scene("henon_heiles")
    data = scene.periodic.families[name]
    family = solve_periodic_family(scene.system, [0.02, 0.06, 0.1], nodes=101,
                                   section=data.section, start=data.start)
    periods = []
    for _, orbit in family:
        assert orbit.success, orbit.message
        assert orbit.verdict.name == "accurate"
        # the trajectory error of the exact flow from node 0, of the orbit's size: 1.2e-3 to 3.8e-3
        assert orbit.verdict.error_max < 5e-3
        assert abs(orbit.orbit.unfolding) < 1e-12
        assert np.ptp(orbit.q[:, 0]) > 0.2 and np.ptp(orbit.q[:, 1]) > 0.01  # both move
        periods.append(orbit.orbit.period)
    assert (np.diff(periods) > 0).all() if increasing else (np.diff(periods) < 0).all()


@pytest.mark.parametrize("kwargs, message", [
    ({"solver": "simplex"}, "unknown solver 'simplex' (choose from auto, newton, ipopt)"),
    ({"angles": ("q2",)}, "angles must name coordinates q1..q1, got ('q2',)"),
    ({"energy": 2.5, "angles": ("q1",)},
     "a rotation of the angle q1 has a section on it, e.g. q1=0"),
    ({"energy": 3.0, "section": "q1=0.5", "nodes": 2}, "nodes must be an integer >= 4, got 2"),
    ({"energy": float("nan")}, "energy"),
])
def test_more_bad_input_is_refused(kwargs, message):
    arguments = {"energy": 0.5, "nodes": 50, **kwargs}
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")
                       .replace(".", r"\.")):
        if "solver" in arguments:
            arguments["options"] = GridOptions(solver=arguments.pop("solver"))
        solve_periodic(load_scene("pendulum").system, **arguments)


@pytest.mark.parametrize("scene, arguments, message", [
    ("pendulum", ["--energy", "0.5", "--solver", "simplex"], "unknown solver 'simplex'"),
    ("pendulum", ["--energy", "2.5"], "a rotation of the angle q1 has a section on it"),
    ("paper_pendulum", ["--energy", "0.5"], "H depends on t"),
    ("henon_heiles", ["--energy", "0.1", "--section", "q3=0"], "section names no coordinate"),
    ("harmonic", ["--energy", "-1"], "no motion exists at energy -1.0"),
])
def test_cli_refuses_before_any_output(tmp_path, capsys, scene, arguments, message):
    from ddvp_nlp.cli import main

    out = tmp_path / "out"
    assert main(["periodic", scene, *arguments, "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert message in error and "Traceback" not in error
    assert not out.exists()


def test_cli_rotation_on_ipopt(tmp_path, capsys):
    from ddvp_nlp.cli import main

    assert main(["periodic", "pendulum", "--energy", "2.5", "--section", "q1=0", "--nodes",
                 "101", "--solver", "ipopt", "--out", str(tmp_path), "--no-plot"]) == 0
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert meta["solver"] == "ipopt" and meta["winding"] == [1]
    assert meta["period"] == pytest.approx(rotation_period(2.5), abs=1e-3)
    data = np.load(tmp_path / "result.npz")
    assert data["q"][-1, 0] == pytest.approx(data["q"][0, 0] + 2 * np.pi, abs=1e-12)
