"""Ctrl-C and SIGTERM during a command: the first asks the march to stop cleanly, later ones
are noted while the run is saved."""

from __future__ import annotations

import signal
import sys


class Stopped(Exception):
    """The command was interrupted; the message says what was written."""


class Interrupts:
    """SIGINT and SIGTERM, handled alike. During a march (``mode="flag"``) the first one only
    asks the march to stop: it ends after its current chunk of steps with status
    ``interrupted`` and every accepted node (raising inside a CasADi call could tear it). With
    ``mode="raise"`` the first one raises ``KeyboardInterrupt`` (a grid keeps its rows). Once a
    run is stopping or being saved (:meth:`saving`), later ones are only noted, so a second
    Ctrl-C cannot cut the files of a run short; a second one before the march polled the
    first (during its build) raises."""

    def __init__(self):
        self.mode = "raise"
        self.requested = False
        self.stopping = False
        self.pending = False
        self.holding = 0

    def install(self, mode: str):
        import threading

        self.__init__()
        self.mode = mode
        if threading.current_thread() is not threading.main_thread():
            return lambda: None  # handlers can only be set from the main thread
        previous = {sig: signal.signal(sig, self.handle)
                    for sig in (signal.SIGINT, signal.SIGTERM)}
        return lambda: [signal.signal(sig, handler) for sig, handler in previous.items()]

    def handle(self, signum, frame):
        if self.holding or self.stopping:
            self.pending = True
            print("ddvp: still saving the run; it stops once the files are written",
                  file=sys.stderr)
            return
        if self.mode == "flag" and not self.requested:
            self.requested = True
            return
        raise KeyboardInterrupt

    def stop_requested(self) -> bool:
        """Polled by the march after each chunk: whether to stop (and from then on hold)."""
        if self.requested:
            self.stopping = True
        return self.requested

    def saving(self):
        import contextlib

        @contextlib.contextmanager
        def held():
            self.holding += 1
            try:
                yield
            finally:
                self.holding -= 1
        return held()


INTERRUPTS = Interrupts()
