"""``ddvp sweep``: your own grid of runs (scene parameters and settings by methods), run like the
stress grid, on local worker processes or a Dask cluster, resumable.

A grid is given on the command line (``--grid e=0.5:0.95:10 --grid tau0=0.01,0.005``) or in a
TOML file (read by `ddvp_nlp.studies.sweep_file`) as a `SweepSpec`;
`sweep_cases` turns it into the stress grid's cases.

An axis is a scene parameter or a run setting (``t0``, ``t_end``); ``tau0`` is the step of every
step method (the first step of ``vddvp``/``lee``) and ``rtol`` the tolerance of DOP853.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

from ..errors import InputError
from ..scenes import load_scene
from ..validation import check_real
from .comparable import check_comparable
from .methods import METHODS
from .stress import DEFAULT_METHODS, DOP853_RTOL, StressCase


@dataclass
class SweepSpec:
    """What to sweep: a scene, methods, fixed settings, axes and bounds."""

    scene: str
    axes: dict[str, list[float]]
    methods: tuple = DEFAULT_METHODS
    settings: dict = field(default_factory=dict)
    max_steps: int = 2_000_000
    time_limit: float = 60.0


def parse_axis(name: str, text: str) -> list[float]:
    """``FROM:TO:COUNT`` (evenly spaced, both ends included) or ``V1,V2,...``."""
    where = f"grid {name}"
    try:
        if ":" in text:
            start, stop, count = text.split(":")
            return evenly_spaced(where, float(start), float(stop), int(count))
        return [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"{where}: expected FROM:TO:COUNT or V1,V2,..., got {text!r}") from None


def evenly_spaced(where, start, stop, count) -> list[float]:
    """``count`` values from ``start`` to ``stop``, both ends included."""
    if count < 1:
        raise InputError(f"{where}: count must be >= 1, got {count}")
    if count > MAX_POINTS:
        raise InputError(f"{where}: count must be at most {MAX_POINTS}, got {count}")
    if count == 1:
        return [start]
    return [start + (stop - start) * i / (count - 1) for i in range(count)]


def sweep_cases(spec: SweepSpec) -> list[StressCase]:
    """The product of the axes, one `StressCase` per point; every point's settings are
    checked against the scene before anything runs."""
    scene = load_scene(spec.scene)
    check_comparable(scene)
    names = list(spec.axes)
    size = math.prod(len(spec.axes[n]) for n in names)
    if size > MAX_POINTS:
        raise InputError(f"the grid has {size} points, more than {MAX_POINTS}; split it into "
                         "several sweeps")
    cases = [_case_at(scene, spec, dict(zip(names, point, strict=True)))
             for point in itertools.product(*(spec.axes[n] for n in names))]
    for method in spec.methods:
        reason = METHODS[method].applies(scene.system)
        if reason:
            raise InputError(f"method {method!r} does not apply to scene {scene.name!r}: "
                             f"{reason}")
    return cases


# Points of one grid: a grid of 10**8 ran for minutes with no output before any task started.
MAX_POINTS = 100_000


def _case_at(scene, spec: SweepSpec, values: dict) -> StressCase:
    """The case at one point of the grid (``values``: one value per axis)."""
    settings = {**spec.settings, **{k: v for k, v in values.items()
                                    if k not in ("tau0", "rtol")}}
    config = scene.resolve({**settings, **({"tau0": values["tau0"]}
                                           if "tau0" in values else {})})
    tau = config.tau0
    if tau > config.t_end - config.t0:
        raise InputError(f"tau0 = {tau!r} is longer than t_end - t0 = "
                         f"{config.t_end - config.t0!r} at {values}")
    rtol = check_real("rtol", values.get("rtol", DOP853_RTOL), positive=True)
    label = ", ".join(f"{k}={v:g}" for k, v in values.items())
    return StressCase(scene.name if "/" not in spec.scene else spec.scene, label, spec.scene,
                      settings, tau, methods=spec.methods, rtol=rtol)
