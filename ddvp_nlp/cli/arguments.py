"""The command line's options as the solvers' option objects: one place where ``--tol``,
``--max-steps``, ``--careful`` ... become a `StepControl`, a `Tolerance`, a
`GridOptions`, a `Compilation` or an `Output`, for every command that has
them. A bad value fails here, with the object's own message naming the field."""

from __future__ import annotations

import contextlib
import dataclasses
import inspect
from typing import TYPE_CHECKING

from ..discrete import Scheme
from ..errors import InputError
from ..scenes import PeriodicSettings
from ..solvers import Compilation, GridOptions, Output, StepControl, Tolerance
from .flags import flags

if TYPE_CHECKING:  # the task runner loads with the commands that run tasks, not with a march
    from ..runner.tasks import Workers


def _field(kind, name: str):
    """The default of field ``name`` of the option object ``kind`` (a frozen dataclass)."""
    return {f.name: f.default for f in dataclasses.fields(kind)}[name]


def _argument(function, name: str):
    """The default of keyword argument ``name`` of ``function``."""
    return inspect.signature(function).parameters[name].default


# Every command-line option that stands for a field of an option object or an argument of the
# API, by command: the parser takes each default from here, so that a default exists once (the
# API's); tests/workbench/cli/test_usage.py checks that every option with a default is here or
# is the command line's own (CLI_ONLY).
API_DEFAULTS = {
    "march": {"tol": lambda: _field(StepControl, "tol"),
              "tau_min": lambda: _field(StepControl, "tau_min"),
              "tau_max": lambda: _field(StepControl, "tau_max"),
              "max_step_ratio": lambda: _field(StepControl, "max_step_ratio"),
              "max_steps": lambda: _field(StepControl, "max_steps"),
              "time_limit": lambda: _field(StepControl, "time_limit"),
              "energy_guard": lambda: _field(StepControl, "energy_guard"),
              "alpha": lambda: _field(Scheme, "alpha"),
              "clock": lambda: _field(Scheme, "clock"),
              "checkpoint_every": lambda: _field(Output, "checkpoint_interval"),
              "keep": lambda: _field(Output, "keep"),
              "target_error": lambda: _argument(_solvers().march, "target_error")},
    "bvp": {"tol": lambda: _field(GridOptions, "tol"),
            "solver": lambda: _field(GridOptions, "solver"),
            "time_limit": lambda: _field(GridOptions, "time_limit"),
            "alpha": lambda: _field(Scheme, "alpha"),
            "clock": lambda: _field(Scheme, "clock")},
    "periodic": {"solver": lambda: _field(GridOptions, "solver"),
                 "scheme": lambda: _argument(_solvers().solve_periodic, "scheme"),
                 "stability_tol": lambda: _field(_solvers().Continuation, "tol"),
                 "max_orbits": lambda: _field(_solvers().Continuation, "max_orbits"),
                 "seeds": lambda: _argument(_solvers().find_periodic_orbits, "seeds"),
                 "max_returns": lambda: _argument(_solvers().find_periodic_orbits,
                                                  "max_returns"),
                 "reversing": lambda: _argument(_solvers().find_periodic_orbits, "reversing"),
                 "workers": lambda: _argument(_solvers().find_periodic_orbits, "workers"),
                 "switch_tol": lambda: _field(_solvers().Switch, "tol")},
    "poincare": {"workers": lambda: _argument(_solvers().march_ensemble, "workers"),
                 "orbits": lambda: _argument(_poincare_section(), "orbits"),
                 "section": lambda: _argument(_poincare_section(), "section"),
                 "direction": lambda: _argument(_poincare_section(), "direction"),
                 "t_end": lambda: _argument(_poincare_section(), "t_end"),
                 "seed": lambda: _argument(_poincare_section(), "seed")},
    "chaos": {"workers": lambda: _argument(_chaos_map(), "workers"),
              "section": lambda: _argument(_chaos_map(), "section"),
              "t_end": lambda: _argument(_chaos_map(), "t_end")},
    "compare": {"halvings": lambda: _field(_compare_options(), "halvings"),
                "repeats": lambda: _field(_compare_options(), "repeats"),
                "max_steps": lambda: _field(_compare_options(), "max_steps"),
                "time_unit": lambda: _argument(_horizons(), "unit"),
                "run_budget": lambda: _argument(_horizons(), "run_budget_s"),
                "reference_span": lambda: _argument(_horizons(), "reference_span")},
    "stress": {"max_steps": lambda: _stress_steps().max_steps,
               "time_limit": lambda: _stress_steps().time_limit},
    "accuracy": {"rtol": lambda: _field(Tolerance, "rtol"),
                 "atol": lambda: _field(Tolerance, "atol"),
                 "energy_tol": lambda: _field(Tolerance, "energy_tol"),
                 "global_tol": lambda: _field(Tolerance, "global_tol")},
}


# The defaults of a command are read when its parser is built (only the running command's is):
# the modules behind them load then, not with the command line.
def _solvers():
    from .. import solvers

    return solvers


def _poincare_section():
    from ..studies.poincare import poincare_section

    return poincare_section


def _chaos_map():
    from ..studies.chaos_map import chaos_map

    return chaos_map


def _compare_options():
    from ..studies.work_precision import CompareOptions

    return CompareOptions


def _horizons():
    from ..studies.horizons_report import work_precision_horizons

    return work_precision_horizons


def _stress_steps():
    from ..studies.stress import DEFAULT_STEPS

    return DEFAULT_STEPS


def api_default(command: str, dest: str):
    """The API's default of option ``dest`` of ``command`` (`API_DEFAULTS`)."""
    return API_DEFAULTS[command][dest]()


def periodic_nodes() -> int:
    """A periodic orbit's nodes when neither the command line nor the scene gives them."""
    return _field(PeriodicSettings, "nodes")


def step_control(args) -> StepControl:
    """``ddvp march``'s step acceptance and limits."""
    return StepControl(tol=args.tol, tau_min=args.tau_min, tau_max=args.tau_max,
                       max_step_ratio=args.max_step_ratio,
                       breakdown="least_squares" if args.least_squares else "stop",
                       max_steps=args.max_steps, time_limit=args.time_limit,
                       energy_guard=args.energy_guard)


def tolerance(args, exact=None) -> Tolerance:
    """The accuracy check's tolerances (``--rtol``, ``--atol``, ``--energy-tol``,
    ``--global-tol``, ``--require-accurate``, ``--accept-inaccurate``) and the motion's
    ``exact`` states, if known."""
    return Tolerance(rtol=args.rtol, atol=args.atol, energy_tol=args.energy_tol,
                     global_tol=args.global_tol, require_accurate=args.require_accurate,
                     stop=not args.accept_inaccurate, exact=exact)


def compilation(args) -> Compilation:
    """``--careful`` turns the compiled chunks off (the march's careful per-step path)."""
    return Compilation(fast=not args.careful)


def grid_options(args) -> GridOptions:
    """A grid solve's options (``--solver``, ``--tol``, ``--time-limit``, ``--verbose``; the
    object's defaults where a command has none, ``request.ABSENT``) and the accuracy check's
    (`tolerance`)."""
    return GridOptions(solver=args.solver, tol=args.tol, time_limit=args.time_limit,
                       verbose=args.verbose, accuracy=tolerance(args))


def march_output(args, *, checkpoint=None, stop=None, t_eval=None, events=None) -> Output:
    """A march's progress (on unless ``--no-progress``), checkpoints, stop request, output
    times and events (``cli/events.py``)."""
    keep_every = 1 if args.keep_every is None else args.keep_every
    thinned = keep_every > 1 or args.keep != "nodes"
    return Output(progress=args.progress is not False,
                  checkpoint=None if thinned else checkpoint,
                  checkpoint_interval=args.checkpoint_every, stop=stop, t_eval=t_eval,
                  events=events or None, keep_every=keep_every, keep=args.keep)


def compiled_or_not(args) -> Compilation:
    """``--no-compile``: CasADi's virtual machine instead of gcc."""
    return Compilation(compiler=None if args.no_compile else "auto")


@contextlib.contextmanager
def on_cluster(args):
    """The request the command runs: with ``--cluster SPEC|FILE``, the description checked,
    the cluster started for the command (``runner/cluster.py``) and its scheduler's address the
    new request's ``scheduler``, where the grids and the Poincare ensemble already send their
    tasks; closed at the end. Without it, ``args`` as it is."""
    text = args.cluster
    if text is None:
        yield args
        return
    from ..runner.cluster import check_available, parse_cluster, start_cluster

    if args.scheduler is not None:
        raise InputError("give --cluster (a cluster started for this run) or --scheduler (one "
                         "that runs already), not both")
    spec = parse_cluster(text)
    check_available(spec)
    with start_cluster(spec) as cluster:
        yield args.but(scheduler=cluster.scheduler_address)


def workers(args, *, default: int | None = 1) -> Workers:
    """``--workers`` and ``--scheduler`` (``default``: the count when ``--workers`` is not
    given)."""
    from ..runner.tasks import Workers

    return Workers(count=args.workers if args.workers is not None else default,
                   scheduler=args.scheduler)


# The numbers of the command line that stand for no field of an option object (the sizes,
# counts, seeds and times of a run, by option name): what each must be. "positive": a finite
# number > 0; "finite": any finite number; "count": an integer >= 1; "natural": an integer
# >= 0. Every other number is a field of an option object, checked by the object
# (`check_options`).
NUMBERS = {
    "nodes": "count", "energy": "finite", "orbits": "count", "t_end": "finite",
    "tau0": "positive", "seed": "natural", "time_unit": "positive",
    "run_budget": "positive", "reference_span": "positive",
}
# The least --nodes each command's grid takes (the solvers' own rule, said with the flag: `--nodes
# -5` had read "a positive integer" where `--nodes 1` read "an integer >= 3"); a higher-order
# scene's larger least is its solver's to say.
LEAST_NODES = {"bvp": 3, "periodic": 4}
# Seeds numpy takes: below 2**63 (a larger one was taken, and a negative one a traceback).
MAX_SEED = 2**63 - 1


def check_options(request) -> None:
    """Every number the command has, checked before anything is loaded: its option objects
    made (each checks its own fields; their messages said with the flags, ``cli/flags.py``),
    then the command line's own numbers (`NUMBERS`) and lists (``--time-limit nan`` and
    ``--alpha 0`` had passed)."""
    for owner, make in OPTION_OBJECTS.get(request.command, ()):
        with flags(owner):
            make(request)
    _check_numbers(request)
    _check_lists(request)


def _given(request, names) -> dict:
    """The options among ``names`` the command has and that are given (not ``None``)."""
    return {name: value for name, value in request.having(names).items() if value is not None}


def _comparison(request):
    from ..studies.work_precision import CompareOptions
    return CompareOptions(halvings=request.halvings, repeats=request.repeats,
                          max_steps=request.max_steps,
                          target_errors=target_errors(request.target_errors))


def _continuation(request):
    from ..solvers import Continuation

    return Continuation(step=request.step, tol=request.stability_tol,
                        max_orbits=request.max_orbits)


def _bounds(request) -> StepControl:
    """The per-run bounds of a grid of runs (``None``: the grid file's)."""
    return StepControl(**_given(request, ("max_steps", "time_limit")))


def _workers(request) -> None:
    """``--workers``: a count the runner's `Workers` takes (and whose processes fit in
    memory); ``None``, the command's own default."""
    from ..runner.tasks import Workers

    if request.workers is not None:
        Workers(count=request.workers)


def _march_output(request) -> Output:
    """The fields of a march's `Output` the command line gives as numbers."""
    return Output(checkpoint_interval=request.checkpoint_every,
                  keep_every=1 if request.keep_every is None else request.keep_every)


# The option objects each command's numbers stand for: (the object whose fields the messages
# name, how it is made from the request).
OPTION_OBJECTS = {
    "march": ((None, step_control), (None, tolerance), (None, _march_output),
              (None, lambda request: Scheme(alpha=request.alpha))),
    "bvp": ((None, grid_options), (None, lambda request: Scheme(alpha=request.alpha))),
    "periodic": ((None, grid_options), ("Continuation", _continuation)),
    "poincare": ((None, tolerance), (None, _workers)),
    "chaos": ((None, _workers),),
    "compare": ((None, _comparison), (None, _workers)),
    "stress": ((None, _bounds), (None, _workers)),
    "sweep": ((None, _bounds), (None, _workers)),
    "reproduce": ((None, _workers),),
}


def _check_numbers(request) -> None:
    from ..validation import check_integer, check_real

    for dest, value in _given(request, NUMBERS).items():
        rule, flag = NUMBERS[dest], "--" + dest.replace("_", "-")
        if rule in ("count", "natural"):
            least = LEAST_NODES.get(request.command, 1) if dest == "nodes" else 1
            check_integer(flag, value, minimum=least if rule == "count" else 0,
                          maximum=MAX_SEED if dest == "seed" else None)
        else:
            check_real(flag, value, positive=rule == "positive")


def _check_lists(args) -> None:
    """``--methods``, ``--section`` and ``--horizons``: not empty, no repeats."""
    from ..errors import InputError

    methods = args.methods
    if methods is not None:
        names = [name.strip() for name in methods.split(",")]
        if not any(names) or "" in names:
            raise InputError(f"--methods must be comma-separated method names, got "
                             f"{methods!r}")
        repeated = sorted({name for name in names if names.count(name) > 1})
        if repeated:
            raise InputError(f"--methods names {repeated[0]!r} twice")
    section = args.section
    if section is not None and (not section.strip() or "=" not in section):
        raise InputError(f"--section must be NAME=VALUE (e.g. q1=0), got {section!r}")
    horizons = args.horizons
    if horizons is not None:
        check_values("--horizons", horizons, positive=True)


def target_errors(text: str | None) -> list[float] | None:
    """``--target-errors E1,E2,...`` as numbers (`CompareOptions` checks them)."""
    if text is None:
        return None
    try:
        errors = [float(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise InputError(f"--target-errors expects numbers separated by commas, got {text!r}") \
            from None
    return errors


def check_values(flag: str, text: str, *, positive: bool = False) -> list[float]:
    """Comma-separated finite numbers, none repeated (``positive``: all > 0)."""
    from ..errors import InputError
    from ..validation import check_real

    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"{flag} must be comma-separated numbers, got {text!r}") from None
    for value in values:
        check_real(flag, value, positive=positive)
    check_distinct(flag, values)
    return values


def check_distinct(flag: str, values) -> None:
    """No value twice (a repeated grid value ran the same runs twice and one row hid the
    other)."""
    from ..errors import InputError

    seen = set()
    for value in values:
        if value in seen:
            raise InputError(f"{flag} has the value {value!r} twice; give each value once")
        seen.add(value)


def check_grid_memory(flag: str, nodes: int, n: int, members: int) -> None:
    """The nodes of a grid solve (and ``members`` kept solutions) against the memory."""
    from ..validation import check_memory

    check_memory(flag, nodes, 48.0 * nodes * (2 * n + 2) ** 2 + members * 64.0 * nodes * n,
                 "the grid's Jacobian and the kept orbits")


def family_energies(text: str, n: int = 1, nodes: int = 200):
    """``E1:E2:COUNT`` as ``COUNT`` distinct energies from ``E1`` to ``E2``, the family's
    orbits checked against the memory before any is solved."""
    import numpy as np

    from ..validation import check_integer, check_memory

    parts = text.split(":")
    try:
        if len(parts) != 3:
            raise ValueError
        first, last, count = float(parts[0]), float(parts[1]), int(parts[2])
    except (ValueError, IndexError, OverflowError):
        raise InputError(f"--family must be E1:E2:COUNT, got {text!r}") from None
    if not np.isfinite(first) or not np.isfinite(last):
        raise InputError(f"--family needs finite E1 and E2, got {text!r}")
    check_integer("--family COUNT", count, minimum=2)
    if first == last:
        raise InputError(f"--family needs E1 != E2, got {text!r}")
    check_memory("--family COUNT", count, count * (64.0 * (nodes + 1) * (2 * n + 2) + 4096),
                 "the family's orbits")
    check_grid_memory("--nodes", nodes, n, count)
    energies = np.linspace(first, last, count)
    if np.unique(energies).size != count:
        raise InputError(f"--family {text!r}: {count} energies from {first!r} to {last!r} are "
                         "not all distinct in floating point")
    return energies
