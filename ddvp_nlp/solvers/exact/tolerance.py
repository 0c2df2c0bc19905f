"""The exact flow's tolerance policy, as ``exact/`` and its readers import it: `ExactTolerance`
and its one instance ``EXACT_TOLERANCE`` are defined once in the core (``solvers/options.py``),
where ``marching/``, which may not import ``exact/``, reads them too."""

from __future__ import annotations

from ..options import EXACT_TOLERANCE, ExactTolerance

__all__ = ["EXACT_TOLERANCE", "ExactTolerance"]
