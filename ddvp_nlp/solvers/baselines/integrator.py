"""What an integrator declares about itself, beside its implementation, for the studies to read.

An `Integrator` is one method of the comparison: its traits (stated once, here and
nowhere else) and ``run``, which turns ``(system, run configuration, knob value)`` into a
`Solution`. The knob is what a user turns for accuracy: the first step
``tau0`` of the energy-determined schemes, the step ``tau`` of fixed-step ones, a tolerance
``rtol``. The run configuration is read by attribute only (``q0``, ``p0``, ``t0``, ``t_end``,
``params``: a ``scenes.RunConfig``), so this layer needs no import of the scenes.

Each implementation module declares its integrators as module constants; the registry
(``INTEGRATORS`` in ``solvers/baselines/__init__.py``) lists them, one line each.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields

from ...solution import Solution
from ..marching.backward import run_time_reversed


def no_reason(system) -> None:
    """The default of ``applies`` and ``redundant``: applies to every system, repeats no other
    method."""
    return None


@dataclass(frozen=True)
class Integrator:
    """One integrator of the comparison.

    Attributes:
        name: key used on the command line and in the CSV.
        description: one line for reports.
        order: order of accuracy.
        symplectic, energy_conserving: traits.
        knob: the accuracy setting swept (``"tau0"``, ``"tau"`` or ``"rtol"``).
        run: ``run(system, config, value, *, compiler, cache_dir, max_steps, time_limit=None)
            -> Solution``.
        applies: ``applies(system) -> None`` or the reason the method does not apply.
        redundant: ``redundant(system) -> None`` or why, on this system, the method repeats
            another one exactly (left out of default comparisons, run when asked for by name).
        aims: ``run`` also takes ``target_error=E`` and chooses its own knob for a trajectory
            error ``E`` (the march's ``target_error``); a comparison at target errors runs it
            once per target.
        limitation: where the method cannot run at all, in words (empty if nowhere known): a
            report says it beside the method's failed runs.
        reverses_itself: ``run`` marches backwards in time itself when ``t_end < t0`` (the
            paper's schemes: the march does). Otherwise ``run`` is given a backward run as
            the forward run of the time-reversed system, mapped back
            (``marching/backward.run_time_reversed``), so every method runs either way.
        constrained_only: a method of systems with holonomic constraints (RATTLE, SHAKE):
            a default comparison of a system without constraints leaves it out without a
            word, as it leaves out what the scene does not need.
        constrained: ``run`` marches a system with holonomic constraints on ``g = 0`` (the
            paper's schemes, RATTLE, SHAKE). A method without it refuses such a system by
            its ``applies``, with the reason (`knows_no_constraints`): it would march the
            motion without the constraint forces, off ``g = 0``.
    """

    name: str
    description: str
    order: int
    symplectic: bool
    energy_conserving: bool
    knob: str
    run: Callable[..., Solution]
    applies: Callable[[object], str | None] = no_reason
    redundant: Callable[[object], str | None] = no_reason
    aims: bool = False
    limitation: str = ""
    reverses_itself: bool = False
    constrained_only: bool = False
    constrained: bool = False

    def __post_init__(self):
        if not (self.reverses_itself or getattr(self.run, "either_way", False)):
            object.__setattr__(self, "run", _either_way(self.run))
        if not (self.constrained or getattr(self.applies, "knows_constraints", False)):
            object.__setattr__(self, "applies", _refusing_constraints(self.applies))

    def traits(self) -> dict:
        """Every field by name (to build a richer view of the same integrator)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


KNOWS_NO_CONSTRAINTS = "it does not know holonomic constraints (it would leave g = 0)"


def knows_no_constraints(system) -> str | None:
    """Why a method without constraints does not apply to ``system`` (it has some), or
    ``None``."""
    return KNOWS_NO_CONSTRAINTS if getattr(system, "n_constraints", 0) else None


def _refusing_constraints(applies):
    """``applies`` of a method without constraints: a constrained system refused first."""
    def refusing(system):
        return knows_no_constraints(system) or applies(system)
    refusing.__wrapped__, refusing.knows_constraints = applies, True
    return refusing


def _either_way(run):
    """``run`` forwards as it is, backwards (``t_end < t0``) by time reversal."""
    def either_way(system, config, value, **options):
        if float(config.t_end) < float(config.t0):
            return run_time_reversed(run, system, config, value, **options)
        return run(system, config, value, **options)
    either_way.__wrapped__, either_way.either_way = run, True
    return either_way
