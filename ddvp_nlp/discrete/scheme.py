"""Which discrete equations to use: energy rule, weights and clock (docs/theory.md sections 1-3)."""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import InputError
from ..validation import check_in_range

RULES = ("vddvp", "lee", "fixed")
CLOCKS = ("midpoint", "left")


@dataclass(frozen=True)
class Scheme:
    """The variable-step midpoint family of the paper (case 3).

    Interval ``k`` uses ``Q_k = alpha q_k + beta q_{k+1}``, ``P_k = alpha p_{k+1} + beta p_k``
    with ``beta = 1 - alpha``, and the clock ``s_k = t_k + tau_k/2`` (``clock="midpoint"``) or
    ``s_k = t_k`` (``clock="left"``).

    Attributes:
        rule: energy equation at interior nodes: ``"vddvp"`` (the paper: energy of interval k at
            the previous interval's clock equals the previous energy), ``"lee"`` (``dS_D/dt_k = 0``
            of the same action) or ``"fixed"`` (no energy equation, the steps are given).
        alpha: weight of the scheme; ``1/2`` is the second-order midpoint rule.
        clock: where ``H`` is evaluated in time on each interval.
    """

    rule: str = "vddvp"
    alpha: float = 0.5
    clock: str = "midpoint"

    def __post_init__(self):
        if self.rule not in RULES:
            raise InputError(f"unknown scheme {self.rule!r} (choose from {', '.join(RULES)})")
        check_in_range("alpha", self.alpha, 0.0, 1.0)
        if self.clock not in CLOCKS:
            raise InputError(f"unknown clock {self.clock!r} (choose from {', '.join(CLOCKS)})")
        object.__setattr__(self, "alpha", float(self.alpha))

    @property
    def beta(self) -> float:
        return 1.0 - self.alpha

    @property
    def variable_steps(self) -> bool:
        return self.rule != "fixed"

    @classmethod
    def coerce(cls, scheme: str | Scheme) -> Scheme:
        if isinstance(scheme, Scheme):
            return scheme
        if not isinstance(scheme, str):
            raise InputError(f"scheme must be a name or a Scheme, got {scheme!r}")
        return cls(rule=scheme)
