"""The exact flow's tolerance policy, in one place: how tightly the flow is integrated where a
Newton on it (shooting, closure, transfer, fit) or a check reads it, and how closely those
Newtons solve their equations. Every module that runs the exact flow for a solve or a verdict
takes its tolerances from here (named for what they are for), so the policy is changed once.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ExactTolerance:
    """One tolerance policy of the exact flow.

    Attributes:
        flow_rtol: the flow's relative tolerance inside a Newton on it (shooting, closure,
            transfer, fit) and for the level of a verdict: its error is then far below the
            Newton's own ``newton_tol`` of the motion's size.
        reference_rtol: the first tolerance of a reference trajectory that states its own
            error (tightened by 100 while it must be).
        newton_tol: the residual, relative to the motion's size, a Newton on the exact flow
            stops at (continuity, end positions, closure, fit).
    """

    flow_rtol: float = 1e-12
    reference_rtol: float = 1e-9
    newton_tol: float = 1e-10


EXACT_TOLERANCE = ExactTolerance()
