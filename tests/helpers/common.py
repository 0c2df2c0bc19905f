"""Helpers shared by the tests (imported as ``helpers.common``; tests/conftest.py puts tests/
on the path)."""

import numpy as np

from ddvp_nlp import load_scene, march


def run_scene(name, overrides=None, **kwargs):
    """March a built-in scene with its defaults, ``overrides`` applied to them."""
    scene = load_scene(name)
    config = scene.resolve(overrides or {})
    options = {"tau0": config.tau0, "params": config.params, **kwargs}
    return scene, config, march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                                **options)


def fitted_order(steps, errors):
    """Slope of log(error) against log(step) by least squares."""
    return float(np.polyfit(np.log(steps), np.log(errors), 1)[0])
