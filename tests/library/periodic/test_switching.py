"""Branch switching at a branch point (``solvers/periodic/switching.py``): a pitchfork of two
coupled oscillators, where the family ``q2 = 0`` meets the 1:1 resonance and a branch with
``q2 != 0`` is born, switched onto and both halves followed (cheap: N = 40); the halves are
each other's images under ``(q2, p2) -> -(q2, p2)``; the same with the coordinates swapped and
an energy offset; the refusals. The CR3BP's halo branches against an independent differential
correction are the slow test at the end."""

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import (
    Continuation,
    HamiltonianSystem,
    InputError,
    Switch,
    follow_periodic_family,
    load_scene,
)
from ddvp_nlp.cli import main
from ddvp_nlp.solvers.periodic.switching import _chosen

W, BETA = 0.9, 0.5  # the q2 oscillator's frequency and the coupling beta q1^2 q2^2
NODES, HALF = 41, 4  # nodes of the grid, orbits of each half


def _oscillators(swap: bool = False, offset: float = 0.0) -> HamiltonianSystem:
    """``(p1^2 + q1^2)/2 + (p2^2 + W^2 q2^2)/2 + BETA q1^2 q2^2 + offset``; with ``swap`` the
    two coordinates exchanged. Along ``q2 = 0`` (period 2 pi) the ``q2`` motion's frequency
    ``sqrt(W^2 + BETA A^2)`` grows with the amplitude ``A`` until it meets 1: a pair of
    multipliers through +1, the branch point of the in-phase family ``q2 != 0``."""
    a, b = (1, 0) if swap else (0, 1)

    def hamiltonian(q, p, t):
        return ((p[a] ** 2 + q[a] ** 2) / 2 + (p[b] ** 2 + W ** 2 * q[b] ** 2) / 2
                + BETA * q[a] ** 2 * q[b] ** 2 + offset)
    return HamiltonianSystem(hamiltonian, 2, name=f"pitchfork_{int(swap)}_{offset}")


def _follow(swap: bool = False, offset: float = 0.0, energies=(0.1, 0.3), switch=None,
            min_step: float = 1e-4):
    a = 1 if swap else 0
    t = np.linspace(0.0, 2 * np.pi, NODES)
    amplitude = np.sqrt(2 * energies[0])
    q, p = np.zeros((NODES, 2)), np.zeros((NODES, 2))
    q[:, a], p[:, a] = amplitude * np.cos(t), -amplitude * np.sin(t)
    return follow_periodic_family(
        _oscillators(swap, offset), (energies[0] + offset, energies[1] + offset), nodes=NODES,
        section=f"p{a + 1}=0", guess={"t": t, "q": q, "p": p},
        continuation=Continuation(step=0.05, switch=switch or Switch(orbits=HALF, tol=None),
                                  min_step=min_step))


@pytest.fixture(scope="module")
def switched():
    return _follow()


def test_both_halves_of_the_new_branch_are_followed_and_verified(switched):
    [point] = switched.bifurcations
    assert point.kind == "branch point" and 0.1 < point.energy < 0.2
    assert switched.switched.startswith("switched at bifurcation 1 (branch point")
    assert sorted(b.label for b in switched.branches) == ["+q2", "-q2"]
    for branch in switched.branches:
        assert branch.at == 1 and branch.residual < 1e-10
        assert branch.family.complete and len(branch.family.members) == HALF
        for member in branch.family.members:
            assert member.orbit.success and member.stability.exact_orbit.converged
            # off the followed family: q2 moves, and grows along the half
        heights = [np.max(np.abs(m.orbit.q[:, 1])) for m in branch.family.members]
        assert heights[0] > 1e-2 and np.all(np.diff(heights) > 0)
        sign = 1 if branch.label == "+q2" else -1
        assert all(sign * m.orbit.q[0, 1] > 0 for m in branch.family.members)


def test_the_two_halves_are_mirror_images(switched):
    """``(q2, p2) -> -(q2, p2)`` is a symmetry of H; the kernel direction is odd under it, so
    the halves are each other's images (to the corrector's tolerance, not bit for bit)."""
    plus, minus = ({b.label: b.family.members for b in switched.branches}[k]
                   for k in ("+q2", "-q2"))
    for a, b in zip(plus, minus, strict=True):
        assert abs(a.energy - b.energy) < 1e-9
        assert abs(a.orbit.orbit.period - b.orbit.orbit.period) < 1e-9
        assert np.max(np.abs(a.orbit.q * [1, -1] - b.orbit.q)) < 1e-8
        assert np.max(np.abs(a.orbit.p * [1, -1] - b.orbit.p)) < 1e-8


def test_coordinates_swapped_and_energy_offset_give_the_same_branches(switched):
    """The same system with ``q1 <-> q2`` and ``H + 0.25``: the branch point and every orbit of
    both halves at energies 0.25 higher, the same periods, the coordinates swapped."""
    other = _follow(swap=True, offset=0.25)
    assert abs(other.bifurcations[0].energy - 0.25 - switched.bifurcations[0].energy) < 1e-9
    assert sorted(b.label for b in other.branches) == ["+q1", "-q1"]
    mine = {b.label[0]: b.family.members for b in switched.branches}
    theirs = {b.label[0]: b.family.members for b in other.branches}
    for sign in "+-":
        for a, b in zip(mine[sign], theirs[sign], strict=True):
            assert abs(b.energy - 0.25 - a.energy) < 1e-9
            assert abs(b.orbit.orbit.period - a.orbit.orbit.period) < 1e-9
            assert np.max(np.abs(b.orbit.q[:, ::-1] - a.orbit.q)) < 1e-8


def test_a_family_without_a_branch_point_says_there_is_nothing_to_switch_onto():
    family = _follow(energies=(0.02, 0.06), switch=Switch(orbits=2))
    assert family.complete and not family.bifurcations and family.branches == []
    assert "no branch point was located on the family" in family.switched


def test_a_half_that_cannot_be_started_says_why_and_reports_no_orbit():
    """A first step of 1000 in the arclength, halved once (``min_step`` 0.5): the corrector
    finds no orbit there; each half is empty, incomplete, and says why."""
    family = _follow(switch=Switch(orbits=3, step=1000.0), min_step=0.5)
    assert len(family.branches) == 2
    for branch in family.branches:
        assert branch.family.members == [] and not branch.family.complete
        assert branch.family.message.startswith(
            "the first orbit off the branch point was not found: a step below 500 failed")
    assert "-q2: 0 orbits" in family.switched and "+q2: 0 orbits" in family.switched


def test_the_bifurcation_to_switch_at_is_chosen_or_refused_by_name():
    fold = SimpleNamespace(kind="fold", energy=0.1)
    doubling = SimpleNamespace(kind="period doubling", energy=0.2)
    branch = SimpleNamespace(kind="branch point", energy=0.3)
    assert _chosen([fold, doubling, branch], Switch()) == (2, doubling)
    assert _chosen([fold, branch], Switch(at=2)) == (2, branch)
    assert _chosen([fold, doubling], Switch(at=2)) == (2, doubling)
    assert "is a fold: switching is done at branch points and period doublings" in _chosen(
        [fold, doubling], Switch(at=1))
    assert "(bifurcations located: fold)" in _chosen([fold], Switch())
    assert "at = 3, but 2 bifurcation(s)" in _chosen([fold, branch], Switch(at=3))


@settings(max_examples=30, deadline=None)
@given(st.one_of(st.integers(max_value=1), st.sampled_from([1.5, "4", None])))
def test_a_bad_orbit_count_is_refused_by_name(orbits):
    with pytest.raises(InputError, match="orbits"):
        Switch(orbits=orbits)


@settings(max_examples=30, deadline=None)
@given(st.one_of(st.floats(max_value=0.0), st.just(float("nan")), st.just(float("inf"))))
def test_a_bad_step_is_refused_by_name(step):
    with pytest.raises(InputError, match="step"):
        Switch(step=step)


@settings(max_examples=20, deadline=None)
@given(st.one_of(st.integers(max_value=0), st.just(2.5)))
def test_a_bad_bifurcation_number_is_refused_by_name(at):
    with pytest.raises(InputError, match="at"):
        Switch(at=at)


def test_a_switch_that_is_not_one_is_refused_before_any_orbit():
    with pytest.raises(InputError, match="switch must be a Switch, True or None"):
        Continuation(switch="yes")
    assert Continuation(switch=True).switch == Switch()
    assert Continuation(switch=False).switch is None


@pytest.mark.parametrize("argv, text", [
    (["--energy", "0.5", "--switch", "3"], "--switch needs --follow E_END"),
    (["--energy", "0.5", "--follow", "0.6", "--switch", "1"],
     "--switch must be an integer >= 2, got 1"),
    (["--energy", "0.5", "--follow", "0.6", "--switch", "x"],
     "argument --switch: invalid int value"),
    (["--energy", "0.5", "--follow", "0.6", "--switch-tol", "1e-4"],
     "--switch-tol 1e-4 needs --switch"),
    (["--energy", "0.5", "--follow", "0.6", "--switch", "--switch-tol", "-0.5"],
     "--switch-tol must be a positive number or 'none', got '-0.5'"),
])
def test_the_command_line_refuses_a_bad_switch_by_its_flag(argv, text, tmp_path, capsys):
    try:
        code = main(["periodic", "harmonic", "--nodes", "40", "--no-plot", *argv, "--out",
                     str(tmp_path / "out")])
    except SystemExit as exc:  # argparse's own refusal
        code = exc.code
    assert code == 2
    assert text in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


BENCHMARKS = Path(__file__).resolve().parents[3] / "scripts" / "benchmarks"


# the CR3BP family to its branch point and 20 halo orbits on each side at N = 400, each closed on
# the exact flow, then corrected by DOP853: minutes of CPU
@pytest.mark.slow(why="study")
def test_halo_branches_match_an_independent_differential_correction():
    """Issue 46's target: from the L1 Lyapunov family, both halves of the halo branch for 20
    orbits; each orbit's period within 1e-4 of Howell's differential correction at its energy
    and its Jacobi constant within 1e-4 of the correction at its z0
    (scripts/benchmarks/halo_correction.py: scipy's DOP853, no solver of this package); the
    halves are each other's images under z -> -z."""
    sys.path.insert(0, str(BENCHMARKS))
    try:
        from halo_correction import correct
    finally:
        sys.path.remove(str(BENCHMARKS))
    scene = load_scene("cr3bp")
    mu = scene.params["mu"]
    family = follow_periodic_family(
        scene.system, (-1.5935, -1.585), nodes=401, section="q2=0",
        guess=scene.periodic.guess(-1.5935, mu=mu),
        continuation=Continuation(step=0.0005, switch=Switch(orbits=20)))
    assert [b.label for b in family.branches] in (["+q3", "-q3"], ["-q3", "+q3"])
    halves = {b.label: b.family.members for b in family.branches}
    for label, members in halves.items():
        assert len(members) == 20, label
        for member in members:
            orbit = member.orbit
            assert orbit.success and member.stability.exact_orbit.converged
            x0, z0, vy0 = orbit.q[0, 0], orbit.q[0, 2], orbit.p[0, 1] - orbit.q[0, 0]
            period = float(orbit.orbit.period)
            at_energy = correct(x0, z0, vy0, mu, period, jacobi_constant=-2 * member.energy)
            at_height = correct(x0, z0, vy0, mu, period)
            assert abs(period - at_energy.period) < 1e-4
            assert abs(-2 * member.energy - at_height.jacobi) < 1e-4
    # each member sits where the corrector's arclength row put it, to that row's tolerance:
    # the halves' members were 1.5e-7 of arclength apart, 1.1e-7 in energy (1e-7 before the
    # unfolding's metric, which enters the arclength's norm), their orbits 1e-6 apart
    for a, b in zip(halves["+q3"], halves["-q3"], strict=True):
        assert abs(a.energy - b.energy) < 2e-7
        assert np.max(np.abs(a.orbit.q * [1, 1, -1] - b.orbit.q)) < 1e-6


@settings(max_examples=80, deadline=None)
@given(text=st.text(max_size=8) | st.floats(allow_nan=True).map(repr) | st.just("None"))
def test_any_switch_tol_is_a_positive_number_none_or_refused_by_its_flag(text):
    from types import SimpleNamespace

    from ddvp_nlp.cli.orbit_commands import switch_tol

    try:
        got = switch_tol(SimpleNamespace(switch=20, switch_tol=text))
    except InputError as exc:
        assert str(exc).startswith("--switch-tol must be")
        return
    tol = got["tol"]
    assert tol is None and text.strip().lower() == "none" or 0 < tol < np.inf
    assert Switch(tol=tol).tol == tol  # what the command hands on, the API takes
