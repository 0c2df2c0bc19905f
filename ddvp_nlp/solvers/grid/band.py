"""Banded LU with partial pivoting and its solve, compiled: LAPACK's ``dgbtf2`` and ``dgbtrs``
(no transpose, one right-hand side) written out in C, for the bandwidths of the fixed-endpoint
Jacobian (``newton.py``, through ``linear.py``).

Why: the reference ``dgbtf2`` that scipy's OpenBLAS runs for a band this narrow (``kl = 4`` is
below LAPACK's block size) calls ``idamax``, ``dswap``, ``dscal`` and ``dger`` once per column,
and ``dgbtrs`` ``dswap`` and ``dger`` once per column: at ``N m = 3e6`` columns the calls, not the
arithmetic, were the time (``gbtrf`` 0.35 s, ``gbtrs`` 0.17 s; this code 0.15 s and 0.08 s on
the same matrix, measured). The loops are LAPACK's, in LAPACK's order (the same pivots, the
same multipliers, the same updates, compiled without contraction to FMA), so the factors and
solutions are LAPACK's to the bit on the matrices measured
(``tests/library/bvp/test_compiled_assembly.py``).

Built once per compiler and source by ``compiler.py``'s build and cache (``band_HASH.so`` in the
compiled-code cache, checksummed); without a compiler (``Compilation(band_lu="lapack")``, no
compiler found, or a failed build, with one warning per process) `kernel` is ``None`` and
the caller runs LAPACK through scipy.
"""

from __future__ import annotations

import ctypes
import warnings
from pathlib import Path

import numpy as np

from ..compiler import CompileUnavailable, cache_folder, compile_source, find_compiler

SOURCE = r"""
#include <math.h>
/* LAPACK dgbtf2 (kl subdiagonals, ku superdiagonals, ab in gbtrf storage with leading
   dimension ldab >= 2 kl + ku + 1, column-major); 0-based pivots; returns info */
int band_lu(long n, long kl, long ku, double *ab, long ldab, int *ipiv) {
  long kv = ku + kl, ju = 0;
  int info = 0;
  for (long j = ku + 1; j < (kv < n ? kv : n); ++j)
    for (long i = kv - j; i < kl; ++i) ab[i + j * ldab] = 0.0;
  for (long j = 0; j < n; ++j) {
    if (j + kv < n)
      for (long i = 0; i < kl; ++i) ab[i + (j + kv) * ldab] = 0.0;
    long km = kl < n - 1 - j ? kl : n - 1 - j;
    double *col = ab + kv + j * ldab;
    long jp = 0;
    double big = fabs(col[0]);
    for (long i = 1; i <= km; ++i)
      if (fabs(col[i]) > big) { big = fabs(col[i]); jp = i; }
    ipiv[j] = (int)(j + jp);
    if (col[jp] != 0.0) {
      long last = j + ku + jp < n - 1 ? j + ku + jp : n - 1;
      if (last > ju) ju = last;
      if (jp != 0) {
        double *a = col + jp, *b = col;
        for (long c = 0; c <= ju - j; ++c) {
          double t = a[c * (ldab - 1)];
          a[c * (ldab - 1)] = b[c * (ldab - 1)];
          b[c * (ldab - 1)] = t;
        }
      }
      if (km > 0) {
        double r = 1.0 / col[0];
        for (long i = 1; i <= km; ++i) col[i] *= r;
        for (long c = 1; c <= ju - j; ++c) {
          double *dst = ab + kv - c + (j + c) * ldab;
          double u = dst[0];
          if (u != 0.0)
            for (long i = 1; i <= km; ++i) dst[i] -= col[i] * u;
        }
      }
    } else if (info == 0) {
      info = (int)(j + 1);
    }
  }
  return info;
}

/* LAPACK dgbtrs, no transpose, one right-hand side b (overwritten by the solution) */
void band_solve(long n, long kl, long ku, const double *ab, long ldab, const int *ipiv,
                double *b) {
  long kv = ku + kl;
  for (long j = 0; j < n - 1; ++j) {
    long lm = kl < n - 1 - j ? kl : n - 1 - j;
    long l = ipiv[j];
    if (l != j) { double t = b[l]; b[l] = b[j]; b[j] = t; }
    double bj = b[j];
    if (bj != 0.0)
      for (long i = 1; i <= lm; ++i) b[j + i] -= ab[kv + i + j * ldab] * bj;
  }
  for (long j = n - 1; j >= 0; --j) {
    if (b[j] != 0.0) {
      b[j] /= ab[kv + j * ldab];
      double t = b[j];
      long lo = j - kv > 0 ? j - kv : 0;
      for (long i = lo; i < j; ++i) b[i] -= t * ab[kv + i - j + j * ldab];
    }
  }
}
"""

_LOADED: dict = {}


class BandKernel:
    """The compiled ``band_lu`` and ``band_solve`` of one library."""

    def __init__(self, library: Path):
        lib = ctypes.CDLL(str(library))
        matrix = np.ctypeslib.ndpointer(np.float64, ndim=2, flags="F_CONTIGUOUS")
        vector = np.ctypeslib.ndpointer(np.float64, ndim=1, flags="C_CONTIGUOUS")
        pivots = np.ctypeslib.ndpointer(np.int32, ndim=1, flags="C_CONTIGUOUS")
        size = ctypes.c_long
        self._lu = lib.band_lu
        self._lu.argtypes = [size, size, size, matrix, size, pivots]
        self._lu.restype = ctypes.c_int
        self._solve = lib.band_solve
        self._solve.argtypes = [size, size, size, matrix, size, pivots, vector]
        self._solve.restype = None

    def factor(self, ab: np.ndarray, kl: int, ku: int):
        """``(pivots, info)``; ``ab`` (``(2 kl + ku + 1, n)``, Fortran order) becomes the
        factors, as ``dgbtrf`` leaves them."""
        pivots = np.empty(ab.shape[1], np.int32)
        info = self._lu(ab.shape[1], kl, ku, ab, ab.shape[0], pivots)
        return pivots, info

    def solve(self, lu: np.ndarray, kl: int, ku: int, pivots: np.ndarray,
              rhs: np.ndarray) -> np.ndarray:
        """The solution, in ``rhs`` itself when it is a contiguous float array (else a copy)."""
        b = np.ascontiguousarray(rhs, np.float64)
        self._solve(lu.shape[1], kl, ku, lu, lu.shape[0], pivots, b)
        return b


def kernel(compiler: str | None = "auto", cache_dir=None) -> BandKernel | None:
    """The compiled kernel, built (once per source, compiler and flags) or loaded from the
    cache; ``None`` without a compiler or if the build fails (one warning): LAPACK then."""
    found = find_compiler(compiler)
    if found is None:
        return None
    folder = cache_folder(cache_dir)
    key = (found, str(folder))
    if key not in _LOADED:
        try:
            _LOADED[key] = compile_source(SOURCE, "band_lu", found, folder, prefix="band",
                                          load=BandKernel)
        except (CompileUnavailable, OSError) as exc:
            _LOADED[key] = None
            warnings.warn(f"{exc}; the banded LU runs LAPACK through scipy instead (slower, "
                          f"the same factors)", RuntimeWarning, stacklevel=3)
    return _LOADED[key]
