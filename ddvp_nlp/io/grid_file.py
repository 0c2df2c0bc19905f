"""Reading a sweep's TOML grid file into a :class:`ddvp_nlp.studies.sweep.SweepSpec`::

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
from ..studies.methods import get_methods
from ..studies.stress import DEFAULT_METHODS
from ..studies.sweep import SweepSpec, evenly_spaced

TOP_KEYS = ("scene", "methods", "settings", "grid", "bounds")
RANGE_KEYS = ("from", "to", "count")
BOUND_KEYS = ("max_steps", "time_limit")


def load_grid_file(path: str | Path) -> SweepSpec:
    """Read a TOML grid; an unknown key is an error that gives the key's path."""
    path = Path(path)
    data = _read_toml(path)
    where = str(path)
    _known(where, data, TOP_KEYS, "")
    if not isinstance(data.get("scene"), str):
        raise InputError(f"{where}: 'scene' must be a scene name or file, got "
                         f"{data.get('scene')!r}")
    grid = data.get("grid")
    if not isinstance(grid, dict) or not grid:
        raise InputError(f"{where}: '[grid]' must list at least one axis")
    axes = {name: _axis(where, f"grid.{name}", value) for name, value in grid.items()}
    bounds = _table(where, data, "bounds")
    _known(where, bounds, BOUND_KEYS, "bounds.")
    settings = _table(where, data, "settings")
    methods = data.get("methods", list(DEFAULT_METHODS))
    if not isinstance(methods, list) or not all(isinstance(m, str) for m in methods):
        raise InputError(f"{where}: 'methods' must be a list of method names, got {methods!r}")
    return SweepSpec(scene=data["scene"], axes=axes,
                     methods=tuple(m.name for m in get_methods(methods)), settings=settings,
                     max_steps=bounds.get("max_steps", 2_000_000),
                     time_limit=bounds.get("time_limit", 60.0))


def _read_toml(path: Path) -> dict:
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib

    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError as exc:
        raise InputError(f"grid file {str(path)!r} is not UTF-8 text (byte {exc.start})") from None
    except OSError as exc:
        raise InputError(f"grid file {str(path)!r} cannot be read: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"grid file {str(path)!r} is not valid TOML: {exc}") from None


def _axis(where: str, key: str, value) -> list[float]:
    """One axis: a list of numbers, or ``{from, to, count}``."""
    if isinstance(value, dict):
        return _range_axis(where, key, value)
    if isinstance(value, list) and value and all(_number(v) for v in value):
        return [float(v) for v in value]
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
