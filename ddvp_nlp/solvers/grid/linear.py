"""The linear solves of the grid's Newton: banded LU of ``F'(x)``, or sparse LU where the band
is wide.

Banded up to ``WIDEST_BAND``: LAPACK's ``gbtrf``/``gbtrs`` (``O(N w^2)`` work and ``O(N w)``
memory, ``w`` the bandwidth), run by the compiled kernel of ``band.py`` when
``Compilation.band_lu`` is ``"compiled"`` and there is a compiler (the same factors), else by
scipy. Wider bands, and problems whose Jacobian is not banded (a periodic grid's corner and
unfolding columns), go to SuperLU.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla
from scipy.linalg import lapack

from ..options import Compilation
from . import band
from .problem import GridProblem

# Band storage above this bandwidth costs more than the sparse factorisation (fill-in of the
# whole band against the blocks' own).
WIDEST_BAND = 32


def band_kernel(compilation: Compilation) -> band.BandKernel | None:
    """The compiled band LU of ``compilation`` (``None``: LAPACK through scipy)."""
    if compilation.band_lu != "compiled":
        return None
    return band.kernel(compilation.compiler, compilation.cache_dir)


class Factorization:
    """LU factors of ``F'(x)``: banded up to ``WIDEST_BAND`` (the compiled ``kernel`` if given,
    else LAPACK through scipy: the same factors), else sparse (SuperLU); ``solve(rhs)`` is
    ``nan`` if the matrix is singular. The band is factorised in place, in the problem's
    store."""

    def __init__(self, problem: GridProblem, jacobian, linear: str = "auto",
                 kernel: band.BandKernel | None = None):
        self.width = problem.layout.bandwidth
        self.banded = linear == "banded" or (linear == "auto" and self.width <= WIDEST_BAND)
        self.singular = False
        self.kernel = None
        if self.banded:
            ab = problem.banded(jacobian)
            self.kernel = kernel if ab.flags.f_contiguous else None
            if self.kernel is not None:
                self.pivots, info = self.kernel.factor(ab, self.width, self.width)
                self.lu = ab
            else:
                self.lu, self.pivots, info = lapack.dgbtrf(ab, self.width, self.width,
                                                           overwrite_ab=1)
            self.singular = info != 0
            return
        try:
            self.lu = spla.splu(problem.sparse(jacobian))
        except RuntimeError:  # SuperLU: "Factor is exactly singular"
            self.singular = True

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``F'(x)^-1 rhs``; ``rhs`` (a temporary of the caller's) may be overwritten."""
        if self.singular:
            return np.full_like(rhs, np.nan)
        if self.kernel is not None:
            return self.kernel.solve(self.lu, self.width, self.width, self.pivots, rhs)
        if self.banded:
            return lapack.dgbtrs(self.lu, self.width, self.width, rhs, self.pivots,
                                 overwrite_b=1)[0]
        return self.lu.solve(rhs)

    def solve_transposed(self, rhs: np.ndarray) -> np.ndarray:
        """``F'(x)^-T rhs`` from the same factors (an adjoint solve ``J^T lambda = g`` is one
        call); ``nan`` if the matrix is singular. The compiled kernel's factors are LAPACK's
        (same storage, same 0-based pivots), so LAPACK's transposed ``gbtrs`` reads them."""
        if self.singular:
            return np.full_like(rhs, np.nan)
        if self.banded:
            return lapack.dgbtrs(self.lu, self.width, self.width, rhs, self.pivots,
                                 trans=1)[0]
        return self.lu.solve(rhs, trans="T")
