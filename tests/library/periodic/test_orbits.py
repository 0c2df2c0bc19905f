"""Periodic orbits at a prescribed energy (solvers/periodic/): convergence of the discrete
period, the equations recomputed independently, input errors and the failure status."""

import numpy as np
import pytest
from scipy.special import ellipk

from ddvp_nlp import GridOptions, solve_periodic
from ddvp_nlp.errors import InputError
from ddvp_nlp.scenes import load_scene
from ddvp_nlp.solution import Status


def fitted_order(sizes, errors) -> float:
    return -np.polyfit(np.log(sizes), np.log(np.abs(errors)), 1)[0]


def pendulum_period(energy: float) -> float:
    """``4 K(k)``, ``k = sin(theta_max / 2)``, ``cos(theta_max) = 1 - E``: ``k^2 = E / 2``."""
    return 4 * ellipk(energy / 2)


@pytest.fixture(scope="module")
def pendulum_orbits():
    system = load_scene("pendulum").system
    return {N: solve_periodic(system, energy=0.5, nodes=N + 1, section="p1=0")
            for N in (100, 200, 400)}


def test_pendulum_period_converges_at_order_two(pendulum_orbits):
    exact = pendulum_period(0.5)
    assert exact == pytest.approx(6.7430014192503, abs=1e-12)
    sizes = sorted(pendulum_orbits)
    errors = [pendulum_orbits[N].orbit.period - exact for N in sizes]
    assert all(pendulum_orbits[N].success for N in sizes)
    assert fitted_order(sizes, errors) == pytest.approx(2.0, abs=0.05)
    assert abs(errors[-1]) < 2e-4


def test_pendulum_equations_hold_when_recomputed_with_numpy(pendulum_orbits):
    """The midpoint rule's canonical equations, H(Q_k, P_k) = E on every interval (hence every
    vddvp energy equation, wrap-around included), closure and the section, written here again
    without CasADi."""
    for solution in pendulum_orbits.values():
        t, q, p = solution.t, solution.q[:, 0], solution.p[:, 0]
        tau = np.diff(t)
        Q, P = (q[:-1] + q[1:]) / 2, (p[:-1] + p[1:]) / 2
        assert np.all(tau > 0) and t[0] == 0
        assert np.max(np.abs(q[1:] - q[:-1] - tau * P)) < 1e-10
        assert np.max(np.abs(p[1:] - p[:-1] + tau * np.sin(Q))) < 1e-10
        H = P ** 2 / 2 + 1 - np.cos(Q)
        assert np.max(np.abs(H - 0.5)) < 1e-10
        assert np.max(np.abs(np.diff(np.append(H, H[0])))) < 1e-10
        assert abs(q[-1] - q[0]) < 1e-10 and abs(p[-1] - p[0]) < 1e-10 and abs(p[0]) < 1e-10
        assert solution.orbit.residuals["canonical"] < 1e-12
        assert solution.energy_residual.shape == (solution.steps,)


def test_harmonic_period_error_at_order_two():
    system = load_scene("harmonic").system
    sizes = (40, 80, 160)
    periods = [solve_periodic(system, energy=0.3, nodes=N + 1, params={"w": 2.0}).orbit.period
               for N in sizes]
    errors = np.array(periods) - np.pi
    assert fitted_order(sizes, errors) == pytest.approx(2.0, abs=0.05)


def test_the_section_may_be_any_coordinate_value_the_orbit_crosses():
    system = load_scene("pendulum").system
    on_turning_point = solve_periodic(system, energy=0.5, nodes=61, section="p1=0")
    elsewhere = solve_periodic(system, energy=0.5, nodes=61, section="q1=0.3")
    assert elsewhere.success and elsewhere.q[0, 0] == pytest.approx(0.3, abs=1e-14)
    assert elsewhere.orbit.period == pytest.approx(on_turning_point.orbit.period,
                                                      abs=1e-9)


@pytest.mark.parametrize("kwargs, message", [
    ({"energy": 2.5}, "energy 2.5 is outside the range where the section p1=0 meets"),
    ({"energy": -0.1}, "no motion exists at energy -0.1: H is at least 0"),
    ({"nodes": 2}, "nodes must be an integer >= 4, got 2"),
    ({"section": "p2=0"}, "section names no coordinate: p2"),
    ({"section": "x1=0"}, "section must be NAME=VALUE with NAME one of q1..q1, p1..p1, got 'x1=0'"),
    ({"scheme": "fixed"}, "scheme 'fixed' has no energy equation"),
])
def test_bad_input_is_refused_naming_argument_and_value(kwargs, message):
    arguments = {"energy": 0.5, "nodes": 50, **kwargs}
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(".", r"\.")):
        solve_periodic(load_scene("pendulum").system, **arguments)


def test_time_dependent_hamiltonian_is_refused():
    with pytest.raises(InputError, match="H depends on t"):
        solve_periodic(load_scene("paper_pendulum").system, energy=0.5, nodes=51)


def test_no_orbit_found_is_a_failure_status_with_residuals():
    """Henon-Heiles from a generic point of x = 0: the march does not close, Newton finds no
    orbit nearby; the result says so and carries the residuals."""
    solution = solve_periodic(load_scene("henon_heiles").system, energy=0.1, nodes=101,
                              section="q1=0", options=GridOptions(max_iter=20))
    assert solution.status in (Status.SOLVER_FAILED, Status.NOT_VERIFIED)
    assert "canonical" in solution.message and solution.orbit.residuals["canonical"] > 1e-6
    # auto: Newton, then IPOPT from the same start; neither is passed off as an orbit
    assert [a["solver"] for a in solution.stats["attempts"]] == ["newton", "ipopt"]
    assert all(a["status"] != "success" for a in solution.stats["attempts"])


@pytest.mark.slow(why="study")
def test_figure_eight_closes_with_simos_period_and_one_curve():
    """Three equal masses at Simo's energy: the period within 1e-3 of 6.32591398 at N = 600,
    and each body's orbit is the next one's shifted by a third of the period (to the
    discretisation error)."""
    scene = load_scene("figure_eight")
    data = scene.periodic
    solution = solve_periodic(scene.system, energy=data.energy, nodes=601,
                              section=data.section, start=data.start,
                              integrals=data.integrals)
    assert solution.success, solution.message
    period = solution.orbit.period
    assert abs(period - 6.32591398) < 1e-3
    assert np.max(np.abs(solution.orbit.integral_unfoldings)) < 1e-12
    # The choreography, node by node (600 intervals: a third is 200 of them): body i + 1 is
    # where body i was a third of the period earlier, and a third of the nodes spans T / 3.
    t, q = solution.t[:-1], solution.q[:-1]
    third = 200
    later = np.roll(np.arange(600), -third)
    assert np.max(np.abs((t[later] - t) % period - period / 3)) < 1e-8
    for body in range(3):
        following = 2 * ((body + 1) % 3)
        assert np.max(np.abs(q[later, following:following + 2] - q[:, 2 * body:2 * body + 2])) \
            < 1e-8


def test_cli_writes_an_orbit_and_a_family(tmp_path, capsys):
    from ddvp_nlp.cli import main

    assert main(["periodic", "pendulum", "--energy", "0.5", "--nodes", "61", "--out",
                 str(tmp_path / "one"), "--no-plot"]) == 0
    data = np.load(tmp_path / "one" / "result.npz")
    assert data["t"].shape == (61,) and np.array_equal(data["q"][-1], data["q"][0])
    import json
    meta = json.loads((tmp_path / "one" / "meta.json").read_text())
    assert meta["status"] == "success" and meta["period"] == pytest.approx(6.75, abs=0.01)
    assert set(meta["residuals"]) >= {"closure", "canonical", "energy"}
    assert main(["periodic", "harmonic", "--family", "0.1:0.5:3", "--nodes", "41", "--out",
                 str(tmp_path / "family")]) == 0
    lines = (tmp_path / "family" / "family.csv").read_text().splitlines()
    assert len(lines) == 4 and (tmp_path / "family" / "family.png").exists()


@pytest.mark.parametrize("arguments, message", [
    (["--energy", "2.5"], "energy 2.5 is outside the range"),
    (["--energy", "0.5", "--nodes", "2"], "nodes must be an integer >= 4, got 2"),
    (["--energy", "0.5", "--section", "q3=0"], "section names no coordinate: q3"),
    (["--family", "0.5:3:4"], "energy 3.0 is outside the range"),
    (["--family", "0.5:1"], "--family must be E1:E2:COUNT, got '0.5:1'"),
])
def test_cli_bad_input_exits_2_before_any_output(tmp_path, capsys, arguments, message):
    from ddvp_nlp.cli import main

    out = tmp_path / "out"
    assert main(["periodic", "pendulum", *arguments, "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert message in error and "Traceback" not in error
    assert not out.exists()


def test_an_energy_below_every_motion_says_that_no_motion_exists():
    """'ddvp periodic pendulum --energy -1' had suggested a rotation section: below the least
    value of H there is no motion at all, and the message says so with the minimum; an energy
    above the librations still gets the rotation hint."""
    import re

    pendulum = load_scene("pendulum")
    with pytest.raises(InputError, match=re.escape(
            "no motion exists at energy -1.0: H is at least 0 (its minimum, at q = [0.0], "
            "p = [0.0]); give an energy above it")):
        pendulum.solve_periodic(-1.0)
    with pytest.raises(InputError, match="a rotation of the angle q1 has a section on it"):
        pendulum.solve_periodic(3.0)
