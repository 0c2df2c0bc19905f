"""The accuracy check's passes over every node in C: the continuous extension of an adaptive
run read at many times (`Trajectory`), written as numpy computes it, operation for operation.

Why: numpy reads a run's dense output at ``N`` times in about 22 passes over an ``(N, d)``
table (eight gathers, seven products and seven sums of the Horner scheme), each a loop of its
own through memory; the check of a march reads its reference at every node, and on
Henon-Heiles (9 650 nodes and 2 x 2 865 samples of the claim) that was 1.4 ms of a check of
4 ms, for a march of 4.9 ms. One loop in C reads each step's coefficients once per time and
keeps the value in a register.

The same numbers to the bit: each value is the same sequence of IEEE operations as numpy's
(``x = (s - t_old) / h``, then Horner alternating ``x`` and ``1 - x``, then ``+ w_old``),
compiled without contraction to FMA (``compiler.COMPILE_FLAGS``); the step holding a time is
numpy's ``searchsorted(..., side="right") - 1``, clipped to the steps
(``tests/library/exact/test_kernel.py`` compares the two on runs and on times outside them).

Built once per compiler and source by ``compiler.py``'s build and cache (``check_HASH.so``,
checksummed), and only once the work pays for it: `kernel` loads a library already in the
cache, builds one only when told the work is paid (``build=True``: the accuracy check asks so
once the exact flow of the system it judges is compiled, whose own rent its checks have paid),
and is ``None`` otherwise, without a compiler or after a failed build (one warning); the
caller then runs numpy, which gives the same numbers.
"""

from __future__ import annotations

import ctypes
import threading
import warnings

import numpy as np

from ..compiler import CompileUnavailable, cache_folder, compile_source, find_compiler

SOURCE = r"""
#define POWER 7 /* rows of dense-output coefficients (attempt.POWER) */

/* numpy's searchsorted(keys, key, side="right") - 1 clipped to 0 .. steps - 1, keys being
   direction * t_old (increasing), started from the step k of the time before: increasing
   times find their step a few steps on, any others by bisection (a NaN key lies past every
   finite one, as in numpy) */
static long step_of(double key, double direction, const double *t_old, long steps, long k) {
  long lo, hi;
  if (!(key < direction * t_old[k])) {
    long ahead = k + 8 < steps ? k + 8 : steps;
    for (long j = k + 1; j < ahead; ++j)
      if (key < direction * t_old[j]) return j - 1;
    lo = ahead; hi = steps;
  } else {
    lo = 0; hi = k;
  }
  while (lo < hi) {
    long mid = lo + (hi - lo) / 2;
    if (key < direction * t_old[mid]) hi = mid; else lo = mid + 1;
  }
  k = lo - 1;
  return k < 0 ? 0 : (k > steps - 1 ? steps - 1 : k);
}

/* out (n x (c1 - c0)): components c0 .. c1 of the continuous extension of the run of `steps`
   steps (t_old, h, w_old (steps x D), F (POWER x steps x D)) at the n times; `direction` the
   run's (+1 or -1). Each value as numpy computes it in trajectory.py. */
void dense_values(long steps, long D, const double *t_old, const double *h,
                  const double *w_old, const double *F, double direction, long n,
                  const double *times, long c0, long c1, double *out) {
  long width = c1 - c0, k = 0, plane = steps * D;
  for (long i = 0; i < n; ++i) {
    double s = times[i];
    k = step_of(direction * s, direction, t_old, steps, k);
    double x = s - t_old[k];
    x /= h[k];
    double one_minus = 1.0 - x;
    const double *f = F + k * D;
    double *row = out + i * width;
    for (long c = c0; c < c1; ++c) {
      double y = f[6 * plane + c] * x;
      y += f[5 * plane + c]; y *= one_minus;
      y += f[4 * plane + c]; y *= x;
      y += f[3 * plane + c]; y *= one_minus;
      y += f[2 * plane + c]; y *= x;
      y += f[1 * plane + c]; y *= one_minus;
      y += f[c]; y *= x;
      y += w_old[k * D + c];
      row[c - c0] = y;
    }
  }
}
"""

_LOADED: dict = {}  # (compiler, folder) -> the kernel, or None (not in the cache, or failed)
_FAILED: set = set()  # (compiler, folder) whose build failed: not tried again
_LOCK = threading.Lock()


class CheckKernel:
    """The compiled passes of one library."""

    def __init__(self, library):
        lib = ctypes.CDLL(str(library))
        self._dense = lib.dense_values
        size, pointer = ctypes.c_long, ctypes.c_void_p
        self._dense.argtypes = [size, size, pointer, pointer, pointer, pointer,
                                ctypes.c_double, size, pointer, size, size, pointer]
        self._dense.restype = None

    def dense_values(self, t_old: np.ndarray, h: np.ndarray, w_old: np.ndarray,
                     F: np.ndarray, direction: float, times: np.ndarray, c0: int, c1: int,
                     out: np.ndarray) -> None:
        """``out`` (C-ordered ``(len(times), c1 - c0)``): components ``c0 .. c1`` of the
        continuous extension at ``times`` (``Trajectory.__call__``'s numbers); every array
        C-ordered float64, ``F`` of shape ``(POWER, steps, D)``."""
        _, steps, D = F.shape
        self._dense(steps, D, t_old.ctypes.data, h.ctypes.data, w_old.ctypes.data,
                    F.ctypes.data, float(direction), times.size, times.ctypes.data, c0, c1,
                    out.ctypes.data)


def kernel(compiler: str | None = "auto", cache_dir=None, *,
           build: bool = False) -> CheckKernel | None:
    """The compiled kernel, loaded from the cache, or built there if ``build`` (the caller's
    work has paid for it: module docstring); ``None`` if not in the cache and not to be
    built, without a compiler, or if the build fails (one warning): numpy then."""
    found = find_compiler(compiler) if compiler is not None else None
    if found is None:
        return None
    folder = cache_folder(cache_dir)
    key = (found, str(folder))
    loaded = _LOADED.get(key)
    if loaded is not None or key in _FAILED or (key in _LOADED and not build):
        return loaded
    with _LOCK:
        if _LOADED.get(key) is not None or key in _FAILED:
            return _LOADED.get(key)
        try:
            _LOADED[key] = compile_source(SOURCE, "dense_values", found, folder,
                                          prefix="check", load=CheckKernel, build=build)
        except (CompileUnavailable, OSError) as exc:
            _LOADED[key] = None
            _FAILED.add(key)
            if build:
                warnings.warn(f"{exc}; the accuracy check reads its reference with numpy "
                              f"instead (slower, the same numbers)", RuntimeWarning,
                              stacklevel=3)
    return _LOADED[key]
