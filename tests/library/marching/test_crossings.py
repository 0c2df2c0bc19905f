"""Poincare crossings located by the dense output, against DOP853's event location."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ddvp_nlp import load_scene, march
from ddvp_nlp.errors import InputError
from ddvp_nlp.physics.hamiltonian import vector_field_function
from ddvp_nlp.studies.poincare import crossings, section_starts


def test_crossings_lie_on_the_section_and_converge_to_dop853_at_the_schemes_order():
    system = load_scene("henon_heiles").system
    theta = system.parameter_vector(None)
    z0 = section_starts(system, theta, 1 / 12, "q1=0", 1, seed=1)[0]
    field = vector_field_function(system)

    def upward(t, z):
        return z[0]
    upward.direction = 1
    t_end = 25.0
    reference = solve_ivp(lambda t, z: np.asarray(field(z, t, theta)).ravel(), (0, t_end), z0,
                          method="DOP853", rtol=1e-13, atol=1e-13, events=upward)
    later = reference.t_events[0] > 1e-6  # the start lies on the section: not a crossing
    t_ref, z_ref = reference.t_events[0][later], reference.y_events[0][later]
    assert t_ref.size == 3
    errors = []
    for tau0 in (0.1, 0.05, 0.025):
        solution = march(system, z0[:2], z0[2:], (0.0, t_end), tau0=tau0)
        t, z = crossings(system, theta, solution.t, np.hstack([solution.q, solution.p]), 0, 0.0,
                         "+")
        assert t.size == 3 and np.max(np.abs(z[:, 0])) <= 1e-12  # on the section
        errors.append(max(np.max(np.abs(z - z_ref)), np.max(np.abs(t - t_ref))))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all((orders > 1.8) & (orders < 2.2)), orders  # the scheme's order, 2
    assert errors[-1] < 1e-3


@pytest.mark.slow(why="processes")
def test_a_section_on_a_dask_cluster_is_the_local_one():
    import dask
    from distributed import LocalCluster

    from ddvp_nlp.studies.poincare import poincare_section

    system = load_scene("henon_heiles").system
    options = dict(orbits=3, tau0=0.05, t_end=30.0, seed=2)
    local = poincare_section(system, 1 / 12, **options)
    with dask.config.set({"distributed.scheduler.allowed-failures": 1}):
        cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                               dashboard_address=None)
    with cluster:
        remote = poincare_section(system, 1 / 12, scene="henon_heiles",
                                  scheduler=cluster.scheduler_address, **options)
        with pytest.raises(InputError, match="scene="):
            poincare_section(system, 1 / 12, scheduler=cluster.scheduler_address, **options)
    assert remote.statuses == local.statuses == ["success"] * 3
    assert np.array_equal(remote.points, local.points) and np.array_equal(remote.orbit,
                                                                          local.orbit)
