"""The study figures looked at as drawn objects (labels, legends, scales, colour norms), through
`figures.Keep`, which keeps a drawn figure instead of writing it."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad

from ddvp_nlp.io import figures
from ddvp_nlp.io.orbit_files import plot_family, scene_period
from ddvp_nlp.scenes import load_scene


def quadrature_period(energy: float) -> float:
    """The libration period by quadrature, independent of the elliptic integral: with
    ``sin(q/2) = k sin(phi)``, ``k^2 = E/2``, ``T = 4 int_0^{pi/2} dphi / sqrt(1 - k^2 sin^2)``."""
    m = energy / 2
    return 4 * quad(lambda phi: 1 / np.sqrt(1 - m * np.sin(phi) ** 2), 0, np.pi / 2,
                    epsabs=1e-13, epsrel=1e-13)[0]


def rotation_quadrature(energy: float) -> float:
    """One turn: ``int_0^{2 pi} dq / sqrt(2 (E - 1 + cos q))``."""
    return quad(lambda q: 1 / np.sqrt(2 * (energy - 1 + np.cos(q))), 0, 2 * np.pi,
                epsabs=1e-13, epsrel=1e-13)[0]


@pytest.mark.parametrize("energy", [0.05, 0.5, 1.3, 1.95])
def test_the_pendulum_declares_its_exact_libration_period(energy):
    period = scene_period(load_scene("pendulum"), None, {})
    assert period(energy) == pytest.approx(quadrature_period(energy), rel=1e-11)
    assert np.isnan(period(2.5)) and np.isnan(period(-0.1))


@pytest.mark.parametrize("energy", [2.2, 3.0, 10.0])
def test_the_rotations_are_looked_up_by_their_section(energy):
    scene = load_scene("pendulum")
    period = scene_period(scene, "q1 = 0", {})
    assert period(energy) == pytest.approx(rotation_quadrature(energy), rel=1e-11)
    assert scene_period(scene, "q1=0.5", {}) is None  # no family declared through that section


def test_the_harmonic_period_takes_the_frequency_given():
    period = scene_period(load_scene("harmonic"), None, {"w": 2.0})
    assert np.allclose(period(np.array([0.1, 0.7])), np.pi)


def family_rows(periods, statuses=None):
    energies = [0.2, 0.6, 1.0, 1.4]
    statuses = statuses or ["success"] * len(energies)
    return [{"energy": e, "period": t, "status": s, "nodes": 100}
            for e, t, s in zip(energies, periods, statuses, strict=True)]


def test_the_family_figure_draws_the_exact_curve_and_the_relative_difference():
    period = scene_period(load_scene("pendulum"), None, {})
    exact = period(np.array([0.2, 0.6, 1.0, 1.4]))
    rows = family_rows(exact * (1 + np.array([1e-4, 2e-4, 4e-4, 0.0])),
                       ["success", "success", "success", "max_iterations"])
    kept = figures.Keep()
    plot_family(rows, "pendulum", kept, reference=period)
    top, bottom = kept.figure.axes
    labels = [t.get_text() for t in top.get_legend().get_texts()]
    assert labels == ["exact period", "discrete, 100 nodes", "failed (no orbit)"]
    assert bottom.get_yscale() == "log" and "T_{\\mathrm{exact}}" in bottom.get_ylabel()
    # the failed member is on the energy axis, not at its last iterate's difference
    assert bottom.lines[0].get_xdata().tolist() == [0.2, 0.6, 1.0]
    assert np.allclose(bottom.lines[0].get_ydata(), [1e-4, 2e-4, 4e-4])
    low, high = bottom.get_ylim()
    ticks = [label.get_text() for label in bottom.yaxis.get_ticklabels(which="both")
             if label.get_text() and low <= label.get_position()[1] <= high]
    assert len(set(ticks)) == len(ticks) >= 3 and "10⁻⁴" in ticks  # minor labels within a decade


def test_without_an_exact_period_the_family_figure_has_one_panel():
    kept = figures.Keep()
    plot_family(family_rows([6.3, 6.5, 6.8, 7.2]), "x", kept)
    (ax,) = kept.figure.axes
    assert ax.get_xlabel() == "energy $E$" and ax.get_legend() is not None
