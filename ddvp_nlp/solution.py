"""The result of every solve: nodes, status and the checks that were made on them."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np


class Status(enum.Enum):
    """How a solve ended. Every value but ``SUCCESS`` is a failure; its text says what happened
    in words a person can act on (the message of the result adds step, time and state)."""

    SUCCESS = "reached t_end"
    NO_ADMISSIBLE_STEP = "the step equations have no root with tau > 0 near the previous step"
    NEWTON_FAILED = "Newton's method did not converge on the step equations"
    NON_FINITE = "a step produced a non-finite value"
    RESIDUAL_TOO_LARGE = "a step's own unscaled residual is above the tolerance"
    STEP_BELOW_MIN = "the step length fell below tau_min"
    STEP_ABOVE_MAX = "the step length rose above tau_max"
    STEP_RATIO = "the step length changed by more than max_step_ratio in one step"
    MAX_STEPS = "max_steps was reached before t_end"
    TIME_LIMIT = "the time limit was reached before t_end"
    ENERGY_GUARD = "H left the band energy_guard allows around its initial value"
    INACCURATE = ("an accuracy estimate passed its tolerance: the steps satisfy the scheme's "
                  "equations but do not follow the motion")
    INTERRUPTED = "interrupted by the user"
    SOLVER_FAILED = "the NLP solver did not converge"
    NOT_VERIFIED = "the solver's point does not satisfy the equations to the tolerance"

    @property
    def code(self) -> str:
        return self.name.lower()

    @classmethod
    def from_code(cls, code: str) -> Status:
        return cls[code.upper()]


def bound_reached(steps: int, max_steps: int, started: float, time_limit: float | None):
    """``(status, detail)`` if a run has used its steps or its seconds (``started`` from
    ``time.perf_counter()``), else ``None``."""
    import time

    if steps >= max_steps:
        return Status.MAX_STEPS, f"max_steps = {max_steps}"
    if time_limit is not None and time.perf_counter() - started > time_limit:
        return Status.TIME_LIMIT, f"time_limit = {time_limit:g} s"
    return None


@dataclass
class Solution:
    """Nodes ``t`` (N,), ``q`` and ``p`` (N, n), steps ``tau`` (N-1,) and how the solve went.

    Every accepted node is kept, also when ``status`` is a failure.

    Attributes:
        energy_residual: residual of the energy equation at each interior node (N-2,), in the
            units of ``H`` (``fixed`` steps: the ``lee`` balance they do not enforce).
        canonical_residual: largest canonical residual of each interval (N-1,), increment form.
        newton_iterations: Newton iterations of the march's careful steps (compiled fast steps
            do not report theirs; see ``stats["fast_steps"]``), or the NLP solver's iterations.
        solvability: ``c(z_k) = -(f' H_zz f)/8`` at every node for the energy rules (a positive
            step needs it to keep its sign; THEORY.md section 5), else empty.
        local_error: the accuracy check's local error estimate of each step (N-1,), against one
            RK4 step of the exact flow (``solvers/accuracy.py``), where it was made.
        timing: ``build_s`` and ``solve_s`` in seconds.
        stats: solver-specific statistics (IPOPT's, the march's retries, ...).
    """

    t: np.ndarray
    q: np.ndarray
    p: np.ndarray
    status: Status
    message: str
    scheme: str
    energy_residual: np.ndarray
    canonical_residual: np.ndarray
    newton_iterations: int = 0
    solvability: np.ndarray = field(default_factory=lambda: np.zeros(0))
    local_error: np.ndarray = field(default_factory=lambda: np.zeros(0))
    timing: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)

    @property
    def success(self) -> bool:
        return self.status is Status.SUCCESS

    @property
    def tau(self) -> np.ndarray:
        return np.diff(self.t)

    @property
    def steps(self) -> int:
        return max(self.t.size - 1, 0)

    def __repr__(self) -> str:
        return (f"Solution(status={self.status.code}, steps={self.steps}, "
                f"t=[{self.t[0]:.6g}, {self.t[-1]:.6g}], message={self.message!r})")
