"""Reading a sweep's TOML grid file into a `ddvp_nlp.studies.sweep.SweepSpec`::

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

An unknown key is an error that gives the key's path.
"""

from __future__ import annotations

import math
from pathlib import Path

from ..errors import InputError
from .methods import get_methods
from .stress import DEFAULT_METHODS
from .sweep import SweepSpec, evenly_spaced

TOP_KEYS = ("scene", "methods", "settings", "grid", "bounds")
RANGE_KEYS = ("from", "to", "count")
# Largest grid file read: a grid is a page of TOML (a /dev/zero or a huge file is refused by
# its size before it is read).
JOURNAL_LIMIT = 1 << 20
BOUND_KEYS = ("max_steps", "time_limit")


def load_grid_file(path: str | Path, *, allowed: str | None = None) -> SweepSpec:
    """Read a TOML grid; an unknown key is an error that gives the key's path. Its scene must
    be a built-in name, or the scene file ``allowed`` names: a grid file
    runs no code the command line did not name (a ``scene = "/path/evil.py"`` had been
    imported and run before any check)."""
    path = Path(path)
    data = _read_toml(path)
    where = str(path)
    _known(where, data, TOP_KEYS, "")
    if not isinstance(data.get("scene"), str):
        raise InputError(f"{where}: 'scene' must be a scene name or file, got "
                         f"{data.get('scene')!r}")
    _check_scene_allowed(where, data["scene"], allowed)
    grid = data.get("grid")
    if not isinstance(grid, dict) or not grid:
        raise InputError(f"{where}: '[grid]' must list at least one axis")
    axes = {name: _axis(where, f"grid.{name}", value) for name, value in grid.items()}
    bounds = _table(where, data, "bounds")
    _known(where, bounds, BOUND_KEYS, "bounds.")
    settings = _table(where, data, "settings")
    for key, value in settings.items():
        if not (_number(value) or (isinstance(value, list) and value
                                   and all(_number(v) for v in value))):
            raise InputError(f"{where}: 'settings.{key}' must be a finite number (or a list of "
                             f"them), got {value!r}")
    methods = data.get("methods", list(DEFAULT_METHODS))
    if not isinstance(methods, list) or not methods or \
            not all(isinstance(m, str) for m in methods) or len(set(methods)) != len(methods):
        raise InputError(f"{where}: 'methods' must be a list of distinct method names, got "
                         f"{methods!r}")
    max_steps = bounds.get("max_steps", 2_000_000)
    if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1:
        raise InputError(f"{where}: 'bounds.max_steps' must be a positive integer, got "
                         f"{max_steps!r}")
    time_limit = bounds.get("time_limit", 60.0)
    if not _number(time_limit) or time_limit <= 0:
        raise InputError(f"{where}: 'bounds.time_limit' must be a positive number of seconds, "
                         f"got {time_limit!r}")
    return SweepSpec(scene=data["scene"], axes=axes,
                     methods=tuple(m.name for m in get_methods(methods)), settings=settings,
                     max_steps=max_steps, time_limit=float(time_limit))


def _check_scene_allowed(where: str, scene: str, allowed: str | None) -> None:
    """A built-in scene name passes; a file only if ``allowed`` is the same file."""
    from ..scenes import list_scenes

    if scene in list_scenes():
        return
    if allowed is not None:
        try:
            if Path(scene).resolve() == Path(allowed).resolve():
                return
        except (OSError, RuntimeError):
            pass
    raise InputError(f"{where}: scene {scene!r} is not a built-in scene; a grid file runs "
                     "no code the command line does not name: allow the file with "
                     f"`allowed` {scene}")


def _read_toml(path: Path) -> dict:
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib

    from ..validation import read_limited

    data = read_limited(path, JOURNAL_LIMIT, what="grid file")
    try:
        return tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise InputError(f"grid file {str(path)!r} is not UTF-8 text (byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"grid file {str(path)!r} is not valid TOML: {exc}") from None
    except RecursionError:
        raise InputError(f"grid file {str(path)!r} is nested too deeply to be a grid "
                         "file") from None


def _axis(where: str, key: str, value) -> list[float]:
    """One axis: a list of numbers, or ``{from, to, count}``."""
    if isinstance(value, dict):
        return _range_axis(where, key, value)
    if isinstance(value, list) and value and all(_number(v) for v in value):
        values = [float(v) for v in value]
        if len(set(values)) != len(values):
            raise InputError(f"{where}: '{key}' has a value twice ({value!r}); give each once")
        return values
    raise InputError(f"{where}: '{key}' must be a list of numbers or "
                     f"{{from, to, count}}, got {value!r}")


def _range_axis(where: str, key: str, value: dict) -> list[float]:
    _known(where, value, RANGE_KEYS, key + ".")
    missing = [k for k in RANGE_KEYS if k not in value]
    if missing:
        raise InputError(f"{where}: '{key}' needs {', '.join(RANGE_KEYS)}; missing "
                         f"{missing[0]!r}")
    count = value["count"]
    if not (_number(value["from"]) and _number(value["to"])) or \
            not isinstance(count, int) or isinstance(count, bool):
        raise InputError(f"{where}: '{key}' must have numbers from, to and an integer "
                         f"count, got {value!r}")
    return evenly_spaced(f"{where}: '{key}'", float(value["from"]), float(value["to"]), count)


def _table(where: str, data: dict, name: str) -> dict:
    """An optional table of the file (``{}`` if absent)."""
    table = data.get(name, {})
    if not isinstance(table, dict):
        raise InputError(f"{where}: '[{name}]' must be a table, got {table!r}")
    return table


def _known(where, table, known, prefix):
    for key in table:
        if key not in known:
            raise InputError(f"{where}: unknown key '{prefix}{key}' (known: "
                             f"{', '.join(known)})")


def _number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)
