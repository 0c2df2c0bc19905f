"""What the package does the moment it is imported by the ``ddvp`` command, before anything
else: hold Ctrl-C and SIGTERM until the command's handlers are in place, and start numpy's
OpenBLAS with one thread. Imported first by the package root; a library user's import changes
nothing. `started_as_command` tells the rest of
the package whether it runs in the command's own short-lived process."""

from __future__ import annotations

import sys


def started_as_command() -> bool:
    """Whether this process is the ``ddvp`` command (``ddvp ...``, ``python -m ddvp_nlp.cli
    ...``): a process that runs one command and exits, read from how it was started
    (``sys.orig_argv``), never from a setting."""
    import os

    argv = getattr(sys, "orig_argv", [])
    return argv[1:3] == ["-m", "ddvp_nlp.cli"] or (
        len(argv) > 1 and os.path.basename(argv[1]) == "ddvp")


def hold_signals_while_the_command_starts() -> None:
    """Started as the ``ddvp`` command (`started_as_command`): Ctrl-C, SIGTERM and SIGHUP are held
    (blocked, not lost) until the command's handlers are in place (``cli/main.py`` releases
    them), so a signal while the imports run ends the command with its message, not a
    ``KeyboardInterrupt`` traceback from an import."""
    import signal

    if started_as_command() and hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM, signal.SIGHUP})


def one_blas_thread(environ=None) -> None:
    """Started as the ``ddvp`` command and with no thread count of the user's: OpenBLAS (numpy's)
    started with one thread (``OPENBLAS_NUM_THREADS=1``, set before numpy is imported). Its
    matrices here are a few dozen rows (a monodromy, a tangent frame; the grids' linear algebra
    is the banded LU in C and SuperLU), where a second thread only waits; starting it was 0.07 s
    of the 0.26 s numpy's import took (2-core machine). The command's workers inherit it.
    ``environ``: the environment to read and set (``os.environ``)."""
    import os

    environ = os.environ if environ is None else environ
    if started_as_command() and "OPENBLAS_NUM_THREADS" not in environ:
        environ["OPENBLAS_NUM_THREADS"] = "1"


hold_signals_while_the_command_starts()
one_blas_thread()

__all__ = ["hold_signals_while_the_command_starts", "one_blas_thread", "started_as_command"]
