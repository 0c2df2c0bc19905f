"""Loading a scene: a built-in scene by name (the files of ``problems/``, installed as
``ddvp_nlp.problems``) or a user's scene file by path, its code run bounded: whatever it raises,
an ``os._exit``, or a run past the time limit is an `InputError` naming the file and the line;
the scene's functions are checked once on its own defaults."""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.util
import json
from collections import OrderedDict
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..physics import Lagrangian
from ..validation import read_limited
from .guard import SceneCodeError, check_invariant_value, guarded, scene_code
from .scene import HigherOrderScene, Scene


def scene_folder() -> Path:
    """The folder of the built-in scenes: installed package data, or the source tree's
    ``problems/`` when running from a checkout."""
    try:
        import ddvp_nlp.problems as installed
        return Path(installed.__file__).parent
    except ImportError:
        return Path(__file__).resolve().parent.parent / "problems"


def list_scenes() -> list[str]:
    return sorted(p.stem for p in scene_folder().glob("*.py") if not p.stem.startswith("_"))


def scene_file(name_or_path: str) -> Path:
    """The file of a built-in scene (by name) or of a scene file (by path), checked."""
    if not isinstance(name_or_path, str) or not name_or_path:
        raise InputError(f"scene must be a name or a path, got {name_or_path!r}")
    if _looks_like_path(name_or_path):
        path = Path(name_or_path)
        try:
            found = path.is_file()
        except OSError as exc:  # a name too long, ...: the argument's fault, not the output's
            raise InputError(f"scene file {_shown(name_or_path)} cannot be looked up: "
                             f"{exc.strerror or exc}") from None
        if not found:
            raise InputError(f"scene file {_shown(name_or_path)} does not exist")
        if path.suffix != ".py":
            raise InputError(f"scene file {name_or_path!r} is not a Python file (.py)")
        return path
    known = list_scenes()
    if name_or_path not in known:
        import difflib

        close = difflib.get_close_matches(name_or_path, known, n=3)
        hint = f"; did you mean {' or '.join(map(repr, close))}?" if close else ""
        raise InputError(f"unknown scene {name_or_path!r}{hint} (built-in scenes: "
                         f"{', '.join(known)}; or a .py file)")
    return scene_folder() / f"{name_or_path}.py"


def _shown(path: str) -> str:
    """``path`` quoted for a message, its middle left out past 200 characters."""
    return repr(path) if len(path) <= 200 else \
        f"{path[:120]!r}...{path[-60:]!r} ({len(path)} characters)"


def is_builtin(name_or_path) -> bool:
    """Whether ``name_or_path`` names a built-in scene (a name of `list_scenes`, not a path):
    the only scene a file ddvp wrote may name (a run folder's resume record), since loading it
    runs no code but the package's own."""
    return (isinstance(name_or_path, str) and not _looks_like_path(name_or_path)
            and name_or_path in list_scenes())


def _looks_like_path(text: str) -> bool:
    return text.endswith(".py") or "/" in text or "\\" in text


def scene_fingerprint(scene, settings: dict) -> str:
    """The SHA-256 of a scene's file (`Scene.digest`) and a run's resolved ``settings`` (its
    parameters, start, steps and span): what a run was computed from. A resumed run is
    continued only from a scene whose fingerprint with the run's settings is the recorded one,
    and a run folder's default name carries it for a scene file."""
    text = json.dumps({"scene_sha256": scene.digest, "settings": settings}, sort_keys=True,
                      default=_plain)
    return hashlib.sha256(text.encode()).hexdigest()


def _plain(value):
    array = np.asarray(value)
    if array.dtype.kind in "biuf":
        return array.tolist()
    raise TypeError(f"cannot write {type(value).__name__} to JSON")


def scene_digest(name_or_path: str) -> str:
    """SHA-256 of the scene's file: what a grid row was computed from, so that a resumed grid
    reuses a row only for the same file, and a worker refuses a different one."""
    return hashlib.sha256(read_limited(scene_file(name_or_path), SCENE_FILE_LIMIT,
                                       what="scene file")).hexdigest()


def load_scene(name_or_path: str, *, digest: str | None = None) -> Scene:
    """A built-in scene by name, or the scene defined in a Python file; with ``digest``, only
    if the file's SHA-256 is that (a worker of a grid loads the file the grid was planned on).

    The file's code runs bounded (`scene_code`): whatever it raises (``SystemExit``,
    ``GeneratorExit``, any ``BaseException`` but ``KeyboardInterrupt``), an ``os._exit``, or a
    run past the time limit is an `InputError` naming the file and the line; so is
    every later call of the scene's functions (``H`` or ``L``, ``exact``, the invariants, the
    start functions), which are checked once on the scene's own defaults here.

    A file loaded again in the same process with the same content is not run again: the
    scene returned is a copy (its own parameters, start and settings to change) sharing the
    functions, and so the system and what was built for it (`LOADED_SCENES` files kept)."""
    path = scene_file(name_or_path)
    name = path.stem
    source = read_limited(path, SCENE_FILE_LIMIT, what="scene file")
    found = hashlib.sha256(source).hexdigest()
    if digest is not None and found != digest:
        raise InputError(f"scene file {str(path)!r} is not the one this grid was planned with "
                         "(its content differs): a worker has another file of that name, or it "
                         "changed since")
    key = (str(path.resolve()), found)
    if key in _LOADED:  # this content ran and passed its checks in this process
        _LOADED.move_to_end(key)
        return _fresh(_LOADED[key], name_or_path)
    spec = importlib.util.spec_from_file_location(f"ddvp_scene_{name}", path)
    module = importlib.util.module_from_spec(spec)
    with scene_code(path, "loading the file"):
        code = compile(source, str(path), "exec")
        exec(code, module.__dict__)  # noqa: S102 - the scene file the user named
    scene = module.__dict__.get("scene")
    if not isinstance(scene, (Scene, HigherOrderScene)):
        raise InputError(f"scene file {str(path)!r} defines no `scene = Scene(...)`")
    scene.name = name
    scene.source = name_or_path  # how another process loads the same scene
    scene.digest = hashlib.sha256(source).hexdigest()
    doc = module.__dict__.get("__doc__")
    scene.description = first_paragraph(doc) if isinstance(doc, str) else ""
    _guard_functions(scene, path)
    _probe(scene, path)
    if not isinstance(scene, Scene):
        return scene
    _LOADED[key] = scene
    while len(_LOADED) > LOADED_SCENES:
        _LOADED.popitem(last=False)
    return _fresh(scene, name_or_path)


# Scene files already run in this process, by path and content: loaded again, the file is not
# run again, and the scene returned is a copy of the one it made (its own parameters, start
# and settings to change), whose functions are the same objects, so that `Scene.system` gives
# the same system and what was built for it is not built again (a test suite, a notebook and
# every row of a study load one scene many times). A higher-order scene is run each time.
LOADED_SCENES = 32
_LOADED: OrderedDict = OrderedDict()


def _fresh(scene: Scene, source: str) -> Scene:
    """A copy of ``scene`` loaded as ``source``: its mappings and arrays its own, its functions
    (and so its system, `Scene.system`) shared."""
    def own(value):
        return value.copy() if isinstance(value, (np.ndarray, list)) else value
    return dataclasses.replace(scene, source=source, params=dict(scene.params),
                               invariants=dict(scene.invariants), ranges=dict(scene.ranges),
                               q0=own(scene.q0), p0=own(scene.p0), v0=own(scene.v0))


def first_paragraph(doc: str) -> str:
    """A docstring's first paragraph as one line (its first line only had cut Kepler's
    description mid-sentence)."""
    return " ".join(doc.strip().split("\n\n")[0].split())


# Largest scene file read: a scene is a page of Python.
SCENE_FILE_LIMIT = 4 << 20


def _guard_functions(scene, path) -> None:
    """Every function of ``scene`` replaced by its guarded form (`guarded`)."""
    if isinstance(scene, HigherOrderScene):
        scene.lagrangian = guarded(scene.lagrangian, path, "L")
        scene.exact = guarded(scene.exact, path, "exact")
        return
    if isinstance(scene.hamiltonian, Lagrangian):
        scene.hamiltonian.function = guarded(scene.hamiltonian.function, path, "L")
    else:
        scene.hamiltonian = guarded(scene.hamiltonian, path, "H")
    scene.exact = guarded(scene.exact, path, "exact", passes=(ValueError,))
    scene.invariants = {name: guarded(f, path, f"invariant {name!r}")
                        for name, f in scene.invariants.items()}
    for key in ("q0", "p0", "v0"):
        setattr(scene, key, guarded(getattr(scene, key), path, key))

def _probe(scene, path) -> None:
    """The scene's functions called once on its own defaults, so that one that raises, hangs
    or returns what is not an array of numbers is refused now, not after a long run: ``H``
    (or ``L``) built symbolically, ``exact`` and every invariant at the start."""
    scene.system  # noqa: B018 - builds H (or L) on symbols, under its guard
    if isinstance(scene, HigherOrderScene):
        config = scene.resolve({})
        scene.exact_motion(np.array([config.t0, config.t0 + config.tau0]), config.params)
        return
    config = scene.resolve({})
    if config.p0 is None:
        return
    q, p = config.q0[None, :], config.p0[None, :]
    for name, invariant in scene.invariants.items():
        value = invariant(q, p, **config.params)
        check_invariant_value(scene.name, name, value, 1)
    if scene.exact is not None:
        try:
            scene.exact(np.array([config.t0, config.t0 + config.tau0]), config.q0, config.p0,
                        config.t0, **config.params)
        except SceneCodeError:
            raise
        except ValueError:  # a start it does not cover: the studies use a reference instead
            pass
