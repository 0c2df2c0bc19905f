"""A run's configuration resolved from a scene: the scene's defaults with the caller's
overrides (parameters, start, times, fixed ends) applied and checked, as the plain values a
solver takes (`RunConfig`, `BoundaryConfig`, `HigherRunConfig`). `scene.py` holds what a scene
declares; this module what one run of it is."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..physics import Lagrangian
from ..validation import (
    check_integer,
    check_parameter_values,
    check_real,
    check_span,
    check_state,
    check_step,
)
from .guard import SceneCodeError

RUN_SETTINGS = ("t0", "tau0", "t_end")
STATE_SETTINGS = ("q0", "p0", "v0")
BOUNDARY_SETTINGS = ("q_start", "q_end", "t0", "t_end")
VECTOR_SETTINGS = ("q0", "p0", "v0", "q_start", "q_end")
# The nodes of a fixed-endpoint grid that neither the command nor the scene's Endpoints give.
BOUNDARY_NODES = 101


@dataclass(frozen=True)
class Endpoints:
    """A scene's default fixed-endpoint problem (``ddvp bvp``): the end positions (not for a
    higher-order scene, whose ends come from its exact motion), the time span and the node
    count. Any field left ``None`` falls back to the scene's ``t0``, ``t_end`` or
    `BOUNDARY_NODES` nodes."""

    q_start: object = None
    q_end: object = None
    t_span: tuple | None = None
    nodes: int | None = None

    def __post_init__(self):
        if self.t_span is not None:
            object.__setattr__(self, "t_span", check_span(self.t_span))
        if self.nodes is not None:
            object.__setattr__(self, "nodes", check_integer("Endpoints nodes", self.nodes,
                                                            minimum=2))


@dataclass
class RunConfig:
    """Resolved values of one run of a scene."""

    params: dict[str, float]
    q0: np.ndarray
    p0: np.ndarray | None
    t0: float
    tau0: float
    t_end: float
    v0: np.ndarray | None = None

    def as_dict(self) -> dict:
        start = {"p0": self.p0.tolist()} if self.p0 is not None else {"v0": self.v0.tolist()}
        return {**self.params, "q0": self.q0.tolist(), **start, "t0": self.t0,
                "tau0": self.tau0, "t_end": self.t_end}


@dataclass
class HigherRunConfig:
    """Resolved values of one run of a higher-order scene."""

    params: dict[str, float]
    t0: float
    tau0: float
    t_end: float

    def as_dict(self) -> dict:
        """The resolved settings as plain values (what a run folder's name is hashed from)."""
        return {"params": dict(self.params), "t0": self.t0, "tau0": self.tau0,
                "t_end": self.t_end}


@dataclass
class BoundaryConfig:
    """Resolved fixed-endpoint data of a scene."""

    params: dict[str, float]
    q_start: np.ndarray
    q_end: np.ndarray
    t_span: tuple[float, float]
    nodes: int

    def as_dict(self) -> dict:
        return {**self.params, "q_start": self.q_start.tolist(), "q_end": self.q_end.tolist(),
                "t0": self.t_span[0], "t_end": self.t_span[1], "nodes": self.nodes}


def split_parameters(scene, overrides, settings_names):
    """``overrides`` parted into the scene's parameters (checked against its ranges) and the
    run settings named in ``settings_names``; an unknown name lists the known ones."""
    overrides = dict(overrides or {})
    settings = {k: overrides.pop(k) for k in settings_names if k in overrides}
    unknown = sorted(set(overrides) - set(scene.params))
    if unknown:
        known = ", ".join([*scene.params, *settings_names])
        raise InputError(f"scene {scene.name!r} has no parameter {unknown[0]!r} "
                         f"(it has: {known})")
    return check_parameter_values(overrides, scene.params, owner=f"scene {scene.name!r}",
                                  ranges=scene.ranges), settings


def resolve_boundary(scene, overrides: Mapping[str, object] | None = None,
                     nodes: int | None = None) -> BoundaryConfig:
    """Fixed-endpoint data: the scene's ``boundary`` with ``overrides`` (parameters,
    ``q_start``, ``q_end``, ``t0``, ``t_end``) and ``nodes`` applied."""
    params, settings = split_parameters(scene, overrides, BOUNDARY_SETTINGS)
    data = scene.boundary or Endpoints()
    if scene.boundary is None and not {"q_start", "q_end"} <= set(settings):
        raise InputError(f"scene {scene.name!r} declares no fixed-endpoint data: give "
                         "q_start, q_end, t0 and t_end (--set NAME=VALUE) and --nodes")
    t_span = data.t_span or (scene.t0, scene.t_end)
    t0 = settings.get("t0", t_span[0])
    t1 = settings.get("t_end", t_span[1])
    return BoundaryConfig(params=params,
                          q_start=np.atleast_1d(np.asarray(settings.get(
                              "q_start", data.q_start), dtype=float)),
                          q_end=np.atleast_1d(np.asarray(settings.get(
                              "q_end", data.q_end), dtype=float)),
                          t_span=(float(t0), float(t1)),
                          nodes=nodes if nodes is not None else (data.nodes or BOUNDARY_NODES))


def resolve_run(scene, overrides: Mapping[str, object] | None = None) -> RunConfig:
    """Defaults with ``overrides`` applied: parameters, ``t0``, ``tau0``, ``t_end``, ``q0``,
    ``p0``. Unknown names are an error that lists the known ones."""
    lagrangian = isinstance(scene.hamiltonian, Lagrangian)
    names = (*RUN_SETTINGS, *(STATE_SETTINGS if lagrangian else STATE_SETTINGS[:2]))
    params, settings = split_parameters(scene, overrides, names)
    q0 = settings.get("q0", scene.q0)
    if "p0" in settings and "v0" in settings:
        raise InputError("give p0 or v0, not both")
    p0 = settings.get("p0", None if "v0" in settings else scene.p0)
    v0 = settings.get("v0", None if "p0" in settings else scene.v0)
    values = {k: settings.get(k, getattr(scene, k)) for k in RUN_SETTINGS}
    for k, v in values.items():
        check_real(k, v)
    if values["t_end"] == values["t0"]:  # t_end < t0: a march backwards in time
        raise InputError(f"t_end must differ from t0 = {values['t0']!r} (t_end < t0 "
                         f"marches backwards), got {values['t_end']!r}")
    check_step(values["tau0"], float(values["t0"]), float(values["t_end"]))
    q0, p0, v0 = (None if x is None else start_value(scene, name, x, params)
                  for name, x in (("q0", q0), ("p0", p0), ("v0", v0)))
    return RunConfig(params=params, q0=q0, p0=p0, v0=v0,
                     **{k: float(v) for k, v in values.items()})


def start_value(scene, name: str, value, params: dict) -> np.ndarray:
    """The scene's ``q0``, ``p0`` or ``v0`` (a function of the parameters, or a value) as a
    finite real vector of length ``n``; a function that raises is named with the values."""
    if callable(value):
        try:
            value = value(**params)
        except SceneCodeError as exc:
            raise InputError(f"scene {scene.name!r}: {name} cannot be computed for "
                             f"{_shown(params)}: {exc.reason.removeprefix('raised ')} "
                             f"({exc.where})") from None
        except Exception as exc:
            raise InputError(f"scene {scene.name!r}: {name} cannot be computed for "
                             f"{_shown(params)}: {type(exc).__name__}: {exc}") from None
    return check_state(f"scene {scene.name!r}: {name}", value, scene.n)


def _shown(params: dict) -> str:
    return ", ".join(f"{k} = {v:g}" for k, v in params.items()) or "the defaults"
