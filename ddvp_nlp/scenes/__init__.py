"""Scenes: a system plus the data to run it (start, fixed ends, periodic settings, default
scheme), declared in a small Python file (``scene.py``), one run's configuration resolved from it
(``run_config.py``), and their loading, by name from
``problems/`` or by path, with the scene's code run bounded (``loader.py``)."""

from .loader import (
    is_builtin,
    list_scenes,
    load_scene,
    scene_digest,
    scene_file,
    scene_fingerprint,
)
from .run_config import (
    BOUNDARY_NODES,
    BOUNDARY_SETTINGS,
    RUN_SETTINGS,
    STATE_SETTINGS,
    VECTOR_SETTINGS,
    BoundaryConfig,
    Endpoints,
    HigherRunConfig,
    RunConfig,
)
from .scene import HigherOrderScene, PeriodicSettings, Scene

__all__ = ["BOUNDARY_NODES", "BOUNDARY_SETTINGS", "RUN_SETTINGS", "STATE_SETTINGS",
           "VECTOR_SETTINGS", "BoundaryConfig", "Endpoints", "HigherOrderScene",
           "HigherRunConfig", "PeriodicSettings", "RunConfig", "Scene", "is_builtin",
           "list_scenes", "load_scene", "scene_digest", "scene_file", "scene_fingerprint"]
