"""``ddvp sweep``: your own grid of runs (scene parameters and settings by methods), run like the
stress grid, on local worker processes or a Dask cluster, resumable.

A grid is given on the command line (``--grid e=0.5:0.95:10 --grid tau0=0.01,0.005``) or in a
TOML file::

    scene = "kepler"
    methods = ["vddvp", "rk4", "dop853"]      # optional: default every method that applies

    [settings]                                # optional: fixed overrides
    t_end = 62.83

    [grid]                                    # one axis per name: a list, or from/to/count
    e = { from = 0.5, to = 0.95, count = 10 }
    tau0 = [0.01, 0.005]

    [bounds]                                  # optional
    max_steps = 1000000
    time_limit = 60.0

An axis is a scene parameter or a run setting (``t0``, ``t_end``); ``tau0`` is the step of every
step method (the first step of ``vddvp``/``lee``) and ``rtol`` the tolerance of DOP853.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from ..scenes import load_scene
from .compare import _comparable
from .methods import METHODS, get_methods
from .stress import DOP853_RTOL, STRESS_METHODS, Case

TOP_KEYS = ("scene", "methods", "settings", "grid", "bounds")
RANGE_KEYS = ("from", "to", "count")
BOUND_KEYS = ("max_steps", "time_limit")


@dataclass
class SweepSpec:
    """What to sweep: a scene, methods, fixed settings, axes and bounds."""

    scene: str
    axes: dict[str, list[float]]
    methods: tuple = STRESS_METHODS
    settings: dict = field(default_factory=dict)
    max_steps: int = 2_000_000
    time_limit: float = 60.0


def parse_axis(name: str, text: str) -> list[float]:
    """``FROM:TO:COUNT`` (evenly spaced, both ends included) or ``V1,V2,...``."""
    where = f"--grid {name}"
    try:
        if ":" in text:
            start, stop, count = text.split(":")
            return _range(where, float(start), float(stop), int(count))
        return [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"{where}: expected FROM:TO:COUNT or V1,V2,..., got {text!r}") from None


def _range(where, start, stop, count):
    if count < 1:
        raise InputError(f"{where}: count must be >= 1, got {count}")
    if count == 1:
        return [start]
    return [start + (stop - start) * i / (count - 1) for i in range(count)]


def load_grid_file(path: str | Path) -> SweepSpec:
    """Read a TOML grid; an unknown key is an error that gives the key's path."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib

    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except OSError as exc:
        raise InputError(f"grid file {str(path)!r} cannot be read: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"grid file {str(path)!r} is not valid TOML: {exc}") from None
    where = str(path)
    _known(where, data, TOP_KEYS, "")
    if not isinstance(data.get("scene"), str):
        raise InputError(f"{where}: 'scene' must be a scene name or file, got "
                         f"{data.get('scene')!r}")
    grid = data.get("grid")
    if not isinstance(grid, dict) or not grid:
        raise InputError(f"{where}: '[grid]' must list at least one axis")
    axes = {}
    for name, value in grid.items():
        key = f"grid.{name}"
        if isinstance(value, dict):
            _known(where, value, RANGE_KEYS, key + ".")
            missing = [k for k in RANGE_KEYS if k not in value]
            if missing:
                raise InputError(f"{where}: '{key}' needs {', '.join(RANGE_KEYS)}; missing "
                                 f"{missing[0]!r}")
            if not all(_number(value[k]) for k in ("from", "to")) or \
                    not isinstance(value["count"], int) or isinstance(value["count"], bool):
                raise InputError(f"{where}: '{key}' must have numbers from, to and an integer "
                                 f"count, got {value!r}")
            axes[name] = _range(f"{where}: '{key}'", float(value["from"]), float(value["to"]),
                                value["count"])
        elif isinstance(value, list) and value and all(_number(v) for v in value):
            axes[name] = [float(v) for v in value]
        else:
            raise InputError(f"{where}: '{key}' must be a list of numbers or "
                             f"{{from, to, count}}, got {value!r}")
    bounds = data.get("bounds", {})
    if not isinstance(bounds, dict):
        raise InputError(f"{where}: '[bounds]' must be a table, got {bounds!r}")
    _known(where, bounds, BOUND_KEYS, "bounds.")
    settings = data.get("settings", {})
    if not isinstance(settings, dict):
        raise InputError(f"{where}: '[settings]' must be a table, got {settings!r}")
    methods = data.get("methods", list(STRESS_METHODS))
    if not isinstance(methods, list) or not all(isinstance(m, str) for m in methods):
        raise InputError(f"{where}: 'methods' must be a list of method names, got {methods!r}")
    return SweepSpec(scene=data["scene"], axes=axes,
                     methods=tuple(m.name for m in get_methods(methods)), settings=settings,
                     max_steps=bounds.get("max_steps", 2_000_000),
                     time_limit=bounds.get("time_limit", 60.0))


def _known(where, table, known, prefix):
    for key in table:
        if key not in known:
            raise InputError(f"{where}: unknown key '{prefix}{key}' (known: "
                             f"{', '.join(known)})")


def _number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)


def sweep_cases(spec: SweepSpec) -> list[Case]:
    """The product of the axes, one :class:`Case` per point; every point's settings are
    checked against the scene before anything runs."""
    scene = load_scene(spec.scene)
    _comparable(scene)
    names = list(spec.axes)
    cases = []
    for point in itertools.product(*(spec.axes[n] for n in names)):
        values = dict(zip(names, point, strict=True))
        settings = {**spec.settings, **{k: v for k, v in values.items()
                                        if k not in ("tau0", "rtol")}}
        config = scene.resolve({**settings, **({"tau0": values["tau0"]}
                                               if "tau0" in values else {})})
        tau = config.tau0
        if tau > config.t_end - config.t0:
            raise InputError(f"tau0 = {tau!r} is longer than t_end - t0 = "
                             f"{config.t_end - config.t0!r} at {values}")
        rtol = values.get("rtol", DOP853_RTOL)
        if not rtol > 0:
            raise InputError(f"rtol must be > 0, got {rtol!r}")
        label = ", ".join(f"{k}={v:g}" for k, v in values.items())
        cases.append(Case(scene.name if "/" not in spec.scene else spec.scene, label,
                          spec.scene, settings, tau, methods=spec.methods, rtol=rtol))
    for method in spec.methods:
        reason = METHODS[method].applies(scene.system)
        if reason:
            raise InputError(f"method {method!r} does not apply to scene {scene.name!r}: "
                             f"{reason}")
    return cases
