"""The march's problem: the checked inputs of one initial-value problem (`MarchProblem`).

`check_problem` checks every input of `march` but the option objects, in the order of its
signature, before anything is built (``InputError`` naming the argument and the value), and
returns the problem: the system and scheme, the start ``z_0 = (q_0, p_0)`` (``p_0`` from ``v0``
by the discrete Legendre transform if that was given), the times, the parameter vector ``theta``,
``H(z_0, t_0)``, the step control and its acceptance test. A `MarchSession` (``session.py``)
marches it; ``march_ensemble`` and the chaos indicators check each of their starts with it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...discrete import equations
from ...discrete.scheme import Scheme
from ...errors import InputError
from ...physics.constraints import refuse_constrained
from ...physics.hamiltonian import HamiltonianSystem
from ...validation import check_span, check_state, check_step
from ..accuracy.judgement import Level
from ..compiler import buffered
from ..options import StepControl
from .acceptance import Acceptance

__all__ = ["MarchProblem", "check_problem"]


@dataclass(frozen=True)
class MarchProblem:
    """The checked inputs of one march: the system and scheme, the start (``p0`` from ``v0``
    if that was given), the times, the parameter vector, ``H(z_0, t_0)``, the step control and
    the acceptance test it makes."""

    system: HamiltonianSystem
    scheme: Scheme
    q0: np.ndarray
    p0: np.ndarray
    t0: float
    t_end: float
    tau0: float
    theta: np.ndarray
    H0: float
    steps: StepControl
    acceptance: Acceptance

    @property
    def z0(self) -> np.ndarray:
        """The start ``z_0 = (q_0, p_0)``, shape ``(2n,)``."""
        return np.concatenate([self.q0, self.p0])

    def level(self, t, z) -> Level | None:
        """The energy level the first step of an energy rule sets: the first interval's
        energy at its clock, from the nodes ``t``, ``z`` (``None`` for fixed steps, or before
        a step)."""
        system, scheme, theta = self.system, self.scheme, self.theta
        if not scheme.variable_steps or t.size < 2:
            return None
        interval_energy = buffered(equations.midpoint_energy_function(system, scheme),
                                   "interval_energy", scheme, owner=system)
        n = system.n
        value = float(interval_energy(t[0], t[1], z[0, :n], z[0, n:], z[1, :n], z[1, n:],
                                      theta)[0][0, 0])
        return Level(value, float(t[0] + (t[1] - t[0]) / 2 if scheme.clock == "midpoint"
                                  else t[0]))


def check_problem(system, scheme: Scheme, q0, p0, v0, t_span, tau0, steps: StepControl,
                  params) -> MarchProblem:
    """Every input of `march` but the options objects, checked in the order of its
    signature (``InputError`` naming the argument and the value), before anything is built;
    ``march_ensemble`` checks each of its starts with it."""
    if not isinstance(system, HamiltonianSystem):
        raise InputError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
    refuse_constrained(system, "this solver (march's problem check)")
    q0, p0, v0 = _check_state(system, q0, p0, v0)
    t0, t_end, tau0 = _check_times(t_span, tau0)
    if (steps.tau_min is not None and tau0 < steps.tau_min) or \
            (steps.tau_max is not None and tau0 > steps.tau_max):
        raise InputError(f"tau0 must lie in [tau_min, tau_max] = [{steps.tau_min}, "
                         f"{steps.tau_max}], got {tau0!r}")
    if steps.breakdown == "least_squares" and not scheme.variable_steps:
        raise InputError("breakdown='least_squares' needs an energy rule (vddvp or lee), got "
                         f"scheme {scheme.rule!r}")
    theta = system.parameter_vector(params)
    p0, H0 = _start(system, scheme, q0, p0, v0, t0=t0, tau0=tau0, theta=theta)
    return MarchProblem(system, scheme, q0, p0, t0, t_end, tau0, theta, H0, steps,
                        Acceptance.at_start(steps, system, q0, p0, t0, tau0, theta))


def _check_state(system, q0, p0, v0):
    """``q0`` and exactly one of ``p0`` and ``v0``."""
    q0 = check_state("q0", q0, system.n)
    if (p0 is None) == (v0 is None):
        raise InputError("give exactly one of p0 and v0")
    if v0 is not None and not system.lagrangian_form:
        raise InputError(f"v0 needs a Lagrangian system; {system.name!r} is Hamiltonian: "
                         "give p0")
    p0 = check_state("p0", p0, system.n) if p0 is not None else None
    v0 = check_state("v0", v0, system.n) if v0 is not None else None
    return q0, p0, v0


def _check_times(t_span, tau0):
    """``t0 < t_end`` and a first step ``0 < tau0 <= t_end - t0``."""
    t0, t_end = check_span(t_span)
    tau0 = check_step(tau0, t0, t_end)
    if tau0 > t_end - t0:
        raise InputError(f"tau0 must not exceed |t_end - t0| = {t_end - t0!r}, got {tau0!r}")
    return t0, t_end, tau0


def _start(system, scheme, q0, p0, v0, *, t0, tau0, theta) -> tuple[np.ndarray, float]:
    """``p_0`` (from ``v0`` by the discrete Legendre transform if given) and ``H(z_0, t_0)``."""
    if v0 is not None:
        from ...discrete.lagrangian_action import start_momentum

        p0 = start_momentum(system, scheme, q0, v0, t0=t0, tau0=tau0, theta=theta)
        if not np.all(np.isfinite(p0)):
            raise InputError(f"p0 from v0 = {v0.tolist()} is not finite: {p0.tolist()}")
    H0 = float(system.energy(q0[None, :], p0[None, :], np.array([t0]), theta)[0])
    if not math.isfinite(H0):
        raise InputError(f"H is not finite at the initial state q0={q0.tolist()}, "
                         f"p0={p0.tolist()}, t0={t0!r}: H = {H0!r}")
    return p0, H0
