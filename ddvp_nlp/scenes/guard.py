"""A scene's code run bounded: loading its file and every later call of its functions (``H`` or
``L``, ``exact``, the invariants, the start functions). Whatever the code raises
(``SystemExit``, any ``BaseException`` but ``KeyboardInterrupt``), an ``os._exit``, or a run past
the time limit becomes a `SceneCodeError` (an `InputError`) naming the file and the line."""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from ..errors import InputError

# Seconds a scene's code may run in one call (loading the file, building H, one evaluation of
# exact or an invariant, plus SCENE_SECONDS_PER_VALUE for each value of its array arguments);
# $DDVP_SCENE_TIME_LIMIT overrides the base.
SCENE_SECONDS = 20.0
SCENE_SECONDS_PER_VALUE = 2e-6
SCENE_SECONDS_VARIABLE = "DDVP_SCENE_TIME_LIMIT"


class _SceneTimeout(BaseException):
    """Raised by the alarm in a scene's code that ran past its time limit."""


class _SceneExit(BaseException):
    """Raised in place of ``os._exit``/``os.abort`` called by a scene's code."""


class _GuardState:
    depth = 0


def scene_seconds() -> float:
    """The base time limit of a scene's code (``$DDVP_SCENE_TIME_LIMIT`` or the default)."""
    import math
    import os

    text = os.environ.get(SCENE_SECONDS_VARIABLE, "")
    try:
        value = float(text) if text.strip() else SCENE_SECONDS
    except ValueError:
        value = SCENE_SECONDS
    return value if math.isfinite(value) and value > 0 else SCENE_SECONDS


@contextlib.contextmanager
def scene_code(path, what: str, size: int = 0):
    """Run a scene's code: any exception it raises but ``KeyboardInterrupt`` (and an
    `InputError` of ddvp's own checks) becomes an `InputError` with the file,
    the line and the message; ``os._exit``/``os.abort`` raise instead of ending the process;
    past ``scene_seconds() + size * SCENE_SECONDS_PER_VALUE`` seconds an alarm ends it (in the
    main thread; worker threads of a grid have no alarm)."""
    import os
    import signal
    import threading

    outer = _GuardState.depth == 0 and threading.current_thread() is threading.main_thread()
    limit = scene_seconds() + size * SCENE_SECONDS_PER_VALUE
    _GuardState.depth += 1
    saved = (os._exit, os.abort)
    if outer:
        os._exit, os.abort = _refused_exit, _refused_abort
        previous = signal.signal(signal.SIGALRM, _alarm)
        signal.setitimer(signal.ITIMER_REAL, limit)
    try:
        yield
    except (KeyboardInterrupt, SceneCodeError, _Passed):
        raise
    except InputError as exc:  # a check of ddvp's own, called by the scene: say where
        where, _ = _describe(path, what, exc, limit)
        if "line" not in where:
            raise
        raise SceneCodeError(f"{where}: {exc}", where=where, reason=str(exc)) from None
    except BaseException as exc:  # noqa: B036 - a scene must not end the command its own way
        where, reason = _describe(path, what, exc, limit)
        raise SceneCodeError(f"{where}: {what} {reason}", where=where, reason=reason) from None
    finally:
        _GuardState.depth -= 1
        if outer:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
            os._exit, os.abort = saved


def _alarm(signum, frame):
    raise _SceneTimeout


def _refused_exit(code=0):
    raise _SceneExit(f"os._exit({code!r})")


def _refused_abort():
    raise _SceneExit("os.abort()")


class SceneCodeError(InputError):
    """A scene's code failed: ``where`` (the file and the line) and ``reason`` (what it did)."""

    def __init__(self, message: str, *, where: str, reason: str):
        super().__init__(message)
        self.where, self.reason = where, reason


def _describe(path, what: str, exc: BaseException, limit: float) -> tuple[str, str]:
    """``(where, reason)``: ``scene file PATH, line N`` (the deepest line of the scene file in
    the traceback) and what happened in words."""
    import traceback

    line = None
    wanted = str(Path(path).resolve())
    for frame in traceback.extract_tb(exc.__traceback__):
        if str(Path(frame.filename).resolve()) == wanted:
            line = frame.lineno
    where = f"scene file {str(path)!r}" + (f", line {line}" if line else "")
    if isinstance(exc, _SceneTimeout):
        return where, (f"did not return within {limit:.3g} s (the limit of a scene's code; "
                       f"${SCENE_SECONDS_VARIABLE} sets it)")
    if isinstance(exc, SystemExit):
        return where, f"called sys.exit({exc.code!r}); a scene may not end the command"
    if isinstance(exc, _SceneExit):
        return where, f"called {exc}; a scene may not end the command"
    return where, f"raised {type(exc).__name__}: {exc}"


def guarded(function, path, what: str, *, passes=()):
    """``function`` run under `scene_code` at every call; exceptions of ``passes`` (the
    ``ValueError`` an ``exact`` raises for a start it does not cover) pass as they are."""
    import functools

    if not callable(function) or getattr(function, "__ddvp_guarded__", False):
        return function

    @functools.wraps(function)
    def guarded(*args, **kwargs):
        size = sum(int(np.size(a)) for a in args if isinstance(a, np.ndarray))
        try:
            with scene_code(path, what, size):
                try:
                    return function(*args, **kwargs)
                except passes as exc:
                    raise _Passed(exc) from None
        except _Passed as passed:
            raise passed.args[0] from None

    guarded.__ddvp_guarded__ = True
    return guarded


class _Passed(InputError):
    """Carries an allowed exception of a scene's function through `scene_code`."""




def check_invariant_value(scene: str, name: str, value, count: int) -> np.ndarray:
    """An invariant's value: ``count`` finite-or-not real numbers."""
    try:
        array = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f"scene {scene!r}: invariant {name!r} returned "
                         f"{type(value).__name__} {str(value)[:60]!r}, not {count} real "
                         "numbers") from None
    if array.size != count:
        raise InputError(f"scene {scene!r}: invariant {name!r} returned {array.size} values "
                         f"for {count} states")
    return array
