"""Scenes: a system plus the data to run it (start, fixed ends, periodic settings, default
scheme), declared in a small Python file (``scene.py``), and their loading, by name from
``problems/`` or by path, with the scene's code run bounded (``loader.py``)."""

from .loader import (
    is_builtin,
    list_scenes,
    load_scene,
    scene_digest,
    scene_file,
    scene_fingerprint,
)
from .scene import (
    BOUNDARY_NODES,
    BOUNDARY_SETTINGS,
    RUN_SETTINGS,
    STATE_SETTINGS,
    VECTOR_SETTINGS,
    BoundaryConfig,
    Endpoints,
    HigherOrderScene,
    HigherRunConfig,
    PeriodicSettings,
    RunConfig,
    Scene,
)

__all__ = ["BOUNDARY_NODES", "BOUNDARY_SETTINGS", "RUN_SETTINGS", "STATE_SETTINGS",
           "VECTOR_SETTINGS", "BoundaryConfig", "Endpoints", "HigherOrderScene",
           "HigherRunConfig", "PeriodicSettings", "RunConfig", "Scene", "is_builtin",
           "list_scenes", "load_scene", "scene_digest", "scene_file", "scene_fingerprint"]
