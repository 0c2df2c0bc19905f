"""The grid's one solve policy, shared by every grid family: which solvers run in which order,
the record of each run, and what the status of a point that fails its verification is.

``solver="auto"`` is Newton, then IPOPT from the same start when Newton's point fails its
verification (the time limit ends the solve either way; a family may hold IPOPT back with a
reason, e.g. a fixed-endpoint start on a branch that leads nowhere); ``"newton"`` or
``"ipopt"`` runs that one. Whatever a solver says of itself is recorded (`Stage`) and quoted;
whether its point solves the problem is the family's verification, by the point's own
residuals (the grid contract, rule 6).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ...solution import Status
from .problem import timed_out


@dataclass
class Stage:
    """One solver's run on one system of a grid solve.

    Attributes:
        name: what was solved (``"vddvp equations"``, ``"fixed steps on uniform times"``, a
            higher-order rule).
        solver: ``"newton"`` or ``"ipopt"``.
        converged: whether the solver says it converged (never trusted on its own).
        said: the solver's own words (IPOPT's return status, Newton's outcome).
        iterations: its iterations.
        seconds: its wall time.
        steps: the steps of a continuation (``None`` for a plain solve).
    """

    name: str
    solver: str
    converged: bool = False
    said: str = ""
    iterations: int = 0
    seconds: float = 0.0
    steps: int | None = None

    @property
    def quoted(self) -> str:
        """``"solver: what it said"``, as messages quote it."""
        return f"{self.solver}: {self.said}"

    def record(self) -> dict:
        """The stage as ``meta.json`` keeps it (``phases``)."""
        record = {"phase": self.name, "solver": self.solver, "converged": self.converged,
                  "return_status": self.said, "iterations": self.iterations,
                  "seconds": self.seconds}
        return record if self.steps is None else {**record, "steps": self.steps}


@dataclass
class Attempt:
    """A stage's point ``x`` and the family's verification of it: ``outcome`` is ``(status,
    message, details)``."""

    x: np.ndarray
    stage: Stage
    outcome: tuple

    @property
    def status(self) -> Status:
        return self.outcome[0]


def solver_order(solver: str) -> tuple[str, ...]:
    """The solvers ``solver`` (a `GridOptions.solver`) runs, in order."""
    return ("newton", "ipopt") if solver == "auto" else (solver,)


def solve_in_order(order, attempt: Callable[[str], Attempt], *,
                   enough=(Status.SUCCESS, Status.TIME_LIMIT),
                   held_back: Callable[[Attempt], str | None] = lambda first: None):
    """Each solver of ``order`` in turn from the same start (``attempt(solver)``) until one's
    point has a status in ``enough``, or ``held_back(first attempt)`` gives a reason not to go
    on. Returns ``(chosen, tried, reason)``: the first attempt that succeeded, else the first
    one; every attempt made; the reason the others were held back (or ``None``)."""
    tried: list[Attempt] = []
    for solver in order:
        if tried:
            reason = held_back(tried[0])
            if reason is not None:
                return tried[0], tried, reason
        tried.append(attempt(solver))
        if tried[-1].status in enough:
            break
    chosen = next((a for a in tried if a.status is Status.SUCCESS), tried[0])
    return chosen, tried, None


def failure_status(stage: Stage, tau: np.ndarray) -> Status:
    """The status of a point that fails its verification: the time limit if the solver hit
    it, a solver failure if it says it did not converge, no admissible step if a step is not
    positive, else not verified (the solver says it converged, the residuals say otherwise)."""
    if timed_out(stage.said):
        return Status.TIME_LIMIT
    if not stage.converged:
        return Status.SOLVER_FAILED
    if tau.size and np.min(tau) <= 0:
        return Status.NO_ADMISSIBLE_STEP
    return Status.NOT_VERIFIED


def worst_against(residuals: dict, limits: dict) -> tuple[dict, dict]:
    """``(worst, limit)`` by kind of row: the residual of the row of each kind furthest over
    (or nearest) its own limit, and that limit (``residuals``: arrays by kind, ``(rows, k)``
    against limits of shape ``(k,)`` or a number)."""
    worst, limit = {}, {}
    for name, values in residuals.items():
        values = np.abs(np.atleast_1d(np.asarray(values, float)))
        bound = np.broadcast_to(np.asarray(limits[name], float), values.shape[-1:])
        if not np.all(np.isfinite(values)):
            worst[name], limit[name] = float("nan"), float(np.max(bound))
            continue
        per_column = np.max(values.reshape(-1, bound.size), axis=0)
        j = int(np.argmax(per_column / bound))
        worst[name], limit[name] = float(per_column[j]), float(bound[j])
    return worst, limit
