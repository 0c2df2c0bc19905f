"""The accuracy verdict does not depend on units: rescaling ``q``, ``p``, ``t`` and ``H``
consistently, adding a constant to ``H``, shifting the clock or translating a
translation-invariant system leaves it unchanged.

Two levels. The check itself: the same trajectory, written in other units, judged again, gives
the same verdict, the same first failure and ``t_drift``, and the same figures (they are ratios
to the motion's own scales). End to end: the march in other units gives the same verdict (its
nodes agree to round-off: its residual test has floors of 1 in the units of the state, which
these factors keep away from)."""

import functools

import numpy as np
import pytest
from helpers.random_cases import cases_and_units
from hypothesis import HealthCheck, given, settings

from ddvp_nlp import Compilation, Tolerance, load_scene, march
from ddvp_nlp.physics.hamiltonian import HamiltonianSystem
from ddvp_nlp.solvers.accuracy.judgement import Judgement, Level
from ddvp_nlp.studies.verdict_study import DrawnCase, RandomSystem, Units, run_case

VM = Compilation(compiler=None, fast=False)
FIGURES = ("error_max", "local_error_max", "level_error", "energy_drift")


def scaled_scene_system(scene, params, units: Units) -> HamiltonianSystem:
    """``H(q, p, t) = (u_q u_p / u_t) H~((q - shift)/u_q, p/u_p, (t - t_shift)/u_t) + offset``
    of a scene's ``H~``."""
    def hamiltonian(q, p, t):
        value = scene.hamiltonian((q - units.shift) / units.q, p / units.p,
                                  (t - units.t_shift) / units.t, **params)
        return units.q * units.p / units.t * value + units.offset
    return HamiltonianSystem(hamiltonian, scene.n, name=f"{scene.name}-scaled")


def march_in(scene_name, overrides, units: Units):
    scene = load_scene(scene_name)
    config = scene.resolve(overrides)
    system = scaled_scene_system(scene, config.params, units)
    span = (units.t * config.t0 + units.t_shift, units.t * config.t_end + units.t_shift)
    return march(system, config.q0 * units.q + units.shift, config.p0 * units.p, span,
                 tau0=units.t * config.tau0, compilation=VM)


@functools.cache
def march_in_own_units(scene_name, overrides: tuple):
    """The march in the scene's own units, once per scene and overrides (``overrides`` as
    sorted items): the reference every other unit system is compared with. Read only."""
    return march_in(scene_name, dict(overrides), Units())


def assert_same(a: dict, b: dict, units: Units, rel=1e-6):
    assert a["verdict"] == b["verdict"]
    fa, fb = a["first_failure"], b["first_failure"]
    assert (fa is None) == (fb is None)
    if fa is not None:
        assert (fa["step"], fa["test"]) == (fb["step"], fb["test"])
    assert (a["t_drift"] is None) == (b["t_drift"] is None)
    if a["t_drift"] is not None:
        assert b["t_drift"] == pytest.approx(units.t * a["t_drift"] + units.t_shift, rel=1e-6,
                                             abs=1e-6 * units.t)
    for key in FIGURES:
        assert (a[key] is None) == (b[key] is None), key
        if a[key] is not None:
            # the figures are ratios to the motion's scales (thresholds 1e-2 and 0.1): 1e-9 of
            # them is round-off of differences taken beside an offset of H or a translation
            assert b[key] == pytest.approx(a[key], rel=rel, abs=1e-9), key


UNITS = [Units(q=1e3, p=1e-2, t=10.0), Units(q=1e-3, p=1e-3, t=1e-2),
         Units(q=1e4, p=1e4, t=1e4), Units(offset=-1e3), Units(t_shift=37.5),
         Units(q=1e-4, p=30.0, t=1e3, offset=0.25, t_shift=-5.0)]
# every change at once: q, p and t scaled, H offset, the clock shifted
ALL_AT_ONCE = UNITS[-1]


def _a_repetition(scene_name, verdict, units, **_):
    """The default run keeps every unit system on kepler's drifted orbit (the verdict the
    phase decides, the most sensitive to scales) and every other scene in the units that change
    everything at once; the other pairs repeat both."""
    if scene_name == "henon_heiles":
        return True
    return not (scene_name == "kepler" and verdict == "drifted") and units != ALL_AT_ONCE


@pytest.mark.slow_when(_a_repetition, why="repetition")
@pytest.mark.parametrize("scene_name, overrides, verdict", [
    ("harmonic", {"t_end": 19.95}, "accurate"),  # 20 falls on a node: the last step is a tie
    ("kepler", {"e": 0.6, "tau0": 0.01, "t_end": 12.0}, "drifted"),
    ("kepler", {"e": 0.95, "tau0": 0.01, "t_end": 3.0}, "inaccurate"),
    ("paper_pendulum", {"t_end": 30.0}, "drifted"),  # time-dependent: the clock scales too
    ("henon_heiles", {"t_end": 50.0}, "accurate"),
])
@pytest.mark.parametrize("units", UNITS, ids=lambda u: f"q{u.q:g}p{u.p:g}t{u.t:g}"
                         f"o{u.offset:g}s{u.t_shift:g}")
def test_a_march_in_other_units_gets_the_same_verdict(scene_name, overrides, verdict, units):
    unit = march_in_own_units(scene_name, tuple(sorted(overrides.items())))
    other = march_in(scene_name, overrides, units)
    assert unit.verdict.name == verdict
    assert other.status == unit.status and other.steps == unit.steps
    assert_same(unit.verdict.as_dict(), other.verdict.as_dict(), units, rel=1e-5)


@pytest.mark.slow(why="repetition")
def test_a_translated_chain_gets_the_same_verdict():
    """A translation-invariant system (a chain of three coupled pendula, ``1 - cos(q_i -
    q_j)``): the whole motion moved by 1e4 of its size, marched, judged alike."""
    system = RandomSystem(n=3, potential="trigonometric", stiffness=(1.0,) * 3,
                          cubic=(0.0,) * 3, quartic=(0.1,) * 3, coupling=(1.0, 0.5, 0.8),
                          masses=(1.0, 1.5, 0.7), translation_invariant=True)
    case = DrawnCase(system, (0.3, -0.2, 0.5), (0.4, 0.1, -0.3), tau0=0.05, t_end=20.0)
    for units in (Units(), Units(shift=1e4), Units(shift=-3e3, q=2.0, p=0.5, t=4.0)):
        _, solution = run_case(case.in_units(units))
        if units == Units():
            first = solution
            continue
        assert solution.status == first.status and solution.steps == first.steps
        assert_same(first.verdict.as_dict(), solution.verdict.as_dict(), units, rel=1e-5)


# -- the check alone, on the same trajectory in other units: random systems ---------------------

@pytest.mark.slow(why="repetition")
@settings(max_examples=40, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(cases_and_units())
def test_the_check_gives_the_same_verdict_on_the_same_trajectory_in_other_units(drawn):
    case, units = drawn
    system, solution = run_case(case)
    if solution.steps < 2:
        return
    t, z = solution.t, np.hstack([solution.q, solution.p])
    n = case.system.n
    other = case.in_units(units).hamiltonian_system()
    t2 = units.t * t + units.t_shift
    z2 = np.hstack([units.q * z[:, :n] + units.shift, units.p * z[:, n:]])
    level = level2 = None
    accuracy = solution.verdict.as_dict()
    if accuracy["level"] is not None:
        clock = t[0] + (t[1] - t[0]) / 2
        level = Level(accuracy["level"], clock)
        level2 = Level(units.q * units.p / units.t * accuracy["level"] + units.offset,
                       units.t * clock + units.t_shift)
    a, _ = Judgement(system, [], Tolerance()).report(t, z, level=level)
    b, _ = Judgement(other, [], Tolerance()).report(t2, z2, level=level2)
    # away from the thresholds (a ratio within 1e-6 of its limit may round either way)
    for figure, limit in (("error_max", "global_tol"), ("local_error_max", "rtol")):
        if abs(a[figure] / a[limit] - 1) < 1e-6:
            return
    assert_same(a, b, units, rel=1e-6)
