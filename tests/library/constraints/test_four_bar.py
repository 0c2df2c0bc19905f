"""A closed four-bar linkage in Cartesian coordinates (``problems/four_bar.py``): three rods
close a loop through the ground, so the constraint Jacobian can lose rank (a parallelogram laid
flat) and a user can write a redundant rod. The march keeps the rods at round-off with at most
5 Newton updates a step, fixed and energy-determined (the linkage lies on a table: the energy
row's c = |G'nu|^2 / 8 > 0); a redundant rod at the start is refused by name; a parallelogram
passes its flat (change) point on its own branch; metamorphic: a time offset, a scaled linkage,
the two joints relabelled.

The marches run on CasADi's virtual machine (``compiler=None``): the same step functions as the
compiled chunks (``test_constrained_march.py`` runs those), without a C compile per variant."""

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import Compilation, HamiltonianSystem, InputError, load_scene, march
from ddvp_nlp.discrete.constrained import solvability_function

VM = Compilation(compiler=None)
SPAN = (0, 4)


def linkage(order=(0, 1), name="four_bar"):
    """A four-bar with rods scaled by the parameter ``L`` (crank L, coupler cL, rocker rL,
    ground gL); ``order`` (1, 0) stores joint C before joint B."""
    def H(q, p, t, L, c, r, g):
        return ca.dot(p, p) / 2

    def rods(q, t, L, c, r, g):
        B, C = [ca.vertcat(q[2 * k], q[2 * k + 1]) for k in order]
        D = ca.vertcat(g * L, 0)
        return [ca.dot(B, B) - L ** 2, ca.dot(C - B, C - B) - (c * L) ** 2,
                ca.dot(C - D, C - D) - (r * L) ** 2]
    return HamiltonianSystem(H, 4, {"L": 1.0, "c": 3.0, "r": 2.5, "g": 3.0}, name=name,
                             constraints=rods)


# the linkage as one system for the module (other sizes are the parameter L): a march's
# functions are built once per system (ddvp_nlp/cache.py)
LINKAGE = linkage()


def scene_start():
    scene = load_scene("four_bar")
    return scene, np.array(scene.q0), np.array(scene.p0)


def crank_turns(solution):
    angle = np.unwrap(np.arctan2(solution.q[:, 1], solution.q[:, 0]))
    return (angle[-1] - angle[0]) / (2 * np.pi)


@pytest.mark.parametrize("scheme, updates", [("fixed", 2), ("vddvp", 5)])
def test_the_scene_keeps_its_rods_at_round_off_in_few_newton_updates(scheme, updates):
    scene, q0, p0 = scene_start()
    solution = march(scene.system, q0, p0, SPAN, tau0=scene.tau0, scheme=scheme, accuracy=None,
                     compilation=VM)
    record = solution.constraints
    assert solution.success, solution.message
    assert crank_turns(solution) > 1  # the crank goes all the way round
    assert record.newton_updates.max() <= updates
    # rods of length up to 3: |g| ~ L^2 at round-off
    assert record.constraint_residual.max() <= 1e-13
    assert record.hidden_residual.max() <= 1e-13
    H = float(np.dot(p0, p0) / 2)
    if scheme == "vddvp":
        assert np.abs(solution.energy_residual).max() <= 1e-13 * H
        z = np.hstack([solution.q, solution.p])
        c = np.asarray(solvability_function(scene.system).map(z.shape[0])(
            z.T, solution.t[None, :], np.zeros((0, z.shape[0])))).ravel()
        assert c.min() > 1  # the energy row keeps a positive root all along


def test_the_scene_is_the_linkage_of_the_parametrised_rods():
    scene, q0, p0 = scene_start()
    a = march(scene.system, q0, p0, (0, 1), tau0=0.01, scheme="fixed", accuracy=None,
              compilation=VM)
    b = march(LINKAGE, q0, p0, (0, 1), tau0=0.01, scheme="fixed", accuracy=None,
              compilation=VM)
    assert np.abs(a.q - b.q).max() <= 1e-13


def test_a_redundant_rod_is_refused_by_name_before_the_march():
    """A fourth row that repeats the coupler's rod in another form (the sum of two rows):
    the Jacobian has rank 3 of 4 rows; refused at the start, naming the redundancy."""
    def rods(q, t):
        g = [q[0] ** 2 + q[1] ** 2 - 1, (q[2] - q[0]) ** 2 + (q[3] - q[1]) ** 2 - 9,
             (q[2] - 3) ** 2 + q[3] ** 2 - 6.25]
        return [*g, g[0] + g[1]]
    system = HamiltonianSystem(lambda q, p, t: ca.dot(p, p) / 2, 5, name="four_bar_extra",
                               constraints=lambda q, t: rods(q, t))
    q0 = [0.0, 1.0, 2.61506, 2.47019, 0.0]
    with pytest.raises(InputError, match="redundant.*rank 3 < 4"):
        march(system, q0, [0.0] * 5, SPAN, tau0=0.01, compilation=VM)


def parallelogram():
    def rods(q, t):
        return [q[0] ** 2 + q[1] ** 2 - 1, (q[2] - q[0]) ** 2 + (q[3] - q[1]) ** 2 - 4,
                (q[2] - 2) ** 2 + q[3] ** 2 - 1]
    return HamiltonianSystem(lambda q, p, t: ca.dot(p, p) / 2, 4, name="parallelogram",
                             constraints=rods)


def test_a_parallelogram_laid_flat_at_the_start_is_refused_as_redundant():
    """All three rods along the ground line: their Jacobian has rank 2 (a change point)."""
    with pytest.raises(InputError, match="redundant"):
        march(parallelogram(), [1.0, 0.0, 3.0, 0.0], [0.0, 1.0, 0.0, 1.0], SPAN, tau0=0.01,
              compilation=VM)


@pytest.mark.parametrize("scheme", ["fixed", "vddvp"])
def test_a_parallelogram_passes_its_flat_point_on_its_own_branch(scheme):
    """Cranks of 1 on a ground of 2, coupler 2: at the flat configurations the rods' Jacobian
    loses a rank and the antiparallelogram branch meets this one. The crank turns through
    them; the coupler stays parallel to the ground (C - B = (2, 0)) and the rods at
    round-off."""
    q0, p0 = [0.0, 1.0, 2.0, 1.0], [-2.0, 0.0, -2.0, 0.0]
    solution = march(parallelogram(), q0, p0, SPAN, tau0=0.01, scheme=scheme, accuracy=None,
                     compilation=VM)
    assert solution.success, solution.message
    assert crank_turns(solution) > 1
    coupler = solution.q[:, 2:] - solution.q[:, :2]
    assert np.abs(coupler - [2.0, 0.0]).max() <= 1e-12
    assert solution.constraints.constraint_residual.max() <= 1e-13
    assert solution.constraints.newton_updates.max() <= 5


@pytest.mark.parametrize("scheme", ["fixed", "vddvp"])
def test_metamorphic_offset_scale_and_relabelling(scheme):
    """The same motion: started at t0 = 7 (the nodes shifted), in a linkage L = 2.5 times
    larger at the same angular speed (q and p times L, H and g times L^2, the same steps),
    and with joint C stored before joint B."""
    _, q0, p0 = scene_start()
    run = dict(tau0=0.01, scheme=scheme, accuracy=None, compilation=VM)
    plain = march(LINKAGE, q0, p0, (0, 2), **run)
    later = march(LINKAGE, q0, p0, (7, 9), **run)
    L = 2.5
    scaled = march(LINKAGE, L * q0, L * p0, (0, 2), params={"L": L}, **run)
    swap = [2, 3, 0, 1]
    relabelled = march(linkage(order=(1, 0), name="four_bar_cb"), q0[swap], p0[swap], (0, 2),
                       **run)
    for other, t_shift, factor, columns in [(later, 7, 1, slice(None)), (scaled, 0, L, slice(None)),
                                            (relabelled, 0, 1, swap)]:
        assert other.t.size == plain.t.size
        assert np.abs(other.t - t_shift - plain.t).max() <= 1e-10
        assert np.abs(other.q[:, columns] / factor - plain.q).max() <= 1e-9
