"""Ctrl-C, SIGTERM and SIGHUP (a closed terminal or ssh session) during a command, honoured
at every moment, alike.

- While a march steps (it polls `Interrupts.stop_requested` after every stepper call), a
  signal only asks it to stop: it ends after the current call (milliseconds) with status
  ``interrupted`` and every accepted node, which are then written.
- While a run's files are written (`Interrupts.saving`) a signal is noted, not raised, so
  the set is never cut short; the only part it may stop is the figure
  (`Interrupts.interruptible`), which is then left out.
- Anywhere else (loading, building, a grid solve, the final verification of a grid) the first
  signal raises ``KeyboardInterrupt``; the command stops and says what it kept. Later signals
  are noted, not raised again while the command is ending (a second Ctrl-C had surfaced as a
  traceback from inside the first one's handling); one arriving more than a second after a
  raised one that the program swallowed (a CasADi callback turns it into another error) raises
  again, and so does the first one itself, two seconds on, if the command has not
  begun to end by then: a swallowed interrupt (a compared method's run failed with it, its
  row written, the table went on) had left ``ddvp compare`` running every remaining run.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import time

# SIGHUP too: a closed terminal had ended a march without saving it (a thinned march lost
# everything), where Ctrl-C and SIGTERM save what was accepted.
SIGNALS = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP}
# A signal this long after a raised one that did not end the command raises again.
RAISE_AGAIN_S = 1.0
# A raised interrupt that the command swallowed is raised again this long after.
AGAIN_S = 2.0


class Stopped(Exception):
    """The command was interrupted; the message says what was written."""


class Interrupts:
    """SIGINT, SIGTERM and SIGHUP, handled alike (module docstring)."""

    def __init__(self):
        self.requested = False   # a signal arrived
        self.signals = 0
        self.name = ""
        self.polling = False     # a march is stepping and polls stop_requested
        self.holding = 0         # inside saving(): note only
        self.abortable = 0       # inside interruptible(): raise even while holding
        self.ending = False      # the command is unwinding: note only
        self.raised_at = None
        self.restore = lambda: None
        self.again = None        # the timer that raises a swallowed interrupt again

    def install(self):
        """Set the handlers (main thread only) and release the signals the package held while
        the command started (``ddvp_nlp/__init__.py``): one that came meanwhile is handled now.
        Returns the function that ends the handling: the old handlers back, or, for the
        command, the signals held again (one arriving while the process exits is dropped, not
        a traceback)."""
        import threading

        self._cancel_again()
        self.__init__()
        if threading.current_thread() is not threading.main_thread():
            return lambda: None  # handlers can only be set from the main thread
        previous = {sig: signal.signal(sig, self.handle) for sig in SIGNALS}
        held = SIGNALS & signal.pthread_sigmask(signal.SIG_BLOCK, set())

        def restore():
            self._cancel_again()
            if held:  # the command: hold them again until the process is gone, and ignore
                # them: the mask is this thread's, and a signal a worker or checkpoint thread
                # took had ended the exiting interpreter with KeyboardInterrupt (exit -2)
                signal.pthread_sigmask(signal.SIG_BLOCK, held)
                for sig in held:
                    signal.signal(sig, signal.SIG_IGN)
                return
            for sig, handler in previous.items():
                signal.signal(sig, handler)
        self.restore = restore  # in place before a held signal is handled (it may raise)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, held)
        return restore

    def handle(self, signum, frame):
        self.requested = True
        self.signals += 1
        self.name = self.name or signal.Signals(signum).name
        if self.abortable:
            raise KeyboardInterrupt
        if self.ending or self.holding or self.polling:
            if self.holding and self.signals == 1:
                _say("ddvp: stopping; the files being written are finished first")
            return
        now = time.monotonic()
        if self.raised_at is None or now - self.raised_at > RAISE_AGAIN_S:
            self.raised_at = now
            self._raise_again_later(signum)
            raise KeyboardInterrupt

    def _raise_again_later(self, signum) -> None:
        """``AGAIN_S`` from now, the signal handled again in the main thread (module
        docstring): it raises again unless the command is ending, writing its files, or
        marching (then it is only noted); nothing once the handlers are gone."""
        import _thread
        import threading

        def again():
            if self.again is timer and signal.getsignal(signum) == self.handle:
                with contextlib.suppress(Exception):
                    _thread.interrupt_main(signum)
        self._cancel_again()
        timer = threading.Timer(AGAIN_S, again)
        timer.daemon = True
        self.again = timer
        timer.start()

    def _cancel_again(self) -> None:
        timer, self.again = getattr(self, "again", None), None
        if timer is not None:
            timer.cancel()

    def stop_requested(self) -> bool:
        """Polled by the march between stepper calls: whether to stop. From the first poll on,
        a signal only asks the march to stop (it keeps every accepted node)."""
        self.polling = True
        return self.requested

    @contextlib.contextmanager
    def saving(self):
        """Signals are noted, not raised, while a run's files are written."""
        self.holding += 1
        try:
            yield
        finally:
            self.holding -= 1

    @contextlib.contextmanager
    def interruptible(self):
        """Inside `saving`, a part a signal may stop (raising ``KeyboardInterrupt``, also
        when the signal surfaced as another error); not entered at all once a signal came: a
        run stopped by the user is written without its optional parts (energies over every
        node, the scene's checks, the figure: seconds for ten million nodes), so it ends as
        soon as its nodes are on disk."""
        if self.signals:  # asked to stop: the optional parts are left out from the start
            raise KeyboardInterrupt
        before = self.signals
        self.abortable += 1
        try:
            yield
        except BaseException:
            # raised inside a CasADi call, the interrupt comes out as another error
            # (NotImplementedError from its wrapper): a signal that came meanwhile decides
            if self.signals > before:
                raise KeyboardInterrupt from None
            raise
        finally:
            self.abortable -= 1

    def end(self) -> None:
        """The command is ending: from now on signals are only noted."""
        self.ending = True


def _say(text: str) -> None:
    with contextlib.suppress(Exception):
        print(text, file=sys.stderr, flush=True)


INTERRUPTS = Interrupts()
