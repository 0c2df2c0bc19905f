"""Checks of user input, shared by every entry point: the one module that says what a valid
argument is. Each check raises InputError naming the argument and the value, before anything is
built, and returns the value in the type the library uses."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from .errors import InputError


def check_state(name: str, value, n: int) -> np.ndarray:
    """A finite real vector of shape ``(n,)`` (a scalar is accepted when ``n == 1``)."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an array of {n} real numbers, got {value!r}") from None
    if array.ndim == 0 and n == 1:
        array = array.reshape(1)
    if array.shape != (n,):
        raise InputError(f"{name} must have shape ({n},), got shape {array.shape}: {value!r}")
    if not np.all(np.isfinite(array)):
        raise InputError(f"{name} must be finite, got {value!r}")
    return array


def check_real(name: str, value, *, positive: bool = False, allow_none: bool = False):
    """A finite real number (``> 0`` if ``positive``; ``None`` passes if ``allow_none``)."""
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(f"{name} must be a real number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise InputError(f"{name} must be finite, got {value!r}")
    if positive and value <= 0:
        raise InputError(f"{name} must be > 0, got {value!r}")
    return value


def check_integer(name: str, value, *, minimum: int = 1, maximum: int | None = None) -> int:
    """An integer ``>= minimum`` (and ``<= maximum``, if given; booleans are refused)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        wanted = "a positive integer" if minimum == 1 else f"an integer >= {minimum}"
        raise InputError(f"{name} must be {wanted}, got {value!r}")
    if maximum is not None and value > maximum:
        raise InputError(f"{name} must be at most {maximum}, got {value!r}")
    return int(value)


def check_parameter_values(values: Mapping[str, object], defaults: Mapping[str, float],
                           *, owner: str) -> dict[str, float]:
    """Merge ``values`` into ``defaults``; each name must be known, each value a finite real."""
    if not isinstance(values, Mapping):
        raise InputError(f"params of {owner} must be a mapping of names to numbers, "
                         f"got {values!r}")
    resolved = dict(defaults)
    for name, value in values.items():
        if name not in defaults:
            known = ", ".join(sorted(defaults)) or "none"
            raise InputError(f"{owner} has no parameter {name!r} (its parameters: {known})")
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise InputError(
                f"parameter {name!r} must be a real number, got {value!r} "
                f"of type {type(value).__name__}")
        if not math.isfinite(float(value)):
            raise InputError(f"parameter {name!r} must be finite, got {value!r}")
        resolved[name] = float(value)
    return resolved


def check_in_range(name: str, value, low: float, high: float) -> float:
    """A finite real number in ``[low, high]``."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(value) or not low <= value <= high:
        raise InputError(f"{name} must be a number in [{low:g}, {high:g}], got {value!r}")
    return float(value)


def check_finite_array(name: str, value, shape: tuple | None = None) -> np.ndarray:
    """A finite real array (of ``shape``, if given)."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an array of real numbers, got {value!r}") from None
    if shape is not None and array.shape != tuple(shape):
        raise InputError(f"{name} must have shape {tuple(shape)}, got {array.shape}")
    bad = np.flatnonzero(~np.isfinite(array.ravel()))
    if bad.size:
        shown = (array.tolist() if array.size <= 10 else
                 f"{bad.size} non-finite entries, the first {array.ravel()[bad[0]]!r} at flat "
                 f"index {bad[0]}")
        raise InputError(f"{name} must be finite, got {shown}")
    return array


def check_count(name: str, value, *, minimum: int = 0, maximum: int | None = None) -> int:
    """An integer ``>= minimum`` (and ``<= maximum``), as :func:`check_integer`, but the message
    always states the minimum (``an integer >= 1``): the comparison's counts have said so since
    they were added."""
    try:
        check_integer(name, value, minimum=minimum)
    except InputError:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}") from None
    return check_integer(name, value, minimum=minimum, maximum=maximum)


def check_cache_folder(value) -> None:
    """``None`` or a path that is not an existing file (the compiled-code cache folder)."""
    import os

    if value is None:
        return
    if not isinstance(value, (str, os.PathLike)) or not str(value).strip():
        raise InputError(f"cache_dir must be a folder path, got {value!r}")
    if os.path.exists(value) and not os.path.isdir(value):
        raise InputError(f"cache_dir must be a folder, got the file {str(value)!r}")


def check_unique_settings(items) -> None:
    """``NAME=VALUE`` items name each setting at most once (a repeat would silently win)."""
    seen = {}
    for item in items:
        name = item.partition("=")[0].strip()
        if name in seen:
            raise InputError(f"--set {name} is given twice ({seen[name]!r} and {item!r}); "
                             "give each setting once")
        seen[name] = item


def check_span(t_span) -> tuple[float, float]:
    """``t_span = (t0, t_end)`` as two finite numbers with ``t0 < t_end``."""
    if t_span is None:
        raise InputError("give t_span = (t0, t_end)")
    try:
        t0, t_end = t_span
    except (TypeError, ValueError):
        raise InputError(f"t_span must be a pair (t0, t_end), got {t_span!r}") from None
    t0 = check_real("t0", t0)
    t_end = check_real("t_end", t_end)
    if t_end <= t0:
        raise InputError(f"t_end must be > t0 = {t0!r}, got {t_end!r}")
    return t0, t_end
