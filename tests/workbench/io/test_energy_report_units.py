"""``meta.json``'s relative energy error of a march is relative to ``|H0|`` in any units (it was
divided by ``max(1, |H0|)``: a swing in lengths of ``1e-8`` reported ``1e-32`` for a drift of
``1e-16`` of its energy), and absolute, and said so, where ``H0`` is 0."""

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import Scene, march
from ddvp_nlp.discrete import Scheme
from ddvp_nlp.io.run_folder import energy_report, run_energies


def report(length: float, zero_at_start: bool = False):
    """The swing in lengths of ``length`` from ``q = 0.5 length`` at rest; ``zero_at_start``:
    ``H`` shifted to 0 there."""
    shift = length ** 2 * (1 - np.cos(0.5)) if zero_at_start else 0.0

    def H(q, p, t):
        return length ** 2 * ((p[0] / length) ** 2 / 2 + 1 - ca.cos(q[0] / length)) - shift
    scene = Scene(hamiltonian=H, n=1, q0=[0.5 * length], p0=[0.0], tau0=0.1, t_end=20.0)
    system = scene.system
    run = march(system, [0.5 * length], [0.0], (0.0, 20.0), tau0=0.1, scheme="fixed")
    theta = system.parameter_vector({})
    return energy_report(scene, Scheme("fixed"), run, theta,
                         run_energies(system, Scheme("fixed"), run, theta))


@pytest.mark.slow_when(lambda length: length == 1e6, why="repetition")
@pytest.mark.parametrize("length", [1e-8, 1e6])
def test_the_relative_error_is_the_same_in_any_units(length):
    base, other = report(1.0), report(length)
    assert other["node_energy_error_kind"] == base["node_energy_error_kind"] == "relative to |H0|"
    assert other["node_energy_error"] == pytest.approx(base["node_energy_error"], rel=1e-6)


def test_an_energy_of_zero_gives_the_absolute_drift_and_says_so():
    zero = report(1.0, zero_at_start=True)
    assert zero["H0"] == 0.0
    assert zero["node_energy_error_kind"] == "absolute (H0 = 0)"
    assert zero["node_energy_error"] == zero["node_energy_drift"]
