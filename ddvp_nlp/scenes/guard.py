"""A scene's code run bounded: loading its file and every later call of its functions (``H`` or
``L``, ``exact``, the invariants, the start functions). Whatever the code raises
(``SystemExit``, any ``BaseException`` but ``KeyboardInterrupt``), an ``os._exit``, or a run past
the limit becomes a `SceneCodeError` (an `InputError`) naming the file and the line.

The limit is one of work, not of wall time, so that a busy machine never refuses a scene: the
code may use `scene_seconds` of CPU time (``ITIMER_PROF``) and may sleep (wait on anything but
the processor: a ``sleep``, a lock, a pipe) as long; the time it waits for a processor on a
loaded machine counts for neither (the main thread's ``/proc/self/task/TID/schedstat``:
asleep = elapsed - on a processor - waiting to run). Both are watched from inside (a timer, in
the main thread), which a scene can defeat (ignore the signal, cancel the timer, catch what
the handler raises, loop inside one C call); the ``ddvp`` command also watches them from
outside, through a `SceneWatch` its supervising process reads (``cli/supervisor.py``), and
ends a process whose scene code runs past the limit. After the code returns, what it may have
changed of the process is put back: the working folder (a scene's ``os.chdir`` had moved where a
relative ``--out`` landed), the umask, the signal handlers and mask.
"""

from __future__ import annotations

import contextlib
import mmap
import os
import struct
import time
from pathlib import Path

import numpy as np

from ..errors import InputError

# Seconds of CPU time (and, separately, of sleep) a scene's code may take in one call (loading
# the file, building H, one evaluation of exact or an invariant, plus SCENE_SECONDS_PER_VALUE
# for each value of its array arguments); $DDVP_SCENE_TIME_LIMIT overrides the base.
SCENE_SECONDS = 20.0
SCENE_SECONDS_PER_VALUE = 2e-6
SCENE_SECONDS_VARIABLE = "DDVP_SCENE_TIME_LIMIT"
# How often the sleep of a scene's code is looked at (at most; a shorter limit, more often).
SLEEP_TICK_S = 1.0


class _SceneTimeout(BaseException):
    """Raised by the timers in a scene's code that ran past its limit."""


class _SceneExit(BaseException):
    """Raised in place of ``os._exit``/``os.abort`` called by a scene's code."""


class _GuardState:
    depth = 0


def scene_seconds() -> float:
    """The base limit of a scene's code (``$DDVP_SCENE_TIME_LIMIT`` or the default), in
    seconds of CPU time (and of sleep)."""
    import math

    text = os.environ.get(SCENE_SECONDS_VARIABLE, "")
    try:
        value = float(text) if text.strip() else SCENE_SECONDS
    except ValueError:
        value = SCENE_SECONDS
    return value if math.isfinite(value) and value > 0 else SCENE_SECONDS


def thread_times(tid: int | None = None) -> tuple[float, float] | None:
    """``(on a processor, waiting to run)`` in seconds of thread ``tid`` of this process (the
    calling thread by default), from ``/proc/self/task/TID/schedstat``; ``None`` where the
    system does not report them."""
    tid = tid or _native_id()
    try:
        with open(f"/proc/self/task/{tid}/schedstat", "rb") as handle:
            running, waiting = handle.read().split()[:2]
        return int(running) / 1e9, int(waiting) / 1e9
    except (OSError, ValueError):
        return None


def _native_id() -> int:
    import threading

    return threading.get_native_id()


class SceneWatch:
    """What a supervising process reads to end a scene's code that defeats its limits (module
    docstring): a page of memory shared with the process that runs the command, which writes
    into it when its main thread enters scene code (the limit, the file, what is run) and
    leaves it, and when the command is done (its exit code). Made before the fork
    (``cli/supervisor.py``); only the process that `attach`-es it writes."""

    SIZE = 4096
    _HEAD = struct.Struct("<iiid")  # state, sequence, exit code, limit (s)
    IDLE, SCENE, DONE = 0, 1, 2

    def __init__(self):
        self.buffer = mmap.mmap(-1, self.SIZE)  # anonymous and shared: seen across a fork
        self.pid = None

    def attach(self) -> None:
        """This process reports to the watch from now on (its children do not)."""
        self.pid = os.getpid()
        _WATCH[0] = self

    def _write(self, state: int, code: int = 0, limit: float = 0.0, text: bytes = b"") -> None:
        if self.pid != os.getpid():
            return
        state_now, sequence, _, _ = self._HEAD.unpack_from(self.buffer, 0)
        if text:
            self.buffer[self._HEAD.size:self._HEAD.size + len(text) + 1] = text + b"\0"
        self._HEAD.pack_into(self.buffer, 0, state, sequence + 1, code, limit)

    def enter(self, path, what: str, limit: float) -> None:
        text = f"{what}\0{path}".encode("utf-8", "replace")[:self.SIZE - 64]
        self._write(self.SCENE, limit=limit, text=text)

    def leave(self) -> None:
        self._write(self.IDLE)

    def done(self, code: int) -> None:
        self._write(self.DONE, code=code)

    def read(self) -> tuple[int, int, int, float, str, str]:
        """``(state, sequence, code, limit, what, path)`` as last written."""
        state, sequence, code, limit = self._HEAD.unpack_from(self.buffer, 0)
        raw = bytes(self.buffer[self._HEAD.size:]).split(b"\0")
        what = raw[0].decode("utf-8", "replace") if raw else ""
        path = raw[1].decode("utf-8", "replace") if len(raw) > 1 else ""
        return state, sequence, code, limit, what, path


_WATCH: list[SceneWatch | None] = [None]  # the command's watch, attached by its process


@contextlib.contextmanager
def scene_code(path, what: str, size: int = 0):
    """Run a scene's code: any exception it raises but ``KeyboardInterrupt`` (and an
    `InputError` of ddvp's own checks) becomes an `InputError` with the file,
    the line and the message; ``os._exit``/``os.abort`` (also as ``posix``'s) raise instead of
    ending the process; past ``scene_seconds() + size * SCENE_SECONDS_PER_VALUE`` seconds of
    CPU time, or as long asleep, a timer ends it (in the main thread; worker threads of a grid
    have no timer). What the code changed of the process is put back (module docstring)."""
    import threading

    outer = _GuardState.depth == 0 and threading.current_thread() is threading.main_thread()
    limit = scene_seconds() + size * SCENE_SECONDS_PER_VALUE
    _GuardState.depth += 1
    saved = _ProcessState.save() if outer else None
    if outer:
        _ProcessState.arm(limit)
        watch = _WATCH[0]
        if watch is not None:
            watch.enter(path, what, limit)
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
            saved.restore()
            watch = _WATCH[0]
            if watch is not None:
                watch.leave()


class _ProcessState:
    """What a scene's code may change of the process, saved before it runs and put back
    after: the exits it may not call, the timers' and the command's signal handlers, the
    signal mask, the working folder and the umask."""

    SIGNALS = ("SIGALRM", "SIGPROF", "SIGINT", "SIGTERM", "SIGHUP")

    @classmethod
    def save(cls) -> _ProcessState:
        import posix
        import signal

        state = cls()
        state.exits = (os._exit, os.abort, posix._exit, posix.abort)
        state.handlers = {getattr(signal, name): signal.getsignal(getattr(signal, name))
                          for name in cls.SIGNALS}
        state.mask = signal.pthread_sigmask(signal.SIG_BLOCK, set())
        try:
            state.cwd = os.open(".", os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        except OSError:
            state.cwd = None
        state.umask = os.umask(0o022)
        os.umask(state.umask)
        os._exit = posix._exit = _refused_exit
        os.abort = posix.abort = _refused_abort
        return state

    @staticmethod
    def arm(limit: float) -> None:
        """The CPU timer at ``limit`` and the sleep ticks (module docstring)."""
        import signal

        clock = _SleepClock(limit)
        signal.signal(signal.SIGPROF, _over_cpu)
        signal.signal(signal.SIGALRM, clock.tick)
        tick = min(SLEEP_TICK_S, limit)
        signal.setitimer(signal.ITIMER_PROF, limit, tick)  # again each tick, if it is caught
        signal.setitimer(signal.ITIMER_REAL, tick, tick)

    def restore(self) -> None:
        import posix
        import signal

        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.setitimer(signal.ITIMER_REAL, 0)
        for signum, handler in self.handlers.items():
            with contextlib.suppress(TypeError, ValueError, OSError):
                signal.signal(signum, handler if handler is not None else signal.SIG_DFL)
        signal.pthread_sigmask(signal.SIG_SETMASK, self.mask)
        if self.cwd is not None:
            with contextlib.suppress(OSError):
                os.fchdir(self.cwd)
            os.close(self.cwd)
        os.umask(self.umask)
        os._exit, os.abort, posix._exit, posix.abort = self.exits


class _SleepClock:
    """The sleep of the main thread since the scene's code started, looked at on each tick:
    elapsed time less the time on a processor and the time waiting for one."""

    def __init__(self, limit: float):
        self.limit = limit
        self.started = time.monotonic()
        self.tid = _native_id()
        self.times = thread_times(self.tid)
        self.cpu = time.process_time()

    def asleep(self) -> float:
        elapsed = time.monotonic() - self.started
        now = thread_times(self.tid)
        if now is None or self.times is None:  # no scheduler figures: the process's CPU time
            return elapsed - (time.process_time() - self.cpu)
        return elapsed - (now[0] - self.times[0]) - (now[1] - self.times[1])

    def tick(self, signum, frame):
        asleep = self.asleep()
        if asleep > self.limit:
            raise _SceneTimeout(f"waited {asleep:.3g} s without computing (asleep: a sleep, a "
                                f"lock, a pipe); a scene's code may sleep {self.limit:.3g} s "
                                f"(${SCENE_SECONDS_VARIABLE} sets it)")


def _over_cpu(signum, frame):
    raise _SceneTimeout("cpu")


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
        if exc.args and exc.args[0] != "cpu":
            return where, exc.args[0]
        return where, (f"did not return within {limit:.3g} s of CPU time (the limit of a "
                       f"scene's code; ${SCENE_SECONDS_VARIABLE} sets it)")
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
