"""What the package does the moment it is imported by the ``ddvp`` command, before anything
else: hold Ctrl-C and SIGTERM until the command's handlers are in place. Imported first by the
package root; a library user's import changes nothing."""

from __future__ import annotations

import sys


def hold_signals_while_the_command_starts() -> None:
    """Started as the ``ddvp`` command (``ddvp ...``, ``python -m ddvp_nlp.cli ...``): Ctrl-C
    and SIGTERM are held (blocked, not lost) until the command's handlers are in place
    (``cli/main.py`` releases them), so a signal while the imports run ends the command with
    its message, not a ``KeyboardInterrupt`` traceback from an import."""
    import os
    import signal

    argv = getattr(sys, "orig_argv", [])
    command = argv[1:3] == ["-m", "ddvp_nlp.cli"] or (
        len(argv) > 1 and os.path.basename(argv[1]) == "ddvp")
    if command and hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})


hold_signals_while_the_command_starts()

__all__ = ["hold_signals_while_the_command_starts"]
