"""The C references of scripts/bench_march.py: the fast C march solves the same equations as
the first one (same steps, same nodes up to the accumulated round-off) with few Newton
iterations, whichever predictor it starts from."""

import ctypes
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from ddvp_nlp import load_scene

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"


@pytest.fixture(scope="module")
def library(tmp_path_factory):
    if shutil.which("gcc") is None:
        pytest.skip("no C compiler")
    sys.path.insert(0, str(SCRIPTS))
    try:
        from bench_march import c_march_library
    finally:
        sys.path.remove(str(SCRIPTS))
    return c_march_library(tmp_path_factory.mktemp("c_march"))


@pytest.mark.parametrize("name, kind, overrides, iterations",
                         [("paper_pendulum", 0, {}, 4.0), ("fpu", 1, {"t_end": 20.0}, 6.0)])
def test_fast_c_march_solves_the_same_equations(library, name, kind, overrides, iterations):
    scene = load_scene(name)
    config = scene.resolve(overrides)
    system = scene.system
    n = system.n
    theta = np.zeros(4)
    values = system.parameter_vector(config.params)
    theta[:values.size] = values
    z0 = np.concatenate([config.q0, config.p0])
    capacity = 30_000

    def arrays():
        return np.empty(capacity + 1), np.empty((capacity + 1, 2 * n)), np.empty(capacity + 1)

    t, z, H = arrays()
    steps = library.c_march(kind, n, theta, z0, config.t0, config.tau0, config.t_end, capacity,
                            1e-10, t, z, H)
    assert steps > 1000
    for predictor in (0, 1, 2):
        count = ctypes.c_long(0)
        t2, z2, H2 = arrays()
        fast = library.c_march_fast(kind, n, theta, z0, config.t0, config.tau0, config.t_end,
                                    capacity, 1e-10, predictor, t2, z2, H2, ctypes.byref(count))
        assert fast == steps
        assert np.max(np.abs(t2[:steps + 1] - t[:steps + 1])) < 1e-2
        assert np.max(np.abs(z2[:steps + 1] - z[:steps + 1])) < 1e-2
        assert np.max(np.abs(H2[:steps + 1] - H[:steps + 1])) < 1e-4
        assert count.value <= iterations * steps  # Newton updates in all
