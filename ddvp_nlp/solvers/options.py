"""The options of the solvers, as small objects a caller builds once and passes by name.

Every public solver takes its essential arguments (the system, the start or the ends, the time
span, the grid) and then at most a few of these:

- `StepControl`: when a march accepts a step and when it stops (``march``,
  ``march_ensemble``);
- `Tolerance`: what the accuracy check, which does not trust the scheme's own equations,
  accepts (``march``, ``march_ensemble``; the grid solvers use its defaults);
- `GridOptions`: how a whole-grid problem is solved (``solve_bvp``, ``solve_periodic``,
  ``solve_periodic_family``, ``solve_bvp_higher``);
- `Compilation`: which compiled code runs (every solver that generates C);
- `Output`: progress, checkpoints and stop requests (``march``, ``solve_bvp``).

`ExactTolerance` (``EXACT_TOLERANCE``) is no user's option but the library's one tolerance
policy of the exact flow, kept here where every family may read it.

Each object checks its fields when it is made: a bad value is an `InputError` that names
the field and the value, raised before any solver is built. Checks that need the problem (a
``tau_min`` against ``tau0``, a ``tau_floor`` against the mean step) are made by the solver,
still before it builds anything. The objects are frozen: ``dataclasses.replace(options,
tol=1e-12)`` makes a changed copy.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError
from ..validation import check_cache_folder, check_integer, check_real

# What a march does when an energy step has no admissible root (StepControl.breakdown).
CONSTRAINT_METHODS = ("multipliers", "null_space")
BREAKDOWNS = ("stop", "least_squares")
# Steps per compiled call: past this the chunk's generated code and its output buffer grow to
# gigabytes (chunk = 10**9 took two minutes and 4.7 GB for a ten-step march) for no speed gained.
MAX_CHUNK = 65536
GRID_SOLVERS = ("auto", "newton", "ipopt")
# Shortest time between two checkpoints of a march (seconds): each one writes every node so far.
MIN_CHECKPOINT_INTERVAL = 0.01
# What a march keeps (Output.keep): its nodes (every keep_every-th), or only the t_eval states
# and the events (with the first and the last node).
KEEPS = ("nodes", "t_eval")
LINEAR_SOLVERS = ("auto", "banded", "sparse")
BAND_LU = ("compiled", "lapack")


def _set(options, name, value):
    object.__setattr__(options, name, value)


def _flag(name: str, value) -> bool:
    """A field that is on or off: ``True``/``False`` (``np.bool_`` too), nothing else (a string
    such as ``"no"`` is truthy and would turn it on)."""
    if not isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def _choice(name: str, value, choices) -> str:
    if value not in choices:
        raise InputError(f"unknown {name} {value!r} (choose from {', '.join(choices)})")
    return value


@dataclass(frozen=True)
class StepControl:
    """When a march accepts a step, and when the march stops.

    Attributes:
        tol: acceptance tolerance of each step's unscaled residuals, relative to
            ``max(|z_k|, Z)`` (canonical equations) and ``max(|H_k|, E)`` (energy equation),
            ``Z`` and ``E`` the run's scales from its start (``marching/acceptance.py``: the
            start's size and first motion, how much ``H`` changes over it; no floor of 1).
        tau_min, tau_max: optional bounds on every step length.
        max_step_ratio: bound on ``max(tau_k/tau_{k-1}, tau_{k-1}/tau_k)`` (``None``: none).
            The default 10 stops a march whose energy equation jumped to a far root: on
            ``kepler`` with ``e = 0.99`` and ``tau0 = 0.01``, without it, the fourth step was
            235 time units, past the whole horizon, and every equation held.
        breakdown: what an energy rule does when a step has no admissible root: ``"stop"``
            (status ``no_admissible_step``) or ``"least_squares"``, the step of Kane, Marsden
            and Ortiz (the ``tau`` that minimises the energy residual subject to the canonical
            equations; each such step is listed in ``march.least_squares``).
        max_steps: bound on the number of steps (status ``max_steps``).
        time_limit: optional bound in seconds on the stepping (status ``time_limit``).
        energy_guard: optional bound on ``|H(z_k, t_k) - H(z_0, t_0)| / max(|H(z_0, t_0)|, E)``
            at every node (status ``energy_guard``), ``E`` the motion's energy scale at the
            start (how much ``H`` changes when the state moves by its own size).
        constraint_method: how a system with constraints solves its steps: ``"multipliers"``
            (the RATTLE-form rows with their multipliers) or ``"null_space"`` (the same
            equations with the multipliers eliminated by a null-space matrix of the
            constraints' Jacobian, ``fixed`` and ``vddvp``; docs/constraints.md). Read only
            for systems with constraints.
    """

    tol: float = 1e-10
    tau_min: float | None = None
    tau_max: float | None = None
    max_step_ratio: float | None = 10.0
    breakdown: str = "stop"
    max_steps: int = 10_000_000
    time_limit: float | None = None
    energy_guard: float | None = None
    constraint_method: str = "multipliers"

    def __post_init__(self):
        _set(self, "tol", check_real("tol", self.tol, positive=True))
        _set(self, "max_steps", check_integer("max_steps", self.max_steps))
        tau_min = check_real("tau_min", self.tau_min, positive=True, allow_none=True)
        tau_max = check_real("tau_max", self.tau_max, positive=True, allow_none=True)
        if tau_min is not None and tau_max is not None and tau_min >= tau_max:
            raise InputError(f"tau_min must be < tau_max = {tau_max!r}, got {tau_min!r}")
        _set(self, "tau_min", tau_min)
        _set(self, "tau_max", tau_max)
        ratio = check_real("max_step_ratio", self.max_step_ratio, positive=True,
                           allow_none=True)
        if ratio is not None and ratio <= 1:
            raise InputError(f"max_step_ratio must be > 1, got {ratio!r}")
        _set(self, "max_step_ratio", ratio)
        _set(self, "time_limit", check_real("time_limit", self.time_limit, positive=True,
                                            allow_none=True))
        _set(self, "energy_guard", check_real("energy_guard", self.energy_guard, positive=True,
                                              allow_none=True))
        if self.breakdown not in BREAKDOWNS:
            raise InputError(f"breakdown must be one of {', '.join(BREAKDOWNS)}, got "
                             f"{self.breakdown!r}")
        if self.constraint_method not in CONSTRAINT_METHODS:
            raise InputError(f"constraint_method must be one of {', '.join(CONSTRAINT_METHODS)}"
                             f", got {self.constraint_method!r}")


@dataclass(frozen=True)
class Tolerance:
    """What the accuracy check accepts (``accuracy/judgement.py``). Every figure is relative to the
    motion's own scales: ``S_i``, the range of component ``i`` of ``z = (q, p)`` over the run,
    and the energy scale ``E_s`` (how much ``H`` changes over ``S``); none to 1.

    Attributes:
        rtol: the local error test of every step, ``|d_k,i| <= rtol S_i (+ atol)``.
        atol: optional absolute allowance added to that bound, in the units of ``z`` (default
            none: a fixed allowance would make the verdict depend on the units).
        energy_tol: bound on the first step's energy level error and on the nodal energy
            drift, relative to ``E_s``.
        global_tol: the trajectory tolerance: ``max_i |z_k,i - z_ref,i(t_k)| / S_i`` at every
            node, against the exact flow from ``z_0``; past it a run is ``drifted``.
        require_accurate: a ``drifted`` run ends with status ``drifted`` (a failure; the
            command line exits 1) instead of keeping its success.
        stop: an ``inaccurate`` run ends with status ``inaccurate``; ``False`` records the
            verdict and keeps the run's own status.
        exact: optional exact motion of the run, ``exact(t) -> z`` of shape ``(N, 2n)``, used
            instead of the reference flow (the command line gives the scene's exact solution).
    """

    rtol: float = 1e-2
    atol: float | None = None
    energy_tol: float = 0.1
    global_tol: float = 1e-2
    require_accurate: bool = False
    stop: bool = True
    exact: Callable | None = None

    def __post_init__(self):
        for name in ("rtol", "energy_tol", "global_tol"):
            _set(self, name, check_real(name, getattr(self, name), positive=True))
        _set(self, "atol", check_real("atol", self.atol, positive=True, allow_none=True))
        for name in ("require_accurate", "stop"):
            _set(self, name, _flag(name, getattr(self, name)))
        if self.exact is not None and not callable(self.exact):
            raise InputError(f"exact must be a callable exact(t) -> z, got {self.exact!r}")


# The default of every ``accuracy=``: the check with its default tolerances. ``accuracy=None``
# has one meaning wherever it is taken: no check (`march`, `continue_march`, `march_ensemble`,
# `march_higher`); a grid solution is always checked, so `GridOptions` refuses it.
DEFAULT_TOLERANCE = Tolerance()


@dataclass(frozen=True)
class ExactTolerance:
    """The exact flow's one tolerance policy (not a user's option: how tightly the library
    integrates the flow its verdicts are measured against, and how closely the Newton on that
    flow, ``exact/flow_newton.py``, solves its equations). Every module that runs the exact
    flow for a solve or a verdict reads it here, named for what each number is for, so the
    policy is changed once; it lives in the core because ``marching/`` reads it too and may not
    import ``exact/`` (``exact/tolerance.py`` re-exports it).

    Attributes:
        flow_rtol: the flow's relative tolerance inside a Newton on it (shooting, closure,
            transfer, fit), for the level of a verdict and wherever a trajectory is measured
            against the flow at one fixed tolerance (the pilot of ``march(target_error=E)``):
            its error is then far below the Newton's own ``newton_tol`` of the motion's size.
        reference_rtol: the first tolerance of a reference trajectory that states its own
            error (tightened by 100 while it must be).
        newton_tol: the residual, relative to the motion's size, a Newton on the exact flow
            stops at (continuity, end positions, closure, fit).
        newton_tight_tol: where the exact transfer at an energy stops (its residual relative
            to the scales of the end positions and of the energy): a tenth of ``newton_tol``.
        newton_accept_tol: the residual at which the exact transfer is still accepted when
            its iterations run out before ``newton_tight_tol``: ten times ``newton_tol``.
    """

    flow_rtol: float = 1e-12
    reference_rtol: float = 1e-9
    newton_tol: float = 1e-10
    newton_tight_tol: float = 1e-11
    newton_accept_tol: float = 1e-9


EXACT_TOLERANCE = ExactTolerance()


@dataclass(frozen=True)
class GridOptions:
    """How a whole-grid problem (fixed ends, a periodic orbit, a higher-order problem) is
    solved. ``None`` takes the solver's own default, given in its docstring.

    Attributes:
        solver: ``"newton"`` (the grid's Newton, ``grid/newton.py``), ``"ipopt"`` (the grid's
            IPOPT build, ``grid/ipopt.py``) or ``"auto"``: Newton, then IPOPT from the same
            start when Newton's point fails its verification.
        tol: verification tolerance of the returned point's own unscaled residuals (above
            their round-off, which is always allowed). For fixed ends and periodic orbits it is
            relative to the motion's size in each row's units
            (``bvp/fixed_ends.verification_limits``, ``periodic/closed_grid.closed_limits``);
            the other grid families (families of orbits, constrained orbits, higher order)
            still read it in the rows' own units.
        max_iter: iteration limit of the solver, per phase (``None``: the family's own,
            given in its docstring).
        tau_floor: smallest step the iterates may take (energy rules).
        linear: Newton's linear solver: ``"auto"`` (banded LU up to bandwidth 32, else
            sparse), ``"banded"`` or ``"sparse"`` (SuperLU).
        time_limit: seconds after which the solve stops (status ``time_limit``).
        verbose: IPOPT's iteration log on stdout.
        accuracy: the accuracy check of the solution (`Tolerance`, default
            ``DEFAULT_TOLERANCE``, the defaults). A grid solution is always checked, so
            ``None`` (no check, as for `march`) is refused.
    """

    solver: str = "auto"
    tol: float = 1e-10
    max_iter: int | None = None
    tau_floor: float | None = None
    linear: str = "auto"
    time_limit: float | None = None
    verbose: bool = False
    accuracy: Tolerance = DEFAULT_TOLERANCE

    def __post_init__(self):
        _choice("solver", self.solver, GRID_SOLVERS)
        _choice("linear", self.linear, LINEAR_SOLVERS)
        _set(self, "tol", check_real("tol", self.tol, positive=True))
        if self.max_iter is not None:
            _set(self, "max_iter", check_integer("max_iter", self.max_iter))
        _set(self, "tau_floor", check_real("tau_floor", self.tau_floor, positive=True,
                                           allow_none=True))
        _set(self, "time_limit", check_real("time_limit", self.time_limit, positive=True,
                                            allow_none=True))
        _set(self, "verbose", _flag("verbose", self.verbose))
        if self.accuracy is None:
            raise InputError("accuracy=None means no check, and a grid solution is always "
                             "checked: give a Tolerance (default Tolerance())")
        _set(self, "accuracy", coerce(self.accuracy, Tolerance, "accuracy"))

    def resolved(self, *, max_iter: int) -> GridOptions:
        """These options with a family's iteration limit in place of ``None``."""
        return replace(self, max_iter=max_iter if self.max_iter is None else self.max_iter)


@dataclass(frozen=True)
class Compilation:
    """Which compiled code a solver runs.

    Attributes:
        compiler: C compiler for generated code: ``"auto"`` (``$CC``, ``gcc``, ``cc``), a
            command, or ``None`` for CasADi's virtual machine (the same functions, slower).
        cache_dir: folder of compiled libraries (default ``$DDVP_NLP_CACHE`` or
            ``~/.cache/ddvp_nlp``).
        fast: a march runs its steps in compiled chunks (``marching/chunk.py``); ``False`` forces
            the careful per-step path. Both accept a step by the same test; their nodes differ
            by round-off (the compiled Newton eliminates where the careful one factors by QR).
        chunk: steps per compiled call of a march.
        batch: most chunk calls a march makes and checks at once (1, 2, 4, ... up to this
            while every step is kept): the same nodes as one call at a time, with the decoding
            and the monitors paid once per batch.
        threads: threads of each mapped evaluation of the fixed-endpoint IPOPT build's
            residual and Hessian blocks (1: two were not faster on two cores, measured).
        band_lu: the grid's banded LU: ``"compiled"`` (LAPACK's loops compiled with
            ``compiler``, ``grid/band.py``; LAPACK through scipy where there is no compiler)
            or ``"lapack"`` (through scipy).
    """

    compiler: str | None = "auto"
    cache_dir: object = None
    fast: bool = True
    chunk: int = 1024
    batch: int = 8
    threads: int = 1
    band_lu: str = "compiled"

    def __post_init__(self):
        if self.compiler is not None and (not isinstance(self.compiler, str)
                                          or not self.compiler.strip()):
            raise InputError(f"compiler must be 'auto', a command or None, got "
                             f"{self.compiler!r}")
        check_cache_folder(self.cache_dir)
        _set(self, "fast", _flag("fast", self.fast))
        _set(self, "chunk", check_integer("chunk", self.chunk, maximum=MAX_CHUNK))
        _set(self, "batch", check_integer("batch", self.batch))
        _set(self, "threads", check_integer("threads", self.threads))
        _choice("band_lu", self.band_lu, BAND_LU)


@dataclass(frozen=True)
class Output:
    """What a solver reports while it runs, and how it can be stopped.

    Attributes:
        progress: a progress bar (march) or a line per iteration (grid solvers) on stderr; a
            grid solve's IPOPT also writes its iteration log, on stdout.
        checkpoint: optional ``save(t, z)``, called with the nodes kept so far every
            ``checkpoint_interval`` seconds of a march's stepping (at most about 5% of it), so
            that a killed march loses at most one interval.
        checkpoint_interval: seconds between checkpoints.
        stop: optional ``stop() -> bool``, asked after every stepper call; ``True`` ends the
            march with status ``interrupted``, every accepted node kept (how the command line
            turns Ctrl-C and SIGTERM into a clean end, never an exception inside CasADi).
        t_eval: times (sorted, inside ``t_span``) at which a march reports ``z = (q, p)`` from
            its dense output, beside the nodes (``Solution.t_eval``, ``z_eval``).
        events: a function ``g(t, q, p)`` or a list of them, with scipy's optional attributes
            ``direction``, ``terminal`` (and ``vectorized``): their crossings are located on the
            march's dense output (``Solution.t_events``, ``z_events``); a terminal one ends
            the march with status ``event`` (``solvers/dense.py``).
        keep_every: a long march keeps only every ``keep_every``-th node (node indices
            ``0, k, 2k, ...``) and its last node; the others are dropped as the march goes
            (in windows of ``window`` nodes), so memory and the
            written file grow with the nodes kept, not with the steps. Every node is still
            marched, watched by the monitors and events, and judged by the accuracy check, a
            window at a time (``accuracy/streaming.py`` says what it keeps and where its
            figures differ from the check of a whole run). A thinned march takes no
            checkpoints and cannot be continued (``continue_march`` needs consecutive nodes).
            ``Solution.march.kept`` records ``keep_every``, ``keep``, the nodes marched and
            the nodes kept. Default 1: every node, as before.
        keep: ``"nodes"`` (default: every ``keep_every``-th node) or ``"t_eval"``: only the
            first and the last node are kept besides the ``t_eval`` states and the events
            (one of them must be asked for).
        window: nodes a thinned march holds before it drops those it does not keep (and
            rechecks and judges them): its memory bound, default 65536 (about 1.5 MB for one
            degree of freedom); the kept nodes and the verdict do not depend on it.
    """

    progress: bool = False
    checkpoint: Callable | None = None
    checkpoint_interval: float = 5.0
    stop: Callable[[], bool] | None = None
    t_eval: object = None
    events: object = None
    keep_every: int = 1
    keep: str = "nodes"
    window: int = 65536

    def __post_init__(self):
        _set(self, "progress", _flag("progress", self.progress))
        # node indices are 64-bit integers: a larger stride cannot be counted (it had ended
        # in an internal error), and from 2**62 on every march keeps its first and last node
        _set(self, "keep_every", check_integer("keep_every", self.keep_every, maximum=2**62))
        _set(self, "window", check_integer("window", self.window))
        if self.window < 16:
            raise InputError(f"window must be at least 16 nodes, got {self.window!r}")
        if self.keep not in KEEPS:
            raise InputError(f"keep must be one of {', '.join(KEEPS)}, got {self.keep!r}")
        if self.checkpoint is not None and not callable(self.checkpoint):
            raise InputError(f"checkpoint must be a callable save(t, z), got "
                             f"{self.checkpoint!r}")
        if self.stop is not None and not callable(self.stop):
            raise InputError(f"stop must be a callable stop() -> bool, got {self.stop!r}")
        interval = check_real("checkpoint_interval", self.checkpoint_interval, positive=True)
        if interval < MIN_CHECKPOINT_INTERVAL:
            raise InputError(f"checkpoint_interval must be at least {MIN_CHECKPOINT_INTERVAL} "
                             f"s (a checkpoint writes every node so far), got {interval!r}")
        _set(self, "checkpoint_interval", interval)
        from ..validation import check_times
        from .dense import check_events

        _set(self, "t_eval", check_times(self.t_eval))
        _set(self, "events", check_events(self.events))
        if self.keep == "t_eval" and self.t_eval is None and not self.events:
            raise InputError("keep='t_eval' keeps only the t_eval states and the events: give "
                             "t_eval or events")
        if self.keep == "t_eval" and self.keep_every != 1:
            raise InputError(f"keep='t_eval' keeps no nodes but the first and the last: "
                             f"keep_every must stay 1, got {self.keep_every!r}")
        if self.thinned and self.checkpoint is not None:
            raise InputError("a thinned march (keep_every > 1 or keep='t_eval') takes no "
                             "checkpoints: a checkpoint is for continuing a march, which needs "
                             "every node")

    @property
    def thinned(self) -> bool:
        """Whether a march keeps fewer than all its nodes."""
        return self.keep_every > 1 or self.keep != "nodes"


def coerce(value, kind, name: str):
    """``value`` if it is a ``kind`` (``None``: the defaults), else an `InputError`
    naming the argument (``steps=dict(...)`` instead of ``steps=StepControl(...)``)."""
    if value is None:
        return kind()
    if not isinstance(value, kind):
        raise InputError(f"{name} must be a {kind.__name__}(...), got {value!r}")
    return value


# --- keywords a solver no longer takes ---------------------------------------------------------

# Arguments the solvers took before their options became objects (version 0.1.0), with what
# replaced them where that is not a field of one of the option objects below.
_MOVED = {"t0": "t_span=(t0, t_end)", "t_end": "t_span=(t0, t_end)",
          "accept_inaccurate": "accuracy=Tolerance(stop=False)",
          "check_accuracy": "accuracy=None (no check) or a Tolerance",
          "p_start": "guess=Shooting(p_start)", "max_iter": "options=GridOptions(max_iter=...)"}
# Which argument of a solver holds each option object (its name in the signature).
_HOLDERS = (("steps", StepControl), ("accuracy", Tolerance), ("options", GridOptions),
            ("compilation", Compilation), ("output", Output))


def replacement(name: str, parameters) -> str | None:
    """What replaced the keyword ``name`` in a solver whose parameters are ``parameters``:
    ``t_span=(t0, t_end)`` for ``t_end``, ``steps=StepControl(tol=...)`` for ``tol``, ...;
    ``None`` for a name that was never an argument."""
    if name in _MOVED and _MOVED[name].split("=")[0] in parameters:
        return _MOVED[name]
    for holder, kind in _HOLDERS:
        if holder in parameters and name in kind.__dataclass_fields__:
            return f"{holder}={kind.__name__}({name}=...)"
    return None


def answers_removed_keywords(function):
    """``function`` as it is (same signature, same parameters), but a keyword it does not take
    that it or its options took before is a ``TypeError`` naming the replacement
    (``march(..., t_end=5)``: give ``t_span=(t0, t_end)``), not Python's bare 'unexpected
    keyword argument'."""
    import functools
    import inspect

    parameters = frozenset(inspect.signature(function).parameters)

    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        for name in kwargs.keys() - parameters:
            instead = replacement(name, parameters)
            if instead is not None:
                raise TypeError(f"{function.__name__}() no longer takes {name}=: give "
                                f"{instead} (CHANGELOG.md, 0.2.0)")
        return function(*args, **kwargs)
    return wrapper
