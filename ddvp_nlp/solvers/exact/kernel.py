"""The accuracy check's passes over every node in C, written as numpy computes them, operation
for operation: the continuous extension of an adaptive run read at many times (`Trajectory`),
the running envelope of a reference's claimed error (``reference.py``, ``Reference.at``: the
two runs read at the samples and compared), the scan of the nodes against the reference's
states (``accuracy/judgement.py``, ``Scan.measure``: each row's error in the motion's scales
up to the first one over the tolerance, the columns' least and greatest states and largest
differences, in one pass), the sizes of ``|S * grad H|`` with each node's share of the time
(the energy scale) and the columns' extremes of a table.

Why: numpy reads a run's dense output at ``N`` times in about 22 passes over an ``(N, d)``
table (eight gathers, seven products and seven sums of the Horner scheme), and scans the nodes
in a dozen more, each a loop of its own through memory; the check of a march does both at
every node, and on Henon-Heiles (9 650 nodes and 2 x 2 865 samples of the claim) the reading
alone was 1.4 ms of a check of 4 ms, for a march of 4.9 ms. One loop in C reads each row once.

The same numbers to the bit: each value is the same sequence of IEEE operations as numpy's
(``x = (s - t_old) / h``, Horner alternating ``x`` and ``1 - x``, ``+ w_old``; ``|z - state|
/ S`` and its maximum, NaN propagating; a row's squares summed column after column), compiled
without contraction to FMA (``compiler.COMPILE_FLAGS``); the step holding a time is numpy's
``searchsorted(..., side="right") - 1`` clipped to the steps; minima, maxima and the first
largest are exact whatever the order (``tests/library/exact/test_kernel.py`` and
``tests/library/accuracy/test_check_cost.py`` compare the two). Passes whose work is a
division per entry (the steps' local figures) stay numpy's: its divisions run in vector
registers, and a scalar loop in C measured no faster.

Built once per compiler and source by ``compiler.py``'s build and cache (``check_HASH.so``,
checksummed), and only once the work pays for it: `kernel` loads a library already in the
cache, builds one only when told the work is paid (``build=True``: the exact flow asks so once
its own chunk is compiled, whose rent the checks of the system have paid), and is ``None``
otherwise, without a compiler or after a failed build (one warning); the caller then runs
numpy, which gives the same numbers.
"""

from __future__ import annotations

import ctypes
import os
import threading
import warnings

import numpy as np

from ..columns import column_extremes
from ..compiler import CompileUnavailable, cache_folder, compile_source, find_compiler

# Columns from which the compiled pass over a table's columns is the faster: numpy reduces a
# column or two in vector registers (20 151 x 2: 0.03 ms against the loop's 0.07), a dozen in
# as many strided passes (99 899 x 12: 2.6 ms against 0.8-1.0).
FEW_COLUMNS = 8

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

/* numpy's maximum: NaN if either is */
static double greater(double a, double b) { return (a >= b || a != a) ? a : b; }

/* A run as dense_values reads it, and the step of the last time read */
typedef struct {
  long steps, row, plane, row_F, k;
  const double *t_old, *h, *w_old, *F;
  double direction, x, one_minus;
} run_t;

/* The run's step holding time s and x = (s - t_old) / h there, as dense_values finds them */
static void seek(run_t *run, double s) {
  run->k = step_of(run->direction * s, run->direction, run->t_old, run->steps, run->k);
  double x = s - run->t_old[run->k];
  x /= run->h[run->k];
  run->x = x;
  run->one_minus = 1.0 - x;
}

/* Component c of the run's continuous extension at the time `seek` found, as dense_values */
static double value_at(const run_t *run, long c) {
  const double *f = run->F + run->k * run->row_F + c;
  double x = run->x, one_minus = run->one_minus, y = f[6 * run->plane] * x;
  y += f[5 * run->plane]; y *= one_minus;
  y += f[4 * run->plane]; y *= x;
  y += f[3 * run->plane]; y *= one_minus;
  y += f[2 * run->plane]; y *= x;
  y += f[run->plane]; y *= one_minus;
  y += f[0]; y *= x;
  return y + run->w_old[run->k * run->row + c];
}

/* The running envelope of a reference's claim (exact/reference.py, Reference.at): at each of
   the n sample times, max_j |coarse_j - fine_j| / scale_j of the two runs' continuous
   extensions (row_max_ratio's numbers, NaN if any term is), then the running maximum of its
   maximum with `floor` (numpy's maximum.accumulate of maximum(difference, floor)), into
   `running`. Each run as dense_values takes it: steps, t_old, h, w_old, row, F, plane, row_F,
   direction. */
void claim_envelope(long n, const double *samples, long d, const double *scale, double floor_,
                    long fs, const double *ft, const double *fh, const double *fw, long frow,
                    const double *fF, long fplane, long frowF, double fdirection,
                    long cs, const double *ct, const double *ch, const double *cw, long crow,
                    const double *cF, long cplane, long crowF, double cdirection,
                    double *running) {
  run_t fine = {fs, frow, fplane, frowF, 0, ft, fh, fw, fF, fdirection, 0.0, 0.0};
  run_t coarse = {cs, crow, cplane, crowF, 0, ct, ch, cw, cF, cdirection, 0.0, 0.0};
  double envelope = 0.0;
  for (long i = 0; i < n; ++i) {
    seek(&fine, samples[i]);
    seek(&coarse, samples[i]);
    double error = 0.0;
    for (long c = 0; c < d; ++c) {
      double q = fabs(value_at(&coarse, c) - value_at(&fine, c)) / scale[c];
      error = c ? greater(error, q) : q;
    }
    double bounded = greater(error, floor_);
    envelope = i ? greater(envelope, bounded) : bounded;
    running[i] = envelope;
  }
}

/* |S * grad H| at each node, sqrt(sum_j (field_j w_j)^2) summed column after column
   (columns.row_norm, at most 16 columns), and each node's share of the time (half of each
   step beside it), as accuracy/judgement.py's gradient_sizes computes them. */
void gradient_sizes(long nodes, long m, const double *restrict field, long stride,
                    const double *restrict w, const double *restrict t,
                    double *restrict norm, double *restrict share) {
  for (long k = 0; k < nodes; ++k) {
    const double *row = field + k * stride;
    double v = row[0] * w[0], sum = v * v;
    for (long j = 1; j < m; ++j) { v = row[j] * w[j]; sum += v * v; }
    norm[k] = sqrt(sum);
    double before = k ? (t[k] - t[k - 1]) / 2 : 0.0;
    double after = k + 1 < nodes ? (t[k + 1] - t[k]) / 2 : 0.0;
    share[k] = k + 1 < nodes ? (k ? 0.0 + after + before : 0.0 + after) : 0.0 + before;
  }
}

/* The least and greatest value of each column of `values` (rows x m, row stride), numpy's
   min and max (NaN if any is). */
void column_extremes(long rows, long m, const double *restrict values, long stride,
                     double *restrict low, double *restrict high) {
  int nan[m];
  for (long j = 0; j < m; ++j) { low[j] = values[j]; high[j] = values[j]; nan[j] = 0; }
  for (long k = 1; k < rows; ++k) {
    const double *row = values + k * stride;
    for (long j = 0; j < m; ++j) {  /* no branch on the data */
      double v = row[j];
      nan[j] |= v != v;
      low[j] = v < low[j] ? v : low[j];
      high[j] = v > high[j] ? v : high[j];
    }
  }
  for (long j = 0; j < m; ++j)
    if (nan[j] || low[j] != low[j]) { low[j] = NAN; high[j] = NAN; }
}

/* The RK4 screen's differences d of each step (steps x m, row stride), read without a
   division: local[k] = max_j |d_kj| (columns.row_max's numbers, NaN if any is); flag[k] = 1
   where some |d_kj| is not <= bound_j (a NaN too), else 0; colmax_j the largest |d_kj| over
   the unflagged steps (0 if none). Returns the number of flagged steps. */
long screen_steps(long steps, long m, const double *restrict d, long stride,
                  const double *restrict bound, double *restrict local,
                  double *restrict colmax, unsigned char *restrict flag) {
  long flagged = 0;
  for (long j = 0; j < m; ++j) colmax[j] = 0.0;
  for (long k = 0; k < steps; ++k) {
    const double *row = d + k * stride;
    double top = fabs(row[0]);
    int nan = top != top, over = !(top <= bound[0]);
    for (long j = 1; j < m; ++j) {
      double v = fabs(row[j]);
      nan |= v != v;
      over |= !(v <= bound[j]);
      top = v > top ? v : top;
    }
    local[k] = nan ? NAN : top;
    flag[k] = (unsigned char)over;
    flagged += over;
    if (!over)
      for (long j = 0; j < m; ++j) {
        double v = fabs(row[j]);
        colmax[j] = v > colmax[j] ? v : colmax[j];
      }
  }
  return flagged;
}

/* The claim at each of the n times from the running envelope at the m samples (increasing
   in the run's direction): SAFETY * max(running[i], rtol) at the first sample i at or after
   the time (numpy's searchsorted(keys, times, side="left") clipped to the samples, keys and
   times multiplied by the direction; a NaN time after every sample), as Reference.at. */
void claim_at(long n, const double *times, double direction, long m, const double *samples,
              const double *running, double safety, double rtol, double *claim) {
  long i = 0;  /* the sample of the time before: increasing times find theirs a few on */
  for (long k = 0; k < n; ++k) {
    double key = direction * times[k];
    long at = m;
    if (key == key) {
      long lo, hi;
      if (i < m && !(direction * samples[i] < key)) {  /* at sample i or before it */
        lo = (i > 0 && direction * samples[i - 1] < key) ? i : 0;
        hi = i;
      } else {  /* past sample i (or anywhere): a few samples on, else bisection */
        lo = i < m ? i + 1 : 0;
        hi = m;
        long ahead = lo + 8 < m ? lo + 8 : m;
        while (lo < ahead && direction * samples[lo] < key) ++lo;
        if (lo < ahead) hi = lo;
      }
      while (lo < hi) {
        long mid = lo + (hi - lo) / 2;
        if (direction * samples[mid] < key) lo = mid + 1; else hi = mid;
      }
      at = i = lo;
    }
    double r = running[at < m ? at : m - 1];
    claim[k] = safety * ((r >= rtol || r != r) ? r : rtol);
  }
}
"""

_LOADED: dict = {}  # (compiler, folder) -> the kernel, or None (not in the cache, or failed)
_FAILED: set = set()  # (compiler, folder) whose build failed: not tried again
_RESOLVED: dict = {}  # the arguments of `kernel` (and the cache's variable) -> (compiler, folder)
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
        self._claim = lib.claim_envelope
        run = [size, pointer, pointer, pointer, size, pointer, size, size, ctypes.c_double]
        self._claim.argtypes = [size, pointer, size, pointer, ctypes.c_double, *run, *run,
                                pointer]
        self._claim.restype = None
        self._claim_at = lib.claim_at
        self._claim_at.argtypes = [size, pointer, ctypes.c_double, size, pointer, pointer,
                                   ctypes.c_double, ctypes.c_double, pointer]
        self._claim_at.restype = None
        self._screen = lib.screen_steps
        self._screen.argtypes = [size, size, pointer, size, pointer, pointer, pointer, pointer]
        self._screen.restype = size
        self._gradient = lib.gradient_sizes
        self._gradient.argtypes = [size, size, pointer, size, pointer, pointer, pointer,
                                   pointer]
        self._gradient.restype = None
        self._extremes = lib.column_extremes
        self._extremes.argtypes = [size, size, pointer, size, pointer, pointer]
        self._extremes.restype = None

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

    def claim_envelope(self, fine, coarse, samples: np.ndarray, scale: np.ndarray,
                       floor: float) -> np.ndarray:
        """The running maximum, from ``floor``, of ``max_j |coarse_j - fine_j| / scale_j`` of
        two runs (`Trajectory`, each with a step, `run_readable`) at ``samples``
        (``Reference.at``'s numbers)."""
        samples = np.ascontiguousarray(samples, float)
        scale = np.ascontiguousarray(scale, float)
        running = np.empty(samples.size)
        self._claim(samples.size, samples.ctypes.data, fine.d, scale.ctypes.data,
                    float(floor), *self._run(fine), *self._run(coarse), running.ctypes.data)
        return running

    def claim_at(self, times: np.ndarray, forward: bool, samples: np.ndarray,
                 running: np.ndarray, safety: float, rtol: float) -> np.ndarray:
        """``safety * max(running[i], rtol)`` at the first sample ``i`` at or after each time
        (``Reference.at``'s numbers: ``searchsorted(..., side="left")`` clipped to the
        samples, in the run's direction); ``samples`` and ``running`` C-ordered, at least
        one."""
        times = np.ascontiguousarray(times, float)
        claim = np.empty(times.size)
        self._claim_at(times.size, times.ctypes.data, 1.0 if forward else -1.0, samples.size,
                       samples.ctypes.data, running.ctypes.data, float(safety), float(rtol),
                       claim.ctypes.data)
        return claim

    @staticmethod
    def _run(run) -> tuple:
        item = run.F.itemsize
        return (run.t_old.size, run.t_old.ctypes.data, run.h.ctypes.data,
                run.w_old.ctypes.data, run.w_old.strides[0] // item, run.F.ctypes.data,
                run.F.strides[0] // item, run.F.strides[1] // item,
                1.0 if run.t_end >= run.t0 else -1.0)

    def run_readable(self, run) -> bool:
        """Whether the kernel reads ``run`` (`Trajectory`) as it is: dense, with a step."""
        return run.F is not None and run.steps > 0 and \
            self.readable(run.t_old, run.h, run.w_old, run.F)

    def screen_steps(self, d: np.ndarray, bound: np.ndarray):
        """``(local, colmax, flagged)`` of the steps' screen differences ``d`` (rows, each
        contiguous): ``max_j |d_kj|`` of each step (``columns.row_max``'s numbers), the
        largest ``|d_kj|`` of each column over the steps with every ``|d_kj| <= bound_j``, and
        the indices of the others (a NaN among them)."""
        steps, m = d.shape
        bound = np.ascontiguousarray(np.broadcast_to(bound, (m,)), float)
        local, colmax = np.empty(steps), np.empty(m)
        flag = np.empty(steps, dtype=np.uint8)
        flagged = self._screen(steps, m, d.ctypes.data, d.strides[0] // d.itemsize,
                               bound.ctypes.data, local.ctypes.data, colmax.ctypes.data,
                               flag.ctypes.data)
        return local, colmax, (np.flatnonzero(flag) if flagged else np.zeros(0, np.intp))

    def gradient_sizes(self, t: np.ndarray, field: np.ndarray, weights: np.ndarray):
        """``(share, norm)``: each node's share of the time and ``|field * weights|_2``
        summed column after column (``columns.row_norm``'s numbers up to its 16 columns)."""
        nodes, m = field.shape
        t = np.ascontiguousarray(t, float)
        weights = np.ascontiguousarray(weights, float)
        norm, share = np.empty(nodes), np.empty(nodes)
        self._gradient(nodes, m, field.ctypes.data, field.strides[0] // field.itemsize,
                       weights.ctypes.data, t.ctypes.data, norm.ctypes.data,
                       share.ctypes.data)
        return share, norm

    def column_extremes(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`columns.column_extremes`' numbers of ``values`` (rows, each contiguous, at least
        one): the least, the greatest and the largest magnitude of each column."""
        rows, m = values.shape
        if m < FEW_COLUMNS:  # numpy's reductions of a few columns are the faster
            return column_extremes(values)
        low, high = np.empty(m), np.empty(m)
        self._extremes(rows, m, values.ctypes.data, values.strides[0] // values.itemsize,
                       low.ctypes.data, high.ctypes.data)
        return low, high, np.maximum(np.abs(low), np.abs(high))

    @staticmethod
    def table_readable(values: np.ndarray) -> bool:
        """Whether a table (rows, each contiguous) is read as it is: float64, 2-d, a row."""
        return values.dtype == np.float64 and values.ndim == 2 and values.shape[0] > 0 and \
            values.shape[1] > 0 and values.strides[1] == values.itemsize and \
            values.strides[0] % values.itemsize == 0

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
    asked = (compiler, cache_dir if cache_dir is not None else
             os.environ.get("DDVP_NLP_CACHE"))
    key = _RESOLVED.get(asked)
    if key is None:  # the compiler and the folder, looked up once (10 us a call: paths)
        found = find_compiler(compiler) if compiler is not None else None
        key = _RESOLVED[asked] = (found, None if found is None else str(cache_folder(cache_dir)))
    found, folder = key
    if found is None:
        return None
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
