"""Progress on stderr, one kind for every command: a tqdm bar redrawn in place on a terminal,
and on anything else (a file, a pipe, a batch job's log) a plain line every
`PLAIN_LINE_SECONDS` seconds with no carriage return, so that a redirected stderr reads as a
log (``stress``, ``sweep`` and ``compare`` had written carriage-return frames into it)."""

from __future__ import annotations

import math
import sys
import time

# Seconds between two plain lines: a log of a day-long march gets about 17000 lines, a run
# shorter than this none.
PLAIN_LINE_SECONDS = 5.0


def progress(total: float, *, unit: str, label: str = "", enabled: bool = True,
             stream=None, every: float = PLAIN_LINE_SECONDS):
    """A progress report over ``[0, total]`` in ``unit`` on ``stream`` (default stderr):
    ``update(amount)`` adds to it, ``close()`` ends it. A tqdm bar if ``stream`` is a
    terminal, `PlainLines` otherwise; `Silent` if not ``enabled``."""
    stream = sys.stderr if stream is None else stream
    if not enabled or stream is None:
        return Silent()
    if _is_terminal(stream):
        from tqdm import tqdm

        # a march's time is a float: tqdm's own counter format shows it with 17 digits
        shape = ("{l_bar}{bar}| t={n:.4g}/{total:.4g} [{elapsed}<{remaining}]" if unit == "t"
                 else None)
        return tqdm(total=total, unit=unit, leave=False, file=stream, desc=label or None,
                    bar_format=shape)
    return PlainLines(total, unit=unit, label=label, stream=stream, every=every)


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):  # closed, or no descriptor
        return False


class Silent:
    """No progress (``--no-progress``)."""

    def update(self, amount: float = 1) -> None:
        pass

    def close(self) -> None:
        pass


class PlainLines:
    """``LABEL: DONE/TOTAL UNIT (PERCENT%), ELAPSED s`` as a line of its own every ``every``
    seconds (``every = 0``: at every update), never a carriage return; nothing for a run that
    ends within ``every`` seconds."""

    def __init__(self, total: float, *, unit: str, label: str = "", stream=None,
                 every: float = PLAIN_LINE_SECONDS):
        self.total, self.unit, self.label = float(total), unit, label
        self.stream = sys.stderr if stream is None else stream
        self.every = every
        self.done = 0.0
        self.start = self.last = time.monotonic()

    def update(self, amount: float = 1) -> None:
        self.done += amount
        now = time.monotonic()
        if now - self.last >= self.every:
            self.last = now
            self._line(now)

    def _line(self, now: float) -> None:
        share = self.done / self.total if self.total > 0 and math.isfinite(self.total) else 0.0
        done = f"{self.done:.6g}" if self.unit == "t" else f"{self.done:g}"
        text = (f"{self.label + ': ' if self.label else ''}{done}/{self.total:.6g} {self.unit} "
                f"({100 * share:.0f}%), {now - self.start:.0f} s")
        try:
            print(text, file=self.stream, flush=True)
        except (OSError, ValueError):  # stderr went away: progress is not worth a failure
            self.every = math.inf

    def close(self) -> None:
        pass

__all__ = ["PLAIN_LINE_SECONDS", "PlainLines", "Silent", "progress"]
