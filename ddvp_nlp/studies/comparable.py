"""What every study needs of a scene: that the compared methods can run it, and the reference
solution ``z_ref(t)`` their errors are measured against."""

from __future__ import annotations

import time
from collections.abc import Mapping

import numpy as np

from ..errors import InputError
from ..scenes import RunConfig, Scene
from ..solvers import exact_reference

# The comparisons' reference: the exact flow's pair of runs at this tolerance (the finer at a
# tenth of it), its own error said beside every error it measures.
REFERENCE_RTOL = 1e-12


def check_comparable(scene) -> None:
    """The compared methods need H (or a first-order L): not a higher-order scene."""
    if not isinstance(scene, Scene):
        raise InputError(f"scene {scene.name!r} has higher derivatives; compare, stress and "
                         "sweep take Hamiltonian and first-order Lagrangian scenes")


def check_starts_from_p0(scene, config: RunConfig) -> None:
    """The compared methods all start from (q0, p0); a march from v0 has a p0 of its own."""
    if config.p0 is None:
        raise InputError(f"scene {scene.name!r} starts from v0; the comparison needs p0 "
                         "(`settings` p0=...)")


REFERENCE_KINDS = ("auto", "exact", "flow", "none")


class ComparisonReference:
    """``z_ref(t)`` of a run configuration: the scene's exact solution, the exact flow (the one
    reference every verdict uses, ``solvers/exact/``), or none (``kind="none"``: the
    trajectory error is not measured, the energy error of an autonomous ``H`` still is).

    ``kind="auto"`` takes the exact solution where the scene has one that covers the start
    (an exact function raises ``ValueError`` for a start it does not cover, e.g. an unbound
    Kepler orbit), else the exact flow at ``REFERENCE_RTOL`` (its run at a tenth of it, its
    own error ``error`` in units of the motion's size)."""

    def __init__(self, scene: Scene, config: RunConfig, kind: str = "auto"):
        if kind not in REFERENCE_KINDS:
            raise InputError(f"reference must be one of {', '.join(REFERENCE_KINDS)}, "
                             f"got {kind!r}")
        self.system = scene.system
        self.config = config
        self.theta = scene.system.parameter_vector(config.params)
        self._exact = self._dense = None
        self.steps = 0
        self.error = 0.0
        started = time.perf_counter()
        if kind in ("auto", "exact") and self._exact_covers(scene, config):
            self.kind = "exact solution"
            self._exact = scene.exact
        elif kind == "exact":
            raise InputError(f"scene {scene.name!r} has no exact solution for this start")
        elif kind == "none":
            self.kind = "none (trajectory error not measured)"
        else:
            reference = exact_reference(scene.system, np.concatenate([config.q0, config.p0]),
                                        config.t0, config.t_end, self.theta,
                                        rtol=REFERENCE_RTOL)
            if not (reference.fine.success and reference.coarse.success):
                raise RuntimeError(f"the reference solution failed: {reference.fine.status}")
            self._dense = reference.fine
            self.steps = reference.fine.steps
            ends = np.array([config.t_end])
            scale = reference.fine.nodes()[1]
            scale = np.ptp(scale, axis=0) + np.finfo(float).tiny
            self.error = float(reference.error(ends, scale)[0])
            self.kind = (f"the exact flow (adaptive DOP853 at rtol {reference.rtol:g}; its own "
                         f"error at most {self.error:.1e} of the motion's range)")
        self.seconds = time.perf_counter() - started

    @property
    def measures_trajectory(self) -> bool:
        return self._exact is not None or self._dense is not None

    @staticmethod
    def _exact_covers(scene: Scene, config: RunConfig) -> bool:
        if scene.exact is None:
            return False
        try:
            scene.exact(np.array([config.t0]), config.q0, config.p0, config.t0, **config.params)
        except ValueError:
            return False
        return True

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Reference states at times ``t``, shape ``(N, 2n)`` (NaN where there is none)."""
        c = self.config
        if self._exact is not None:
            q, p = self._exact(t, c.q0, c.p0, c.t0, **c.params)
            return np.hstack([np.reshape(q, (t.size, -1)), np.reshape(p, (t.size, -1))])
        if self._dense is None:
            return np.full((t.size, 2 * self.system.n), np.nan)
        return self._dense.z(t)


_REFERENCES: dict = {}


def reference_for(scene: Scene, overrides: Mapping[str, object],
                  kind: str = "auto") -> ComparisonReference:
    """The reference of a scene and its overrides, computed once per process (every run of a
    grid on one worker shares it)."""
    key = (scene.source or id(scene), scene.name, repr(sorted(dict(overrides).items())), kind)
    if key not in _REFERENCES:
        _REFERENCES[key] = ComparisonReference(scene, scene.resolve(overrides), kind)
    return _REFERENCES[key]
