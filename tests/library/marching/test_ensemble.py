"""Ensembles: many orbits marched together, each as march() would, and Poincare sections."""

import numpy as np
import pytest

from ddvp_nlp import load_scene, march, march_ensemble
from ddvp_nlp.cli import main
from ddvp_nlp.errors import InputError
from ddvp_nlp.solution import Status
from ddvp_nlp.studies.poincare import poincare_section


def test_ensemble_is_each_march_alone_and_a_failing_orbit_does_not_stop_the_others():
    scene = load_scene("henon_heiles")
    q0s = np.array([[0.0, 0.1], [0.0, 0.0], [0.0, -0.2]])
    p0s = np.array([[0.35, 0.0], [0.0, 1.2], [0.3, 0.1]])  # the second: E = 0.72, escapes
    solutions = march_ensemble(scene.system, q0s, p0s, (0.0, 60.0), tau0=0.05)
    assert [s.success for s in solutions] == [True, False, True]
    # the escape ends in a step Newton does not converge on, or one whose own residual is
    # refused after it stopped: which, depends on whether the careful path's functions run
    # compiled or in CasADi's virtual machine (a system whose functions an earlier run built)
    assert solutions[1].status in (Status.NEWTON_FAILED, Status.RESIDUAL_TOO_LARGE)
    assert solutions[1].steps < 20
    for solution, q0, p0 in zip(solutions, q0s, p0s, strict=True):
        alone = march(scene.system, q0, p0, (0.0, 60.0), tau0=0.05)
        assert alone.status is solution.status and alone.steps == solution.steps
        assert np.array_equal(alone.t, solution.t) and np.array_equal(alone.q, solution.q)
        assert np.array_equal(alone.local_error, solution.local_error)
    assert solutions[0].stats["fast_steps"] == solutions[0].steps - 1  # one call per chunk
    # marched on two forked workers, which inherit the loaded chunk: no compile in a worker
    assert [s.stats["worker_compiles"] for s in solutions] == [0, 0, 0]


def test_workers_give_the_serial_ensemble_and_bad_input_stops_before_any_march():
    scene = load_scene("henon_heiles")
    rng = np.random.default_rng(3)
    q0s = np.column_stack([np.zeros(5), rng.uniform(-0.2, 0.2, 5)])
    p0s = rng.uniform(-0.2, 0.2, (5, 2))
    serial = march_ensemble(scene.system, q0s, p0s, (0.0, 40.0), tau0=0.05, workers=1)
    split = march_ensemble(scene.system, q0s, p0s, (0.0, 40.0), tau0=0.05, workers=2)
    assert all(s.success for s in serial) and len(split) == 5
    for a, b in zip(serial, split, strict=True):
        assert a.status is b.status and a.t.size == b.t.size
        for x, y in ((a.t, b.t), (a.q, b.q), (a.p, b.p), (a.local_error, b.local_error)):
            np.testing.assert_allclose(y, x, rtol=0, atol=1e-12)
        assert np.array_equal(a.at(7.3)[0], b.at(7.3)[0])  # dense output attached again
    with pytest.raises(InputError, match="workers"):
        march_ensemble(scene.system, q0s, p0s, (0.0, 40.0), tau0=0.05, workers=0)
    bad = p0s.copy()
    bad[3, 1] = np.nan
    with pytest.raises(InputError, match="orbit 3"):
        march_ensemble(scene.system, q0s, bad, (0.0, 40.0), tau0=0.05)


def test_section_points_lie_on_the_section_and_the_energy_surface(tmp_path):
    scene = load_scene("henon_heiles")
    energy = 1 / 12
    section = poincare_section(scene.system, energy, orbits=4, tau0=0.05, t_end=150.0)
    assert section.statuses == ["success"] * 4 and section.points.shape[0] > 40
    assert np.max(np.abs(section.points[:, 0])) < 1e-12
    assert np.all(section.points[:, 2] > 0)  # crossing in the + direction
    theta = scene.system.parameter_vector(None)
    H = scene.system.energy(section.points[:, :2], section.points[:, 2:], section.times, theta)
    # on the surface to the scheme's own nodal accuracy (O(tau^2)), not that of the crossing
    assert np.max(np.abs(H - energy)) <= 1.5 * section.energy_errors.max()
    assert section.energy_errors.max() < 1e-4
    out = tmp_path / "section"
    code = main(["poincare", "henon_heiles", "--energy", "0.0833", "--orbits", "2",
                 "--t-end", "30", "--out", str(out), "--no-plot"])
    assert code == 0 and (out / "section.csv").exists() and (out / "orbits.csv").exists()


@pytest.mark.parametrize("energy", ["nan", "inf"])
def test_a_section_at_no_finite_energy_is_refused_by_name(energy, tmp_path, capsys):
    """``--energy nan`` had been searched for starts and reported as a surface that misses the
    section; it is refused as the option it is, before any start or march."""
    code = main(["poincare", "henon_heiles", "--energy", energy, "--orbits", "2",
                 "--out", str(tmp_path / "section")])
    assert code == 2
    assert f"--energy must be finite, got {energy}" in capsys.readouterr().err
    assert not (tmp_path / "section").exists()


def test_the_poincare_defaults_give_a_few_hundred_crossings_per_orbit(tmp_path, capsys):
    """Issue 30: the defaults drew about 30 crossings per orbit (t_end = 200), too sparse to
    see a section; 2000 time units give about 300 (Henon-Heiles at E = 1/8)."""
    import csv

    out = tmp_path / "section"
    assert main(["poincare", "henon_heiles", "--energy", "0.125", "--orbits", "2",
                 "--out", str(out), "--no-plot"]) == 0
    with open(out / "section.csv") as handle:
        orbits = [row["orbit"] for row in csv.DictReader(handle)]
    assert sorted(set(orbits)) == ["0", "1"]
    assert all(orbits.count(orbit) >= 250 for orbit in ("0", "1"))
    from ddvp_nlp.cli.parser import build_parser

    assert build_parser().parse_args(["poincare", "henon_heiles", "--energy", "0.1"]).orbits == 50


@pytest.mark.parametrize("starts", [np.zeros((0, 1)), [], np.zeros((3, 0))])
def test_an_ensemble_of_no_orbit_is_refused_as_such(starts):
    """Zero orbits is named as zero orbits (it was answered "the shapes differ")."""
    system = load_scene("harmonic").system
    with pytest.raises(InputError, match="hold no orbit"):
        march_ensemble(system, starts, starts, (0.0, 1.0), tau0=0.1)
