"""Checks of user input, shared by every entry point: the one module that says what a valid
argument is. Each check raises InputError naming the argument and the value, before anything is
built, and returns the value in the type the library uses."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping

import numpy as np

from . import safe_files
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
                           *, owner: str, ranges: Mapping[str, str] | None = None
                           ) -> dict[str, float]:
    """Merge ``values`` into ``defaults``; each name must be known, each value a finite real,
    inside its interval of ``ranges`` (``{"e": "[0, 1)"}``) if one is declared."""
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
    for name, interval in (ranges or {}).items():
        if name in resolved:
            check_in_interval(name, resolved[name], interval)
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
    """An integer ``>= minimum`` (and ``<= maximum``), as `check_integer`, but the message
    always states the minimum (``an integer >= 1``): the comparison's counts have said so since
    they were added."""
    try:
        check_integer(name, value, minimum=minimum)
    except InputError:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}") from None
    return check_integer(name, value, minimum=minimum, maximum=maximum)


def check_cache_folder(value) -> None:
    """``None`` or a path that is not an existing file (the compiled-code cache folder)."""
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


def check_times(t_eval, t_span=None, *, name: str = "t_eval") -> np.ndarray | None:
    """Output times (``t_eval`` of a march, ``--t-eval`` of the command line): a non-empty
    1-d array of finite times, sorted in the direction of ``t_span`` (repeats allowed, as
    scipy's: increasing, or decreasing for a backward span ``t_end < t0``; without a span
    either way), inside ``t_span`` if given; ``name`` is the argument the message names."""
    if t_eval is None:
        return None
    try:
        times = np.asarray(t_eval, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an array of times, got {t_eval!r}") from None
    if times.ndim != 1 or times.size == 0 or not np.all(np.isfinite(times)):
        raise InputError(f"{name} must be a non-empty 1-d array of finite times, got "
                         f"{np.array2string(np.atleast_1d(times), threshold=6)}")
    # comparisons, not differences: one byte per time, not eight (t_eval may be long)
    increasing = bool(np.all(times[1:] >= times[:-1]))
    decreasing = bool(np.all(times[1:] <= times[:-1]))
    backward = t_span is not None and t_span[1] < t_span[0]
    if backward and not decreasing:
        raise InputError(f"{name} must be sorted in decreasing order for a backward march "
                         f"(t_end < t0), got {np.array2string(times, threshold=6)}")
    if not backward and not increasing and (t_span is not None or not decreasing):
        raise InputError(f"{name} must be sorted in increasing order, got "
                         f"{np.array2string(times, threshold=6)}")
    if t_span is not None and (times.min() < min(t_span) or times.max() > max(t_span)):
        raise InputError(f"{name} must lie in t_span = [{t_span[0]:.10g}, {t_span[1]:.10g}] "
                         f"(the run's span), got times from {times[0]:.10g} to "
                         f"{times[-1]:.10g}")
    return times


def available_memory() -> int:
    """Bytes this process may still allocate: ``MemAvailable`` of ``/proc/meminfo`` (Linux),
    else the physical memory; an address-space limit (``ulimit -v``) lowers it."""
    found = None
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    found = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        pass
    if found is None:
        try:
            found = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (OSError, ValueError, AttributeError):
            found = 1 << 34
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            found = min(found, soft)
    except (ImportError, OSError, ValueError):
        pass
    return int(found)


def check_memory(name: str, value, needed: float, what: str) -> None:
    """Refuse ``value`` of the argument ``name`` when ``what`` would need ``needed`` bytes,
    more than half of `available_memory` (the rest is for everything else the run
    holds), before anything is allocated."""
    budget = available_memory() / 2
    if not needed <= budget:  # also refuses a NaN or infinite estimate
        raise InputError(f"{name} = {value!r} is more than this machine can hold: {what} "
                         f"needs about {_bytes(needed)}, and {_bytes(budget)} (half of the "
                         "memory available now) is the most a run may take")


def _bytes(count: float) -> str:
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if count >= size:
            return f"{count / size:.3g} {unit}"
    return f"{count:.0f} bytes"


# Largest file ddvp reads back whole (a guess, a run's result.npz): a quarter of the memory
# available, checked by the size on disk before reading.
def check_file_size(where: str, size: int) -> None:
    """Refuse a file whose ``size`` would not fit in a quarter of the memory available."""
    budget = available_memory() / 4
    if size > budget:
        raise InputError(f"{where} has {_bytes(size)}, more than this machine can read back "
                         f"({_bytes(budget)}, a quarter of the memory available now)")


def check_step(tau0, t0: float, t_end: float) -> float:
    """A first step ``tau0`` that floating point resolves: positive, finite, not subnormal,
    ``t0 + tau0 > t0`` and ``(t_end - t0) / tau0`` a finite number of steps (``5e-324``
    passed ``> 0`` and overflowed the step count)."""
    tau0 = check_real("tau0", tau0, positive=True)
    if tau0 < np.finfo(float).tiny or not t0 + tau0 > t0:
        raise InputError(f"tau0 = {tau0!r} is too small to be a step from t0 = {t0!r}: "
                         f"t0 + tau0 rounds to t0 (the smallest step there is "
                         f"{np.spacing(max(abs(t0), abs(t_end), np.finfo(float).tiny)):.3g})")
    if not math.isfinite(t_end - t0) or not math.isfinite((t_end - t0) / tau0):
        raise InputError(f"t_end - t0 = {t_end - t0!r} is more steps of tau0 = {tau0!r} than a "
                         "float can count")
    return tau0


def parse_range(name: str, text: str) -> tuple[float, float, bool, bool]:
    """An interval such as ``"[0, 1)"`` or ``"(0, inf)"``: ``(low, high, low_closed,
    high_closed)``."""
    spec = text.strip() if isinstance(text, str) else ""
    try:
        low_text, high_text = spec[1:-1].split(",")
        low, high = float(low_text), float(high_text)
    except ValueError:
        low = high = math.nan
    if len(spec) < 5 or spec[0] not in "[(" or spec[-1] not in "])" or \
            math.isnan(low) or math.isnan(high) or not low < high:
        raise InputError(f"the range of parameter {name!r} must be an interval like '[0, 1)' "
                         f"or '(0, inf)', got {text!r}")
    return low, high, spec[0] == "[", spec[-1] == "]"


def check_in_interval(name: str, value: float, text: str) -> float:
    """``value`` inside the interval ``text`` (`parse_range`)."""
    low, high, low_closed, high_closed = parse_range(name, text)
    above = value >= low if low_closed else value > low
    below = value <= high if high_closed else value < high
    if not (above and below):
        raise InputError(f"parameter {name!r} must lie in {text.strip()}, got {value!r}")
    return value


def read_limited(path: str | os.PathLike, limit: int, *, what: str,
                 dir_fd: int | None = None) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes, opened without following a
    link; anything else (a link, a folder, a device, a bigger file) is an `InputError`
    that names the file and the reason."""
    import stat

    try:
        descriptor = safe_files.open_reading(path, dir_fd=dir_fd)
    except OSError as exc:
        raise InputError(f"{what} {str(path)!r} cannot be read: "
                         f"{safe_files.reason(exc)}") from None
    info = os.fstat(descriptor)
    if not stat.S_ISREG(info.st_mode):
        os.close(descriptor)
        kind = "a folder" if stat.S_ISDIR(info.st_mode) else "not a regular file"
        raise InputError(f"{what} {str(path)!r} is {kind}" if kind == "a folder" else
                         f"{what} {str(path)!r} is not a regular file")
    with os.fdopen(descriptor, "rb") as handle:
        if info.st_size > limit:
            raise InputError(f"{what} {str(path)!r} has {info.st_size} bytes, more than the "
                             f"{limit} such a file can have")
        try:
            data = handle.read(limit + 1)
        except OSError as exc:
            raise InputError(f"{what} {str(path)!r} cannot be read: {exc.strerror}") from None
    if len(data) > limit:
        raise InputError(f"{what} {str(path)!r} is larger than {limit} bytes")
    return data


def check_degrees(n) -> int:
    """Degrees of freedom ``n``: a positive integer whose step equations fit in memory (a
    march's Newton step has a dense ``(2n + 1)``-square Jacobian and its factors; ``n =
    10**6`` built for ever instead of being refused)."""
    n = check_integer("n", n)
    check_memory("n", n, 4 * 8.0 * (2 * n + 1) ** 2, "the dense Jacobian of one step")
    return n


def check_parameter_ranges(ranges, params, *, owner: str) -> dict:
    """A scene's declared parameter ranges: a mapping of its parameter names to intervals
    (``"[0, 1)"``), each default inside its interval."""
    if ranges is None:
        return {}
    if not isinstance(ranges, Mapping):
        raise InputError(f"ranges of {owner} must map parameter names to intervals like "
                         f"'[0, 1)', got {ranges!r}")
    for name, text in ranges.items():
        if name not in params:
            raise InputError(f"{owner} declares a range for {name!r}, which is not one of its "
                             f"parameters ({', '.join(params) or 'none'})")
        parse_range(name, text)
    return dict(ranges)

__all__ = ["available_memory", "check_cache_folder", "check_count", "check_degrees",
           "check_names", "check_times",
           "check_file_size", "check_finite_array", "check_in_interval",
           "check_in_range", "check_integer", "check_memory", "check_parameter_ranges",
           "check_parameter_values", "check_real", "check_span", "check_state",
           "check_step", "check_unique_settings", "parse_range", "read_limited"]


def check_angles(angles, n: int, *, name: str = "angles") -> tuple[int, ...]:
    """Indices (from 0) of the angle coordinates named ``"q1"`` .. ``"qn"`` (``H`` is
    ``2 pi``-periodic in each); ``name`` is the argument the message names."""
    import re

    try:
        names = (angles,) if isinstance(angles, str) else tuple(angles)
    except TypeError:
        raise InputError(f"{name} must name coordinates q1..q{n}, got {angles!r}") from None
    indices = []
    for entry in names:
        match = re.fullmatch(r"q(\d+)", entry) if isinstance(entry, str) else None
        if match is None or not 1 <= int(match.group(1)) <= n:
            raise InputError(f"{name} must name coordinates q1..q{n}, got {angles!r}")
        indices.append(int(match.group(1)) - 1)
    return tuple(sorted(set(indices)))


def check_names(value, allowed: tuple, what: str = "derivatives") -> tuple[str, ...]:
    """``value`` (``None``, a name, or a sequence of names from ``allowed``) as a tuple of
    distinct names in ``allowed``'s order; an ``InputError`` says ``what`` was read, names a
    wrong entry and lists the allowed ones."""
    if value is None:
        return ()
    names = (value,) if isinstance(value, str) else value
    try:
        names = tuple(names)
    except TypeError:
        raise InputError(f"{what} must be a sequence of names from {', '.join(allowed)}, got "
                         f"{value!r}") from None
    for name in names:
        if not isinstance(name, str) or name not in allowed:
            raise InputError(f"{what}: unknown name {name!r} in {value!r} (choose from "
                             f"{', '.join(allowed)})")
    return tuple(name for name in allowed if name in names)
