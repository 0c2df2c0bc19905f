"""What every study needs of a scene: that the compared methods can run it, and the reference
solution ``z_ref(t)`` their errors are measured against."""

from __future__ import annotations

import time
from collections.abc import Mapping

import numpy as np

from ..errors import InputError
from ..scenes import RunConfig, Scene
from .methods import dop853

REFERENCE_RTOL = 1e-13


def check_comparable(scene) -> None:
    """The compared methods need H (or a first-order L): not a higher-order scene."""
    if not isinstance(scene, Scene):
        raise InputError(f"scene {scene.name!r} has higher derivatives; compare, stress and "
                         "sweep take Hamiltonian and first-order Lagrangian scenes")


def check_starts_from_p0(scene, config: RunConfig) -> None:
    """The compared methods all start from (q0, p0); a march from v0 has a p0 of its own."""
    if config.p0 is None:
        raise InputError(f"scene {scene.name!r} starts from v0; the comparison needs p0 "
                         "(--set p0=...)")


class Reference:
    """``z_ref(t)`` of a run configuration: the scene's exact solution or a DOP853 solution."""

    def __init__(self, scene: Scene, config: RunConfig):
        self.system = scene.system
        self.config = config
        self.theta = scene.system.parameter_vector(config.params)
        started = time.perf_counter()
        if scene.exact is not None:
            self.kind = "exact solution"
            self._exact = scene.exact
            self._dense = None
        else:
            self.kind = f"DOP853 at rtol = atol = {REFERENCE_RTOL:g}"
            solution = dop853(scene.system, config, REFERENCE_RTOL, dense_output=True)
            if not solution.success:
                raise RuntimeError(f"the reference solution failed: {solution.message}")
            self._dense = solution.dense
            self.steps = solution.steps
        self.seconds = time.perf_counter() - started

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Reference states at times ``t``, shape ``(N, 2n)``."""
        c = self.config
        if self._dense is None:
            q, p = self._exact(t, c.q0, c.p0, c.t0, **c.params)
            return np.hstack([np.reshape(q, (t.size, -1)), np.reshape(p, (t.size, -1))])
        return self._dense(t).T


_REFERENCES: dict = {}


def reference_for(scene: Scene, overrides: Mapping[str, object]) -> Reference:
    """The reference of a scene and its overrides, computed once per process (every run of a
    grid on one worker shares it)."""
    key = (scene.source or id(scene), scene.name, repr(sorted(dict(overrides).items())))
    if key not in _REFERENCES:
        _REFERENCES[key] = Reference(scene, scene.resolve(overrides))
    return _REFERENCES[key]
