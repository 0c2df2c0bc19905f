"""What every compiled baseline shares: the chunk size, the named columns of a chunk's rows,
the compiled call through numpy buffers, and the `Solution` of a run's nodes."""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from ...solution import Solution
from ..compiler import FunctionBuffer, cache_folder, compile_function

# Steps per compiled call, whatever the run's length: one compile per scene and method (a size
# per run length cost a gcc compile of 0.4 s for each size); a short run throws away the rest
# of its one chunk (1024 steps of an explicit method: well under a millisecond).
CHUNK = 1024


class Columns:
    """Named columns of a compiled chunk's state or output rows, in order: the one place where a
    row is both written (`pack`, CasADi) and read (`split`, `unpack`)."""

    def __init__(self, **widths: int):
        self.widths = widths

    def _slices(self):
        start = 0
        for name, width in self.widths.items():
            yield name, width, slice(start, start + width)
            start += width

    def pack(self, **parts) -> ca.SX:
        """The row as one CasADi column, from its parts by name."""
        if parts.keys() != self.widths.keys():
            raise ValueError(f"a row has the columns {list(self.widths)}, got {list(parts)}")
        return ca.vertcat(*(parts[name] for name in self.widths))

    def join(self, **parts) -> np.ndarray:
        """The row as one numpy vector, from its parts by name."""
        return np.concatenate([np.atleast_1d(np.asarray(parts[name], float))
                               for name in self.widths])

    def split(self, row) -> dict:
        """The parts of one row (a CasADi or numpy vector) by name."""
        return {name: row[part.start] if width == 1 else row[part]
                for name, width, part in self._slices()}

    def unpack(self, rows: np.ndarray) -> dict[str, np.ndarray]:
        """The columns of ``rows`` (one row per step) by name: ``(m,)`` for a width of one, else
        ``(m, width)``."""
        return {name: rows[:, part.start] if width == 1 else rows[:, part]
                for name, width, part in self._slices()}


class Buffered:
    """A chunk function called through ``Function.buffer`` (numpy arrays, no DM conversions),
    answering as a DM call would: each output the ``(rows, columns)`` array ``np.asarray`` makes
    of the DM (a copy: the next call overwrites the buffers; callers keep slices of it)."""

    def __init__(self, function: ca.Function):
        self.function = function
        self._buffer = FunctionBuffer(function)

    def __call__(self, *args) -> list[np.ndarray]:
        outputs = self._buffer(*(np.asarray(a, float).T for a in args))
        return [out.copy().T for out in outputs]


def load(function: ca.Function, compiler, cache_dir) -> tuple[Buffered, float]:
    """``function`` compiled (cached) where a compiler is given, else as it is, as a
    `Buffered` call; and the seconds spent compiling."""
    if compiler is None:
        return Buffered(function), 0.0
    started = time.perf_counter()
    compiled = compile_function(function, compiler, cache_folder(cache_dir))
    return Buffered(compiled), time.perf_counter() - started


def solution_of(t, z, n, status, message, scheme, timing, *, energy_residual=None,
                canonical_residual=None, stats=None) -> Solution:
    """A baseline's `Solution` from its nodes ``t``, ``z = (q, p)``."""
    return Solution(t=t, q=z[:, :n].copy(), p=z[:, n:].copy(), status=status, message=message,
                    scheme=scheme,
                    energy_residual=np.zeros(0) if energy_residual is None else energy_residual,
                    canonical_residual=(np.zeros(0) if canonical_residual is None
                                        else canonical_residual),
                    timing=timing, stats=stats or {})
