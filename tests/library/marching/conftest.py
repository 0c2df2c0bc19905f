"""Fixtures of the marching tests."""

import functools

import pytest

from ddvp_nlp import load_scene, march


@pytest.fixture(scope="session")
def scene_of():
    """``load_scene``, once per built-in scene for the session: a march's functions are built
    once per system (ddvp_nlp/cache.py), so the tests that march the same scene share them
    instead of building them again (0.2-0.3 s of CPU a fresh scene). For tests that only read
    the scene; a test that counts builds, replaces a builder or needs a fresh system makes its
    own (``HamiltonianSystem(...)``: the scenes ``load_scene`` returns for one file share one
    system while any of them lives)."""
    return functools.cache(load_scene)


@pytest.fixture(scope="session")
def run_shared(scene_of):
    """``helpers.common.run_scene`` on the scenes of `scene_of`."""
    def run(name, overrides=None, **kwargs):
        scene = scene_of(name)
        config = scene.resolve(overrides or {})
        options = {"tau0": config.tau0, "params": config.params, **kwargs}
        return scene, config, march(scene.system, config.q0, config.p0,
                                    (config.t0, config.t_end), **options)
    return run
