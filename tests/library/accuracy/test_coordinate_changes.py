"""Metamorphic tests of the verdict under changes of coordinates that change nothing of the
motion (issue 45): an angle shifted by ``2 pi k`` (the same motion, other numbers) and a
rotation of a planar system's coordinates (the same orbit, its components mixed).

The scales are per component, so a rotation moves each component's range: the verdict must
stay, and ``t_drift`` may move only as far as the scales do (a phase error growing linearly
crosses the tolerance later in proportion to its scale)."""

import functools

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import Compilation, HamiltonianSystem, Tolerance, load_scene, march

VM = Compilation(compiler=None, fast=False)
CHECK = Tolerance(stop=False)


def _pendulum_shifted(k):
    scene = load_scene("pendulum")
    config = scene.resolve({"t_end": 40.0})
    return march(scene.system, config.q0 + 2 * np.pi * k, config.p0, (config.t0, config.t_end),
                 tau0=config.tau0, compilation=VM, accuracy=CHECK)


@pytest.fixture(scope="module")
def pendulum_unshifted():
    """The unshifted march, once for every shift compared with it (read only)."""
    return _pendulum_shifted(0)


@pytest.mark.parametrize("k", [3, -5])
def test_an_angle_shifted_by_whole_turns_gets_the_same_verdict(pendulum_unshifted, k):
    runs = [pendulum_unshifted, _pendulum_shifted(k)]
    a, b = (run.verdict for run in runs)
    assert b.name == a.name and (a.t_drift is None) == (b.t_drift is None)
    # the same steps: the energy equation does not see the shift (cos is 2 pi periodic), up
    # to the round-off of the larger angle
    assert runs[1].t.size == runs[0].t.size
    assert np.asarray(b.scale) == pytest.approx(np.asarray(a.scale), rel=1e-9)
    assert b.error_max == pytest.approx(a.error_max, rel=1e-6, abs=1e-12)


def rotated(scene, params, angle):
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    Rs = ca.DM(R)

    def H(q, p, t):
        return scene.hamiltonian(ca.mtimes(Rs.T, q), ca.mtimes(Rs.T, p), t, **params)
    return HamiltonianSystem(H, 2, name="rotated"), R


@functools.cache
def _kepler_unrotated(e, tau0, t_end):
    """The orbit in the scene's own axes, marched once for every rotation (read only)."""
    scene = load_scene("kepler")
    config = scene.resolve({"e": e, "tau0": tau0, "t_end": t_end})
    return march(scene.system, config.q0, config.p0, (0.0, t_end), tau0=tau0,
                 compilation=VM, accuracy=CHECK).verdict


# the rotation by 0.5 rad keeps both verdicts in the default run; by 1.3 rad it repeats them
@pytest.mark.slow_when(lambda angle, **_: angle == 1.3, why="repetition")
@pytest.mark.parametrize("angle", [0.5, 1.3])
@pytest.mark.parametrize("e, tau0, t_end, verdict", [(0.6, 0.01, 12.0, "drifted"),
                                                     (0.95, 0.01, 3.0, "inaccurate")])
def test_a_rotated_kepler_orbit_gets_the_same_verdict(e, tau0, t_end, verdict, angle):
    scene = load_scene("kepler")
    config = scene.resolve({"e": e, "tau0": tau0, "t_end": t_end})
    base = _kepler_unrotated(e, tau0, t_end)
    assert base.name == verdict
    system, R = rotated(scene, config.params, angle)
    other = march(system, R @ config.q0, R @ config.p0, (0.0, t_end), tau0=tau0,
                  compilation=VM, accuracy=CHECK).verdict
    assert other.name == base.name
    assert (other.first_failure is None) == (base.first_failure is None)
    if base.first_failure is not None:
        assert other.first_failure.test == base.first_failure.test
    if base.t_drift is not None:
        moved = np.asarray(other.scale) / np.asarray(base.scale)
        spread = max(np.max(moved), 1 / np.min(moved))
        assert base.t_drift / spread <= other.t_drift <= base.t_drift * spread
