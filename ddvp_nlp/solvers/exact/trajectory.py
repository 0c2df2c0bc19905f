"""The accepted steps of an adaptive run with their continuous extension, read at any times
with numpy (no Python loop over times or steps)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .attempt import POWER

BLOCK = 1 << 14  # times evaluated per numpy pass (keeps the gathered rows in cache)


@dataclass
class Trajectory:
    """An adaptive run from ``t0`` to ``t_end`` (either direction).

    ``t_old`` (S,), ``h`` (S,) (signed), ``w_old`` (S, D): start, length and start state of each
    accepted step; ``F`` (POWER, S, D): the dense-output rows of each step (``None`` when the
    run was made without dense output). ``w_end``: the state at ``t_end``. ``d``: the size of
    ``z``; ``D = d (1 + m)`` with ``m`` tangent columns. ``attempts``, ``calls``: attempted
    steps (accepted and rejected) and chunk calls. ``status``: ``done`` or why not.
    """

    t0: float
    t_end: float
    t_old: np.ndarray
    h: np.ndarray
    w_old: np.ndarray
    F: np.ndarray | None
    w_end: np.ndarray
    d: int
    attempts: int = 0
    calls: int = 0
    status: str = "done"
    t_reached: float = np.nan
    info: dict = field(default_factory=dict)
    # the compiled reading of the dense output (`kernel.CheckKernel`), or None: numpy (the same
    # numbers)
    kernel: object = field(default=None, repr=False, compare=False)

    def __getstate__(self) -> dict:
        """Pickled without the compiled kernel (a library of this process): read with numpy
        where it is unpickled, the same numbers."""
        return {**self.__dict__, "kernel": None}

    @property
    def steps(self) -> int:
        return self.t_old.size

    @property
    def m(self) -> int:
        return self.w_end.size // self.d - 1

    @property
    def success(self) -> bool:
        return self.status == "done"

    @property
    def z_end(self) -> np.ndarray:
        return self.w_end[:self.d]

    @property
    def Y_end(self) -> np.ndarray:
        """The tangent at ``t_end`` (d x m): the flow's Jacobian times ``Y0``."""
        return self.w_end[self.d:].reshape(self.m, self.d).T

    def nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """The accepted steps' ends: times (S+1,) and states (S+1, D)."""
        return (np.append(self.t_old, self.t_reached),
                np.vstack([self.w_old, self.w_end[None, :]]))

    def __call__(self, times, components: slice | None = None) -> np.ndarray:
        """The states at ``times`` (any order, within the span) from the continuous extension:
        rows (len(times), D), or only ``components`` of ``w`` (``slice(0, d)``: ``z``)."""
        if self.F is None:
            raise ValueError("this run was made without dense output")
        times = np.asarray(times, float)
        shape = times.shape
        times = times.ravel()
        cols = slice(None) if components is None else components
        width = np.arange(self.w_end.size)[cols].size
        out = np.empty((times.size, width))
        if self.steps == 0:  # a run that failed at its first step: only its start is known
            out[:] = np.nan
            out[times == self.t0] = self.w_end[cols]
            return out.reshape(*shape, width)
        direction = 1.0 if self.t_end >= self.t0 else -1.0
        picked = range(self.w_end.size)[cols]
        if self.kernel is not None and picked.step == 1 and \
                self.kernel.readable(self.t_old, self.h, self.w_old, self.F):
            self.kernel.dense_values(self.t_old, self.h, self.w_old, self.F, direction,
                                     np.ascontiguousarray(times), picked.start, picked.stop,
                                     out)
            return out.reshape(*shape, width)
        keys = direction * self.t_old
        # contiguous rows, gathered with np.take (fancy indexing was 7x slower, and strided
        # views made the Horner arithmetic the bottleneck: 0.17 s against 0.07 s for 1e6 x 4)
        F = [np.ascontiguousarray(self.F[j][:, cols]) for j in range(POWER)]
        w_old = np.ascontiguousarray(self.w_old[:, cols])
        last = self.steps - 1
        for start in range(0, times.size, BLOCK):
            stop = min(start + BLOCK, times.size)
            s = times[start:stop]
            index = np.searchsorted(keys, direction * s, side="right")
            index -= 1
            np.clip(index, 0, last, out=index)
            x = s - np.take(self.t_old, index)
            x /= np.take(self.h, index)
            x = x[:, None]
            one_minus = 1.0 - x
            y = np.take(F[POWER - 1], index, axis=0)
            y *= x
            for j in range(POWER - 2, -1, -1):  # Horner, alternating x and 1 - x
                y += np.take(F[j], index, axis=0)
                y *= x if j % 2 == 0 else one_minus
            y += np.take(w_old, index, axis=0)
            out[start:stop] = y
        return out.reshape(*shape, width)

    def z(self, times) -> np.ndarray:
        """``z`` at ``times``: rows (len(times), d)."""
        return self(times, slice(0, self.d))

    def Y(self, times) -> np.ndarray:
        """The tangent at ``times``: (len(times), d, m)."""
        flat = self(times, slice(self.d, None))
        return flat.reshape(-1, self.m, self.d).transpose(0, 2, 1)


def concatenate(parts: list[Trajectory]) -> Trajectory:
    """Consecutive runs (each starting where the previous ended) as one trajectory."""
    first, last = parts[0], parts[-1]
    F = None if first.F is None else np.concatenate([p.F for p in parts], axis=1)
    return Trajectory(t0=first.t0, t_end=last.t_end,
                      t_old=np.concatenate([p.t_old for p in parts]),
                      h=np.concatenate([p.h for p in parts]),
                      w_old=np.vstack([p.w_old for p in parts]), F=F, w_end=last.w_end,
                      d=first.d, attempts=sum(p.attempts for p in parts),
                      calls=sum(p.calls for p in parts),
                      status=next((p.status for p in parts if not p.success), "done"),
                      t_reached=last.t_reached, kernel=first.kernel)
