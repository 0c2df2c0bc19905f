"""The run folder of a command: its default name (named by every input that changes the
result, each setting compared with its default, the request's, read once from the parser that
parsed the command line, which takes it from the API; a scene
file's content and a guess's numbers by their SHA-256), and what it holds after an
interrupt."""

from __future__ import annotations

import hashlib

import numpy as np

from ..io.atomic import describe
from ..io.run_folder import default_folder
from ..scenes import is_builtin


def holds(out) -> str:
    """What the output folder ``out`` holds, in words (said when a command stops early)."""
    return describe(out.path)


def default_or(args, label: str, named: dict, *, options=(), defaults: dict | None = None,
               scene=None, guess=None):
    """``(folder, owned)``: ``--out``, else ``runs/LABEL`` for the defaults and
    ``runs/LABEL-HASH`` (``HASH`` of every setting in ``named``) when any setting differs from
    its default: the command's own for the names in ``options``, else ``defaults``. A
    ``scene`` loaded from a file (not a built-in one) and a ``guess`` read from a file always
    count, by their content (`content_inputs`): an edited file never finds the folder of
    the file it was."""
    if args.out is not None:
        return args.out, 1
    reference = {name: args.default(name) for name in options}
    reference.update(defaults or {})
    named = {**named, **content_inputs(scene, guess)}
    changed = {k: v for k, v in named.items() if reference.get(k, object()) != v}
    return default_folder(label, named, changed), 2


def content_inputs(scene=None, guess=None) -> dict:
    """The inputs that are files, by content: ``scene_sha256`` of a scene loaded from a file
    (a built-in scene is the package's own, named by its name), ``guess_sha256`` of a guess's
    arrays."""
    found = {}
    if scene is not None and scene.digest and not is_builtin(scene.source):
        found["scene_sha256"] = scene.digest
    if isinstance(guess, dict):
        digest = hashlib.sha256()
        for key in sorted(guess):
            array = np.ascontiguousarray(guess[key], dtype=float)
            digest.update(f"{key}{array.shape}".encode())
            digest.update(array.tobytes())
        found["guess_sha256"] = digest.hexdigest()
    return found
