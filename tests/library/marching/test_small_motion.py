"""Small oscillations march (found when the step acceptance's scales were taken from the motion
alone, then reverted): the pendulum's energy row evaluates ``1 - cos q``, whose round-off is
``eps`` of the terms' size (about 1), not of the motion's energy (``q^2/2``); an acceptance test
relative to the motion's energy alone refused the pendulum at amplitude 1e-3 after 2 steps. Any
scale for the energy row must allow the round-off of H's own evaluation."""

from __future__ import annotations

import numpy as np
import pytest

from ddvp_nlp import load_scene, march


@pytest.mark.parametrize("amplitude", [1e-3, 1e-6])
@pytest.mark.parametrize("scheme", ["vddvp", "fixed"])
def test_a_pendulum_marches_its_small_oscillations(amplitude, scheme):
    scene = load_scene("pendulum")
    config = scene.resolve({})
    solution = march(scene.system, np.asarray(config.q0) * amplitude,
                     np.asarray(config.p0) * amplitude, (0.0, 5.0), tau0=0.05, scheme=scheme)
    assert solution.success, solution.message
    assert solution.steps >= 80
    assert solution.verdict.name == "accurate"
