"""The accuracy check's passes over every node in C, written as numpy computes them, operation
for operation: the continuous extension of an adaptive run read at many times (`Trajectory`),
and the scan of the nodes against the reference's states (``accuracy/judgement.py``,
``Scan.measure``: each row's error in the motion's scales up to the first one over the
tolerance, the columns' least and greatest states and largest differences, in one pass).

Why: numpy reads a run's dense output at ``N`` times in about 22 passes over an ``(N, d)``
table (eight gathers, seven products and seven sums of the Horner scheme), and scans the nodes
in a dozen more, each a loop of its own through memory; the check of a march does both at
every node, and on Henon-Heiles (9 650 nodes and 2 x 2 865 samples of the claim) the reading
alone was 1.4 ms of a check of 4 ms, for a march of 4.9 ms. One loop in C reads each row once.

The same numbers to the bit: each value is the same sequence of IEEE operations as numpy's
(``x = (s - t_old) / h``, Horner alternating ``x`` and ``1 - x``, ``+ w_old``; ``|z - state| /
S`` and its maximum, NaN propagating), compiled without contraction to FMA
(``compiler.COMPILE_FLAGS``); the step holding a time is numpy's ``searchsorted(...,
side="right") - 1`` clipped to the steps; minima, maxima and the first largest are exact
whatever the order (``tests/library/exact/test_kernel.py``,
``tests/library/accuracy/test_check_cost.py`` compare the two).

Built once per compiler and source by ``compiler.py``'s build and cache (``check_HASH.so``,
checksummed), and only once the work pays for it: `kernel` loads a library already in the
cache, builds one only when told the work is paid (``build=True``: the exact flow asks so once
its own chunk is compiled, whose rent the checks of the system have paid), and is ``None``
otherwise, without a compiler or after a failed build (one warning); the caller then runs
numpy, which gives the same numbers.
"""

from __future__ import annotations

import ctypes
import threading
import warnings

import numpy as np

from ..compiler import CompileUnavailable, cache_folder, compile_source, find_compiler

SOURCE = r"""
#include <math.h>

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
   steps (t_old, h; w_old[k * row + c]: the start of step k; F[j * plane + k * row_F + c]: its
   dense-output row j) at the n times; `direction` the run's (+1 or -1). Each value as numpy
   computes it in trajectory.py. */
void dense_values(long steps, const double *t_old, const double *h, const double *w_old,
                  long row, const double *F, long plane, long row_F, double direction, long n,
                  const double *times, long c0, long c1, double *out) {
  long width = c1 - c0, k = 0;
  for (long i = 0; i < n; ++i) {
    double s = times[i];
    k = step_of(direction * s, direction, t_old, steps, k);
    double x = s - t_old[k];
    x /= h[k];
    double one_minus = 1.0 - x;
    const double *f = F + k * row_F, *w = w_old + k * row;
    double *values = out + i * width;
    for (long c = c0; c < c1; ++c) {
      double y = f[6 * plane + c] * x;
      y += f[5 * plane + c]; y *= one_minus;
      y += f[4 * plane + c]; y *= x;
      y += f[3 * plane + c]; y *= one_minus;
      y += f[2 * plane + c]; y *= x;
      y += f[1 * plane + c]; y *= one_minus;
      y += f[c]; y *= x;
      y += w[c];
      values[c - c0] = y;
    }
  }
}

/* A pass of the accuracy check's scan (accuracy/judgement.py, Scan.measure) over nodes `rows`
   (row i at rows + i * stride) against the reference's `states` (n x d, finite): from row 0 on,
   the least and greatest value of each column of `states` (low, high), the first row of the
   largest |rows_ij - states_ij| of each column and that value (node, value: numpy's argmax,
   the first of equal ones, the first NaN before all) and each row's error
   max_j |rows_ij - states_ij| / scale_j, as row_max_ratio computes it; stops after the first
   row whose error is not <= tol and returns it, or returns -1 after `limit` rows. No branch
   on the data but the argmax's, which rarely changes (a branch per column cost 0.4 ms on
   Kepler's 22 000 nodes). */
long scan_rows(long limit, long d, const double *restrict rows, long stride,
               const double *restrict states, const double *restrict scale, double tol,
               double *restrict low, double *restrict high, long *restrict node,
               double *restrict value) {
  for (long j = 0; j < d; ++j) {
    low[j] = states[j]; high[j] = states[j];
    node[j] = 0; value[j] = fabs(rows[j] - states[j]);
  }
  for (long i = 0; i < limit; ++i) {
    const double *r = rows + i * stride, *s = states + i * d;
    double error = 0.0;
    int nan = 0;  /* numpy's maximum: NaN if any is, and then the row is over */
    for (long j = 0; j < d; ++j) {
      double v = s[j], difference = fabs(r[j] - v), q = difference / scale[j], best = value[j];
      nan |= q != q;
      error = (j == 0 || q > error) ? q : error;
      low[j] = v < low[j] ? v : low[j];
      high[j] = v > high[j] ? v : high[j];
      if (difference > best || (difference != difference && best == best)) {
        value[j] = difference; node[j] = i;
      }
    }
    if (nan || !(error <= tol)) return i;
  }
  return -1;
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
        self._dense.argtypes = [size, pointer, pointer, pointer, size, pointer, size, size,
                                ctypes.c_double, size, pointer, size, size, pointer]
        self._dense.restype = None
        self._scan = lib.scan_rows
        self._scan.argtypes = [size, size, pointer, size, pointer, pointer, ctypes.c_double,
                               pointer, pointer, pointer, pointer]
        self._scan.restype = size

    def dense_values(self, t_old: np.ndarray, h: np.ndarray, w_old: np.ndarray,
                     F: np.ndarray, direction: float, times: np.ndarray, c0: int, c1: int,
                     out: np.ndarray) -> None:
        """``out`` (C-ordered ``(len(times), c1 - c0)``): components ``c0 .. c1`` of the
        continuous extension at ``times`` (``Trajectory.__call__``'s numbers). ``t_old``,
        ``h`` and ``times`` C-ordered float64; ``w_old`` ``(steps, D)`` and ``F``
        ``(POWER, steps, D)`` float64 with contiguous rows, any row strides (views of the
        flow's records); check with `readable`."""
        item = F.itemsize
        self._dense(t_old.size, t_old.ctypes.data, h.ctypes.data, w_old.ctypes.data,
                    w_old.strides[0] // item, F.ctypes.data, F.strides[0] // item,
                    F.strides[1] // item, float(direction), times.size, times.ctypes.data,
                    c0, c1, out.ctypes.data)

    def scan_rows(self, rows: np.ndarray, states: np.ndarray, scale: np.ndarray, tol: float,
                  limit: int) -> tuple[int | None, tuple | None]:
        """``(over, (low, high, node, value))``: the first of the first ``limit`` rows whose
        error ``max_j |rows_ij - states_ij| / scale_j`` (``columns.row_max_ratio``'s numbers)
        is not ``<= tol``, or ``None``; over the rows up to it (or the ``limit``), the least and
        greatest value of each column of ``states`` (`column_extremes`' numbers, the rows being
        finite) and `column_argmax` of ``|rows - states|`` with the value there (``None`` for no
        row). ``rows`` with contiguous rows (any stride), ``states`` C-ordered."""
        d = states.shape[1]
        if limit <= 0:
            return None, None
        low, high, value = np.empty(d), np.empty(d), np.empty(d)
        node = np.empty(d, dtype=np.int64)
        scale = np.ascontiguousarray(scale, float)
        over = self._scan(limit, d, rows.ctypes.data, rows.strides[0] // rows.itemsize,
                          states.ctypes.data, scale.ctypes.data, float(tol), low.ctypes.data,
                          high.ctypes.data, node.ctypes.data, value.ctypes.data)
        return (None if over < 0 else int(over)), (low, high, node.astype(np.intp), value)

    @staticmethod
    def rows_readable(*arrays) -> bool:
        """Whether `scan_rows` reads these tables as they are: float64,
        each row contiguous (the second C-ordered too)."""
        rows, states = arrays
        return rows.dtype == np.float64 and states.dtype == np.float64 and \
            rows.ndim == 2 and rows.strides[1] == rows.itemsize and \
            rows.strides[0] % rows.itemsize == 0 and states.flags.c_contiguous

    @staticmethod
    def readable(t_old, h, w_old, F) -> bool:
        """Whether `dense_values` reads these arrays as they are."""
        flat = all(a.dtype == np.float64 and a.flags.c_contiguous for a in (t_old, h))
        return flat and all(a.dtype == np.float64 and a.strides[-1] == a.itemsize and
                            all(s % a.itemsize == 0 for s in a.strides) for a in (w_old, F))


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
