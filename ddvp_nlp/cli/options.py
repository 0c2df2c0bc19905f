"""The command line's options as the solvers' option objects: one place where ``--tol``,
``--max-steps``, ``--careful`` ... become a :class:`StepControl`, a :class:`Tolerance`, a
:class:`GridOptions`, a :class:`Compilation` or an :class:`Output`, for every command that has
them. A bad value fails here, with the object's own message naming the field."""

from __future__ import annotations

from ..solvers.options import Compilation, GridOptions, Output, StepControl, Tolerance
from ..studies.grid import Workers


def step_control(args) -> StepControl:
    """``ddvp march``'s step acceptance and limits."""
    return StepControl(tol=args.tol, tau_min=args.tau_min, tau_max=args.tau_max,
                       max_step_ratio=args.max_step_ratio,
                       breakdown="least_squares" if args.least_squares else "stop",
                       max_steps=args.max_steps, time_limit=args.time_limit,
                       energy_guard=args.energy_guard)


def tolerance(args, exact=None) -> Tolerance:
    """The accuracy check's tolerances (``--rtol``, ``--atol``, ``--energy-tol``,
    ``--global-tol``, ``--require-accurate``, ``--accept-inaccurate``; their defaults where a
    command has none) and the motion's ``exact`` states, if known."""
    defaults = Tolerance()
    return Tolerance(rtol=getattr(args, "rtol", defaults.rtol),
                     atol=getattr(args, "atol", defaults.atol),
                     energy_tol=getattr(args, "energy_tol", defaults.energy_tol),
                     global_tol=getattr(args, "global_tol", defaults.global_tol),
                     require_accurate=getattr(args, "require_accurate", False),
                     stop=not getattr(args, "accept_inaccurate", False), exact=exact)


def compilation(args) -> Compilation:
    """``--careful`` turns the compiled chunks off (the march's careful per-step path)."""
    return Compilation(fast=not getattr(args, "careful", False))


def grid_options(args, *, tol=None) -> GridOptions:
    """A grid solve's options (``--solver``, ``--tol``, ``--time-limit``, ``--verbose``)."""
    return GridOptions(solver=args.solver, tol=tol,
                       time_limit=getattr(args, "time_limit", None),
                       verbose=getattr(args, "verbose", False), accuracy=tolerance(args))


def march_output(args, *, checkpoint=None, stop=None) -> Output:
    """A march's progress bar (off with ``--no-progress``), checkpoints and stop request."""
    return Output(progress=not args.no_progress, checkpoint=checkpoint,
                  checkpoint_interval=args.checkpoint_every, stop=stop)


def compiled_or_not(args) -> Compilation:
    """``--no-compile``: CasADi's virtual machine instead of gcc."""
    return Compilation(compiler=None if args.no_compile else "auto")


def workers(args, *, default: int | None = 1) -> Workers:
    """``--workers`` and ``--scheduler`` (``default``: the count when ``--workers`` is not
    given)."""
    return Workers(count=args.workers if args.workers is not None else default,
                   scheduler=args.scheduler)
