"""The ``ddvp`` command runs in a child process watched by its parent, so that whatever the
command runs (a scene's code above all) cannot keep it from ending, or make it end lying.

The parent forks as the command starts and then only waits, forwards the signals it is sent
and reads the child's `SceneWatch` (``scenes/guard.py``):

- **a scene's code past its limits**: while the child's main thread runs a scene's code, the
  parent measures it as the child does (CPU time of the process from ``/proc/PID/stat``; sleep
  of the main thread, elapsed less on a processor less waiting to run, from its
  ``schedstat``), so a loaded machine counts for nothing. The child's own timers end such
  code with the file and the line; a scene that defeats them (ignores or cancels the timers,
  catches what they raise, loops inside one C call) is ended from here once it passes
  ``BACKSTOP`` times its limit plus ``BACKSTOP_S``: SIGKILL, exit 2, the file named;
- **a process that ends without finishing**: a child that exits while a scene's code runs
  (``posix._exit``, a signal it sends itself, ...) is exit 2 naming the file; one that exits
  before saying it is done (a scene's thread that ended the process mid-run) is exit 1, never
  the code it died with (an ``_exit(0)`` would have passed for a success);
- **a process that does not end after its work**: once done, the child leaves at once where
  non-daemon threads would keep the interpreter waiting for them, and otherwise runs its
  exit hooks and leaves before the interpreter's finalization, where a daemon thread holding
  a stream had aborted it (`_leave`); a child that still does not end (an ``atexit`` hook
  that hangs) is ended after ``EXIT_ASLEEP_S`` of sleep;
- **signals**: SIGINT, SIGTERM and SIGHUP sent to the parent are passed to the child (one
  from the terminal reaches both already and is not passed twice); if the child then sleeps
  ``STOP_ASLEEP_S`` (or computes ``STOP_CPU_S``) without ending, it is ended, exit 1. A child
  killed by a signal ends the parent by the same signal, and a SIGKILLed parent takes the
  child with it (``PR_SET_PDEATHSIG``);
- **processes left behind**: this process is a subreaper (``PR_SET_CHILD_SUBREAPER``), so a
  process the command started and left running (a scene's subprocess or daemon, however it
  detached) comes to it as an orphan; once the child has ended, such a process gets a second
  to end by itself (multiprocessing's resource tracker does), then SIGTERM, then SIGKILL, and
  the ended ones are named in one warning: nothing a scene starts outlives the command.

Only the command is supervised (``main()`` with no arguments, as the console script and
``python -m ddvp_nlp.cli`` call it); ``main(argv)`` from Python runs in its caller's process,
with the in-process limits only.
"""

from __future__ import annotations

import contextlib
import gc
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from typing import NoReturn

from ..scenes.guard import SceneWatch

# A scene's code is ended from outside once it passes BACKSTOP times its limit plus
# BACKSTOP_S, of CPU time or of sleep (its own timers act at the limit).
BACKSTOP, BACKSTOP_S = 1.5, 2.0
# A child told to stop that sleeps this long (or computes this long) without ending is ended.
STOP_ASLEEP_S, STOP_CPU_S = 20.0, 120.0
# A child done with its work that sleeps this long without ending is ended.
EXIT_ASLEEP_S = 10.0
POLL_S = 0.1
# Rounds of ending what the command left running (each round its leftovers' own children).
LEFTOVER_ROUNDS = 20
# Seconds a process left behind gets to end by itself, and again after SIGTERM.
LEFTOVER_GRACE_S = 1.0
FORWARDED = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
SI_KERNEL = 0x80  # si_code of a signal the kernel sent (the terminal's Ctrl-C), not kill()


def available() -> bool:
    """Whether the command can run supervised here (a fork and Linux's ``/proc``)."""
    return hasattr(os, "fork") and hasattr(signal, "sigtimedwait") and os.path.isdir(
        "/proc/self/task")


def supervise(work: Callable[[], int]) -> int:
    """``work()`` run in a child process watched from this one (module docstring); the
    command's exit code."""
    watch = SceneWatch()
    sys.stdout.flush()
    sys.stderr.flush()
    held = set(FORWARDED) | {signal.SIGCHLD}
    before = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    _adopt_orphans()
    child = os.fork()
    if child == 0:
        signal.pthread_sigmask(signal.SIG_SETMASK, before)
        return _child(work, watch)
    code = Parent(child, watch).wait()
    _leave_uncollected()  # the parent too: it exits next
    return code


def _child(work: Callable[[], int], watch: SceneWatch) -> int:
    """The command itself, in the child: it dies with its parent, reports to the watch, and
    once done leaves without waiting for threads that would keep it alive, nor for the
    interpreter's finalization (`_leave`)."""
    parent = os.getppid()
    _die_with_parent()
    if os.getppid() != parent:  # the parent died before the request took effect
        os._exit(1)
    watch.attach()
    ending = _last_exit_hook()
    try:
        code = work()
    except SystemExit as stop:  # argparse's end (--help, a usage error), as it is
        code = stop.code if isinstance(stop.code, int) else (0 if stop.code is None else 1)
        if stop.code is not None and not isinstance(stop.code, int):
            print(stop.code, file=sys.stderr)
    except KeyboardInterrupt:  # a signal past the command's own handling (as it ended): an
        # interrupted command, exit 1, not the interpreter's death by SIGINT (exit -2)
        _say("ddvp: interrupted as the command ended; every file it wrote is whole")
        code = 1
    finally:  # the code is decided: a later signal changes nothing (the command's handling
        # ignores them already; a child started otherwise would die by one, exit -15)
        for signum in FORWARDED:
            signal.signal(signum, signal.SIG_IGN)
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    watch.done(code)
    lingering = [t for t in threading.enumerate()
                 if t is not threading.main_thread() and not t.daemon and t.is_alive()]
    if lingering:  # a scene's (or a library's) thread: the run is saved, nothing waits for it
        # (the exit hooks would: concurrent.futures' joins its threads)
        _leave(code)
    _leave_uncollected()
    ending.append(code)  # the interpreter's exit runs the exit hooks, then `_leave`
    return code


def _last_exit_hook() -> list:
    """An exit hook (``atexit``) registered before any other of the child (none is before the
    fork), so that it runs after all of them: once the child has put its exit code in the list
    returned, it leaves there (`_leave`), before the interpreter's finalization."""
    import atexit

    code: list[int] = []

    def last():
        if code:
            _leave(code[0])
    atexit.register(last)
    return code


def _leave(code: int) -> NoReturn:
    """The child's exit without the interpreter's finalization: the streams flushed (Python's,
    then C's: a library's ``printf``) and the process ended with ``code`` (``os._exit``);
    called by the last exit hook, after every other one (Dask's, multiprocessing's,
    temporary folders'), or directly when a non-daemon thread is left running (no hook then).

    Finalization is where a thread still running meets the interpreter being taken apart:
    a daemon thread (Dask's event loop, a scene's thread) stopped while it holds a stream's
    lock makes the final flush abort the process ("Fatal Python error: ... Python runtime
    state: finalizing", exit -6 where the command's code was due). Leaving before it, no
    thread can end the command that way, whatever it runs or holds. It also spares the
    teardown of every module and object (0.19 s of CPU of ``ddvp march paper_pendulum``
    with its figure was the cycle collector's alone; ``scripts/benchmarks/bench_startup.py``).
    The command's files are closed as they are written; the signals are ignored from the
    end of the command on."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(BaseException):
            stream.flush()
    with contextlib.suppress(BaseException):
        import ctypes

        ctypes.CDLL(None).fflush(None)
    os._exit(code)


def _leave_uncollected() -> None:
    """Turn the cycle collector off for the process's exit (``gc.freeze``: what is alive now
    is never traversed again): the parent's teardown frees modules and objects by their
    counts alone, and the child's exit hooks run without a collection over every object of
    matplotlib and CasADi."""
    gc.disable()
    gc.freeze()


def _adopt_orphans() -> None:
    """``prctl(PR_SET_CHILD_SUBREAPER)``: a process the command leaves behind (a scene's
    subprocess or daemon, however it detached) becomes this process's child when its own
    parent ends, so that `_end_leftovers` can end it with the command."""
    with contextlib.suppress(Exception):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0)


def _end_leftovers() -> None:
    """The processes the command left running (module docstring) ended, and said so: none
    outlives the command. A process on its way out by itself (multiprocessing's resource
    tracker, a worker finishing its exit) gets ``LEFTOVER_GRACE_S`` to end, then SIGTERM and
    ``LEFTOVER_GRACE_S`` more, then SIGKILL; only a process that had to be ended is named."""
    ended = []
    for _ in range(LEFTOVER_ROUNDS):  # a leftover's own children come to us as it ends
        found = _reaped_within(LEFTOVER_GRACE_S)
        if not found:
            break
        for how in (signal.SIGTERM, signal.SIGKILL):
            for pid, _ in found:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, how)
            ended += [f"{pid} ({name})" for pid, name in found if how == signal.SIGTERM]
            found = _reaped_within(LEFTOVER_GRACE_S if how == signal.SIGTERM else None)
            if not found:
                break
    if ended:
        _say(f"ddvp: warning: ended {len(ended)} process(es) the command left running: "
             f"{', '.join(ended[:5])}{' ...' if len(ended) > 5 else ''}")


def _reaped_within(seconds: float | None) -> list[tuple[int, str]]:
    """This process's children that have not ended within ``seconds`` (``None``: waited for
    as long as they take, after SIGKILL), the ended ones reaped."""
    deadline = None if seconds is None else time.monotonic() + seconds
    while True:
        with contextlib.suppress(ChildProcessError):
            while os.waitpid(-1, os.WNOHANG)[0] > 0:
                pass
        found = _children()
        if not found or (deadline is not None and time.monotonic() >= deadline):
            return found
        if deadline is None:
            with contextlib.suppress(ChildProcessError):
                os.waitpid(-1, 0)
            continue
        time.sleep(0.02)


def _children() -> list[tuple[int, str]]:
    """``(pid, name)`` of this process's children, from ``/proc``."""
    me, found = os.getpid(), []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", "rb") as handle:
                text = handle.read().decode("ascii", "replace")
        except OSError:
            continue
        name, _, rest = text.partition("(")[2].rpartition(")")
        fields = rest.split()
        if len(fields) > 1 and fields[1] == str(me):
            found.append((int(entry), name))
    return found


def _die_with_parent() -> None:
    """``prctl(PR_SET_PDEATHSIG, SIGKILL)``: a SIGKILLed parent takes the child along."""
    with contextlib.suppress(Exception):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL, 0, 0, 0)


class Parent:
    """The waiting parent: signals forwarded, the child's scene code and end watched."""

    def __init__(self, child: int, watch: SceneWatch):
        self.child, self.watch = child, watch
        self.scene = None      # (sequence, cpu at start, thread times at start, elapsed start)
        self.stop = None       # (cpu, thread times, elapsed) when the first stop was passed on
        self.done = None       # the same, when the child said it was done
        self.killed = None     # (message, exit code) if this process ended the child

    def wait(self) -> int:
        while True:
            self._signals()
            ended, status = os.waitpid(self.child, os.WNOHANG)
            if ended:
                _end_leftovers()  # first: a child killed by a signal ends this process too
                return self._end(status)
            self._watch()

    def _signals(self) -> None:
        try:
            info = signal.sigtimedwait(set(FORWARDED) | {signal.SIGCHLD}, POLL_S)
        except InterruptedError:
            return
        if info is None or info.si_signo not in FORWARDED:
            # SIGCHLD, or a wait cut short by a stop and continue (SIGSTOP, SIGCONT) past its
            # timeout: CPython then returns the unfilled siginfo, whose number is garbage
            return
        if info.si_code != SI_KERNEL:  # kill() to this process: the child has not had it
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.child, info.si_signo)
        if self.stop is None:
            self.stop = self._sample()

    def _watch(self) -> None:
        state, sequence, _, limit, what, path = self.watch.read()
        now = self._sample()
        if state == SceneWatch.SCENE:
            if self.scene is None or self.scene[0] != sequence:
                self.scene = (sequence, now)
                return
            cpu, asleep = _since(self.scene[1], now)
            bound = BACKSTOP * limit + BACKSTOP_S
            if cpu > bound or asleep > bound:
                spent = (f"{cpu:.3g} s of CPU time" if cpu > bound else
                         f"{asleep:.3g} s asleep")
                self._kill(f"scene file {path!r}: {what} went on past its limit of "
                           f"{limit:.3g} s ({spent}) and did not stop when told; its process "
                           "was ended", code=2)
            return
        self.scene = None
        if state == SceneWatch.DONE:
            self.done = self.done or now
            cpu, asleep = _since(self.done, now)
            if asleep > EXIT_ASLEEP_S:
                self._kill("", code=self.watch.read()[2])
            return
        if self.stop is not None:
            cpu, asleep = _since(self.stop, now)
            if asleep > STOP_ASLEEP_S or cpu > STOP_CPU_S:
                self._kill(f"ddvp: the command did not end after it was told to stop "
                           f"({asleep:.3g} s asleep, {cpu:.3g} s of CPU time since); it was "
                           "ended", code=1)

    def _sample(self):
        return _process_cpu(self.child), _main_thread(self.child), time.monotonic()

    def _kill(self, message: str, *, code: int) -> None:
        self.killed = (message, code)
        with contextlib.suppress(ProcessLookupError):
            os.kill(self.child, signal.SIGKILL)

    def _end(self, status: int) -> int:
        """The command's exit code from the child's end (module docstring)."""
        state, _, code, _, what, path = self.watch.read()
        if self.killed:
            message, code = self.killed
            if message:
                _say(message)
            return code
        if state == SceneWatch.SCENE:
            how = (f"exit {os.waitstatus_to_exitcode(status)}" if os.WIFEXITED(status) else
                   f"signal {signal.Signals(os.WTERMSIG(status)).name}")
            _say(f"ddvp: error: scene file {path!r}: {what} ended the process ({how}); a scene "
                 "may not end the command")
            return 2
        if os.WIFSIGNALED(status):
            _end_like(os.WTERMSIG(status))
        exit_code = os.waitstatus_to_exitcode(status)
        if state != SceneWatch.DONE:
            _say(f"ddvp: error: the command's process ended (exit {exit_code}) before it was "
                 "done; something it ran ended it (a scene's thread?): what it wrote is whole, "
                 "but the run did not finish")
            return exit_code if exit_code not in (0, None) else 1
        return exit_code


def _since(start, now) -> tuple[float, float]:
    """``(CPU time of the process, sleep of its main thread)`` between two samples."""
    cpu = (now[0] - start[0]) if now[0] is not None and start[0] is not None else 0.0
    elapsed = now[2] - start[2]
    if now[1] is None or start[1] is None:
        return cpu, elapsed - cpu
    return cpu, elapsed - (now[1][0] - start[1][0]) - (now[1][1] - start[1][1])


def _process_cpu(pid: int) -> float | None:
    """User and system CPU time of process ``pid`` (all its threads), in seconds."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as handle:
            fields = handle.read().rsplit(b")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


def _main_thread(pid: int) -> tuple[float, float] | None:
    """``(on a processor, waiting to run)`` of the main thread of ``pid``, in seconds."""
    try:
        with open(f"/proc/{pid}/task/{pid}/schedstat", "rb") as handle:
            running, waiting = handle.read().split()[:2]
        return int(running) / 1e9, int(waiting) / 1e9
    except (OSError, ValueError):
        return None


def _end_like(signum: int) -> None:
    """End this process by ``signum``, as the child ended (a shell sees the same)."""
    with contextlib.suppress(Exception):
        sys.stdout.flush()
    signal.signal(signum, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signum})
    os.kill(os.getpid(), signum)


def _say(text: str) -> None:
    with contextlib.suppress(Exception):
        print(text, file=sys.stderr, flush=True)
