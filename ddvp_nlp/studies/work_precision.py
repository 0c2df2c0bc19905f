"""Work-precision comparison: error against run time for every method on one scene.

For each method a sweep of its accuracy knob, or, for the methods that aim at an error (the
march's schemes, ``Integrator.aims``) when target errors are given, one run per target error
(``march(..., target_error=E)``: the row's knob is ``target_error``, its value ``E``, and
``chosen_tau0`` the first step the march chose); for each run:

- run time: one warm-up call (it pays the build and compile, reported apart as ``build_s``), then
  the best of up to ``repeats`` timed calls (fewer once the repeats add up to ``budget_s``):
  wall-clock ``run_s`` and the CPU time of the same call ``cpu_s``; a run at a target error
  pays its pilot and any second try, as a user does;
- trajectory error: ``max_k |z_k - z_ref(t_k)|_inf`` at the method's own node times, against the
  scene's exact solution or else DOP853 at ``rtol = atol = 1e-13`` with dense output;
- energy error: autonomous ``H``: ``max_k |H(z_k) - H(z_0)|`` (the drift of ``H`` at the nodes);
  time-dependent ``H``: ``max_k |H(z_k, t_k) - H(z_ref(t_k), t_k)|``;
- scheme energy residual: for the schemes with an energy equation, its largest residual (what the
  scheme itself conserves, e.g. ``H`` at interval midpoints for ``vddvp``).

A run that fails keeps its row, with its status and message and the errors of the nodes it
accepted; the sweep goes on. The public entry is ``compare`` (``studies/comparison.py``).
`plan_work_precision` checks the input,
`run_work_precision` runs the grid into its result file and returns a
`WorkPrecision`; the rankings
(`pareto`, `cheapest`, ...) read its rows. The CSV, figure and ``summary.md`` are
written by `ddvp_nlp.studies.work_precision_report`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..runner.journal import RowSchema, run_journalled
from ..runner.tasks import Task, Workers, describe_error, resolve_scheduler
from ..scenes import RunConfig, Scene, load_scene
from ..solution import Status
from ..solvers import Compilation, coerce, evaluate_blocks, find_compiler
from ..validation import check_count, check_real
from .comparable import (
    REFERENCE_KINDS,
    REFERENCE_RTOL,
    ComparisonReference,
    check_comparable,
    check_starts_from_p0,
    reference_for,
)
from .methods import METHODS, Method, get_methods
from .verdict_columns import COLUMNS as ACCURACY_COLUMNS
from .verdict_columns import NOT_MADE, accuracy_columns

ROWS = RowSchema(
    columns=("key", "scene", "method", "knob", "value", "status", "steps", "t_reached", "run_s",
             "build_s", "repeats", "trajectory_error", "energy_error", "scheme_energy_residual",
             "order", "symplectic", "energy_conserving", "reference", *ACCURACY_COLUMNS,
             "cpu_s", "chosen_tau0", "run_s_median", "run_s_max", "cpu_s_median", "cpu_s_max",
             "message", "fingerprint", "row_sha256"),
    floats=("value", "t_reached", "run_s", "build_s", "trajectory_error", "energy_error",
            "scheme_energy_residual", "error_estimate", "cpu_s", "chosen_tau0",
            "run_s_median", "run_s_max", "cpu_s_median", "cpu_s_max"),
    integers=("steps", "repeats", "order"),
    flags=("symplectic", "energy_conserving"))
COLUMNS = list(ROWS.columns)
# Columns added since the first files were written: what a file without them reads as.
ADDED = {"cpu_s": "nan", "chosen_tau0": "nan", "run_s_median": "nan", "run_s_max": "nan",
         "cpu_s_median": "nan", "cpu_s_max": "nan"}
# The spread of a run's timed calls (wall and CPU), beside the best: what the figures' bars
# show.
SPREAD = ("run_s_median", "run_s_max", "cpu_s_median", "cpu_s_max")
ERROR_KINDS = {"trajectory_error": "trajectory error max |z - z_ref|",
               "energy_error": "energy error"}
# The cost a run is ranked and drawn by: the fastest of its timed calls by the wall clock, or
# that call's CPU time (on a machine other processes share, their turns count in wall time).
CLOCKS = {"wall": "run_s", "cpu": "cpu_s"}
# Error levels the summary ranks: decades from 1e-1 down to this; below it errors are round-off
# (and the DOP853 reference's own error) and a ranking would rank noise.
FINEST_LEVEL = 1e-12

__all__ = ["COLUMNS", "CompareOptions", "ComparisonReference", "ERROR_KINDS", "REFERENCE_RTOL",
           "ROWS", "WorkPrecision",
           "WorkPrecisionPlan", "cheapest", "default_methods", "errors", "pareto",
           "plan_work_precision", "run_work_precision", "time_to_reach"]


@dataclass(frozen=True)
class CompareOptions:
    """What a work-precision comparison runs and how it times the runs.

    Attributes:
        methods: names (a list or comma-separated); default every method that applies and is
            not the same as another on this scene.
        halvings: number of halvings of the step in the default sweeps (``2 tau0`` down).
        repeats, budget_s: timed calls per run after the warm-up, and the time after which the
            repeats stop early.
        max_steps: bound on the steps of each run.
        knobs: per-method knob values replacing the default sweep.
        reference: ``auto`` (the scene's exact solution where it covers the start, else
            DOP853 at 1e-13), ``exact``, ``dop853``, or ``none`` (energy error only).
        target_errors: trajectory errors (relative to the motion's size, each in (0, 1)) the
            methods that aim at an error (the march's schemes) are run at, one run each,
            instead of their knob sweep; the other methods keep their sweeps.
    """

    methods: Sequence[str] | str | None = None
    halvings: int = 6
    repeats: int = 3
    budget_s: float = 3.0
    max_steps: int = 5_000_000
    knobs: Mapping[str, Sequence[float]] | None = None
    reference: str = "auto"
    target_errors: Sequence[float] | None = None

    def __post_init__(self):
        object.__setattr__(self, "halvings", check_count("halvings", self.halvings, minimum=0,
                                                         maximum=MAX_HALVINGS))
        object.__setattr__(self, "repeats", check_count("repeats", self.repeats, minimum=1))
        object.__setattr__(self, "budget_s", check_real("budget_s", self.budget_s,
                                                        positive=True))
        object.__setattr__(self, "max_steps", check_count("max_steps", self.max_steps,
                                                          minimum=1))
        if self.reference not in REFERENCE_KINDS:
            raise InputError(f"reference must be one of {', '.join(REFERENCE_KINDS)}, "
                             f"got {self.reference!r}")
        if self.target_errors is not None:
            object.__setattr__(self, "target_errors", check_target_errors(self.target_errors))


def check_target_errors(values, name: str = "target_errors") -> tuple[float, ...]:
    """Target errors: a non-empty list of distinct numbers in (0, 1), refused under ``name``."""
    if isinstance(values, (str, bytes)) or not isinstance(values, Sequence) or not values:
        raise InputError(f"{name} must be a non-empty list of errors in (0, 1), "
                         f"got {values!r}")
    found = []
    for value in values:
        value = check_real(name, value, positive=True)
        if not value < 1:
            raise InputError(f"{name} are relative to the motion's size and must be "
                             f"below 1, got {value!r}")
        if value in found:
            raise InputError(f"{name} gives {value!r} twice")
        found.append(value)
    return tuple(found)


@dataclass
class WorkPrecisionPlan:
    """A checked comparison, ready to run: which method at which knob value, and how."""

    scene: Scene
    overrides: dict
    config: RunConfig
    runs: list[tuple[Method, float, bool]]
    left_out: list[str]
    repeats: int
    budget_s: float
    compiler: str | None
    cache_dir: object
    max_steps: int
    workers: int | None
    scheduler: str | None
    reference: str = "auto"


@dataclass
class WorkPrecision:
    """What a comparison measured, as ``compare`` returns it and ``ddvp compare`` writes it.

    Attributes:
        rows: one dict per run, failed runs included (`COLUMNS`): ``method``, ``knob`` and
            its ``value``, ``status`` and ``message`` (why a run failed), ``steps``,
            ``t_reached``, ``trajectory_error`` (against ``reference``), ``energy_error``,
            ``scheme_energy_residual``, ``run_s`` (wall) and ``cpu_s``, ``build_s``,
            ``accuracy`` (the verdict: ``accurate``, ``drifted from t = ...``,
            ``inaccurate: ...``) and ``error_estimate``, ``chosen_tau0`` (at a target error).
        scene, config: the scene and the run it compared (start, span, parameters).
        reference: what the errors are measured against (``reference.kind`` says).
        left_out: the methods not run on this scene, each with the reason.
        compiler, repeats, budget_s: how the runs were timed.
    """

    rows: list[dict]
    scene: Scene
    config: RunConfig
    reference: ComparisonReference
    left_out: list[str]
    compiler: str | None
    repeats: int
    budget_s: float

    def __repr__(self) -> str:
        failed = len(self.failed)
        return (f"WorkPrecision({self.scene.name!r}: {len(self.rows)} runs of "
                f"{', '.join(methods_in(self.rows))}; {failed} did not reach t_end)")

    @property
    def failed(self) -> list[dict]:
        """The rows of the runs that did not succeed, each with its ``status`` and
        ``message``."""
        return [r for r in self.rows if r["status"] != Status.SUCCESS.code]

    def limitations(self) -> dict[str, str]:
        """``{method: why}`` for each compared method with no successful run whose integrator
        states where it cannot run (`Integrator.limitation`)."""
        return {name: METHODS[name].limitation for name in methods_in(self.rows)
                if METHODS[name].limitation and not succeeded(self.rows, name)}

    def best(self, error: float, kind: str = "trajectory_error", *,
             clock: str = "wall") -> dict | None:
        """The cheapest successful run whose ``kind`` error (a key of `ERROR_KINDS`) is at
        most ``error``; ``None`` if no run reaches it. Cheapest by ``clock``: ``wall``, the
        fastest of its timed calls (``run_s``, what ``summary.md`` ranks by), or ``cpu``, that
        call's CPU time (``cpu_s``; the figure drawn with the same ``clock`` shows it)."""
        if kind not in ERROR_KINDS:
            raise InputError(f"kind must be one of {', '.join(ERROR_KINDS)}, got {kind!r}")
        column = _clock_column(clock)
        error = check_real("error", error, positive=True)
        found = [r for r in self.rows if r["status"] == Status.SUCCESS.code
                 and math.isfinite(r[kind]) and r[kind] <= error
                 and math.isfinite(r.get(column, math.nan))]
        return min(found, key=lambda r: r[column], default=None)

    def to_csv(self, path) -> None:
        """The rows as ``ddvp compare``'s ``work_precision.csv`` (without the journal's
        checksums)."""
        import csv

        columns = [c for c in COLUMNS if c not in ("fingerprint", "row_sha256")]
        with open(path, "w", newline="") as handle:
            writer = csv.DictWriter(handle, columns, extrasaction="ignore")
            writer.writeheader()
            writer.writerows(self.rows)

    def plot(self, path=None, *, title: str | None = None, width: str = "column",
             clock: str = "wall"):
        """The work-precision figure of ``ddvp compare`` (error against run time, a panel per
        error kind, failed runs marked; ``width``: ``column``, 3.4 in, or ``text``, 7 in;
        ``clock``: ``wall`` or ``cpu``, the run time drawn, as `best` ranks by it).
        Returns the ``matplotlib.figure.Figure``; with ``path`` (PNG, SVG or PDF by its
        suffix) it is also written there."""
        from ..io.figures import Keep, format_of, save, styled
        from ..io.work_precision_figure import plot_work_precision

        _clock_column(clock)
        keep = Keep()
        plot_work_precision(self.rows, keep, clock=clock,
                            title=title or f"{self.scene.name}: error against run time",
                            width=width, time_dependent=self.scene.system.time_dependent)
        if path is not None:
            with styled():  # the house style's resolution (savefig.dpi), not matplotlib's
                save(keep.figure, path, format_of(path))
        return keep.figure


def _clock_column(clock: str) -> str:
    if clock not in CLOCKS:
        raise InputError(f"clock must be one of {', '.join(CLOCKS)}, got {clock!r}")
    return CLOCKS[clock]


def errors(system, reference: ComparisonReference, solution,
           compilation: Compilation | None = None) -> tuple[float, float]:
    """Trajectory and energy errors of a solution's nodes (see the module docstring). ``H`` at
    the nodes through a compiled window map kept per system (``compilation``): a map per run's
    length cost more than the runs of ``ddvp compare kepler`` (measured)."""
    t = solution.t
    z = np.hstack([solution.q, solution.p])
    z_ref = reference(t)
    trajectory = float(np.max(np.abs(z - z_ref)))
    theta = reference.theta
    compilation = compilation or Compilation()

    def energy_at(q, p):
        return evaluate_blocks(system, ("study_energy",), system.H_function,
                               [q, p, t[:, None]], theta, compilation)[0].ravel()

    H = energy_at(solution.q, solution.p)
    n = system.n
    if system.time_dependent:
        H_ref = energy_at(z_ref[:, :n], z_ref[:, n:])
        energy = float(np.max(np.abs(H - H_ref)))
    else:
        energy = float(np.max(np.abs(H - H[0])))
    return trajectory, energy


def _timed(call, repeats: int, budget_s: float):
    """Warm-up call, then the best of up to ``repeats`` timed calls, stopping once they add up to
    ``budget_s``. Returns (solution of the warm-up, best wall seconds, the CPU seconds of that
    call, number of timed calls, the spread: `SPREAD`'s medians and maxima of the calls' wall
    and CPU seconds)."""
    first = call()
    walls, cpus, spent = [], [], 0.0
    while len(walls) < repeats and (not walls or spent < budget_s):
        started, cpu = time.perf_counter(), time.process_time()
        call()
        walls.append(time.perf_counter() - started)
        cpus.append(time.process_time() - cpu)
        spent += walls[-1]
    best = int(np.argmin(walls))
    spread = dict(zip(SPREAD, (float(np.median(walls)), max(walls), float(np.median(cpus)),
                               max(cpus)), strict=True))
    return first, walls[best], cpus[best], len(walls), spread


def default_methods(system) -> tuple[list[Method], list[str]]:
    """Every method that applies and does not repeat another on this system, and the reasons
    for the ones left out (a method of constrained systems only is left out of a system
    without constraints without a reason: the report does not list what the scene does not
    need)."""
    chosen, left_out = [], []
    constrained = getattr(system, "n_constraints", 0) > 0
    for method in METHODS.values():
        if method.constrained_only and not constrained:
            continue
        reason = method.applies(system) or method.redundant(system)
        if reason:
            left_out.append(f"`{method.name}`: {reason}")
        else:
            chosen.append(method)
    return chosen, left_out


def _chosen_methods(scene, methods) -> tuple[list[Method], list[str]]:
    """The methods asked for (each must apply), or by default every one that applies."""
    if methods is None:
        return default_methods(scene.system)
    chosen = get_methods(methods)
    for method in chosen:
        reason = method.applies(scene.system)
        if reason:
            raise InputError(f"method {method.name!r} does not apply to scene "
                             f"{scene.name!r}: {reason}")
    return chosen, []


# Halvings of the step past this reach steps of 2 tau0 / 2**40, where round-off has long taken
# over and a single run would take days; 100000 overflowed a float.
MAX_HALVINGS = 40


def _runs(chosen, knobs, config, halvings, targets=None) -> list[tuple[Method, float, bool]]:
    """``(method, value, aims)`` of every run: a method that aims at an error once per target
    error (``aims``: the value is the target), else the given knob values or the method's
    sweep."""
    knobs = dict(knobs or {})
    unknown = sorted(set(knobs) - {m.name for m in chosen})
    if unknown:
        raise InputError(f"knobs given for method {unknown[0]!r}, which is not compared")
    runs = []
    for m in chosen:
        if targets and m.aims and m.name not in knobs:
            runs += [(m, float(e), True) for e in targets]
        else:
            runs += [(m, float(v), False) for v in knobs.get(m.name, m.sweep(config, halvings))]
    span = config.t_end - config.t0
    for method, value, aims in runs:
        if aims:
            continue
        check_real(f"{method.knob} of method {method.name!r}", value, positive=True)
        if method.knob != "rtol" and value > span:
            raise InputError(f"{method.knob} of method {method.name!r} must not exceed "
                             f"t_end - t0 = {span!r}, got {value!r}")
    return runs


def plan_work_precision(scene: Scene, *, overrides: Mapping[str, object] | None = None,
                        options: CompareOptions | None = None,
                        compilation: Compilation | None = None,
                        workers: Workers | None = None) -> WorkPrecisionPlan:
    """Check a comparison's input before anything runs (arguments as
    `ddvp_nlp.studies.work_precision_report.work_precision`)."""
    options = coerce(options, CompareOptions, "options")
    compilation = coerce(compilation, Compilation, "compilation")
    workers = coerce(workers, Workers, "workers")
    check_comparable(scene)
    config = scene.resolve(overrides)
    check_starts_from_p0(scene, config)
    chosen, left_out = _chosen_methods(scene, options.methods)
    runs = _runs(chosen, options.knobs, config, options.halvings, options.target_errors)
    scheduler = resolve_scheduler(workers.scheduler)
    if (scheduler is not None or workers.count != 1) and not scene.source:
        raise InputError(f"scene {scene.name!r} was made in Python, not loaded from a file: "
                         "other processes cannot load it (use workers=1)")
    return WorkPrecisionPlan(scene, dict(overrides or {}), config, runs, left_out,
                             options.repeats, options.budget_s,
                             find_compiler(compilation.compiler), compilation.cache_dir,
                             options.max_steps, workers.count, scheduler, options.reference)


def run_work_precision(plan: WorkPrecisionPlan, rows_path, *,
                       progress: bool = False, commit: bool = True) -> WorkPrecision:
    """Run a planned comparison; its rows go to the result file ``rows_path`` as they finish."""
    scene = plan.scene
    reference = reference_for(scene, plan.overrides, plan.reference)
    where = scene.source or scene  # a scene made in Python runs in this process only
    tasks = [Task(key=f"{method.name}|{'target=' if aims else ''}{value!r}",
                  function=TASK_FUNCTION,
                  kwargs={"scene": where, "overrides": plan.overrides,
                          "method": method.name, "value": value, "repeats": plan.repeats,
                          "budget_s": plan.budget_s, "compiler": plan.compiler,
                          "cache_dir": plan.cache_dir, "max_steps": plan.max_steps,
                          "reference": plan.reference, "aims": aims})
             for method, value, aims in plan.runs]
    rows, _ = run_journalled(tasks, rows_path, COLUMNS, failure_row=failure_row, parse=ROWS.parse,
                       resume=False, workers=plan.workers, scheduler=plan.scheduler,
                       progress=progress, commit=commit)
    return WorkPrecision(rows, scene, plan.config, reference, plan.left_out, plan.compiler,
                         plan.repeats, plan.budget_s)


def timed_run(*, scene, overrides, method, value, repeats, budget_s, compiler, cache_dir,
            max_steps, reference: str = "auto", aims: bool = False) -> dict:
    """One run of the comparison, timed and measured: its row (a grid task); with ``aims``
    the method aims at the trajectory error ``value`` from a pilot at the scene's ``tau0``."""
    scene = load_scene(scene) if isinstance(scene, str) else scene
    config = scene.resolve(overrides)
    return _measure(scene, config, METHODS[method], value,
                    reference_for(scene, overrides, reference),
                    repeats=repeats, budget_s=budget_s, compiler=compiler,
                    cache_dir=cache_dir, max_steps=max_steps, aims=aims)


# The task's function as journals name it: every row's fingerprint hashes this path, so a
# journal written before `timed_run` had its own name (it was `run_one`, the name of the
# command line's run too) is resumed, not run again; `run_one` stays for it.
run_one = timed_run
TASK_FUNCTION = "ddvp_nlp.studies.work_precision:run_one"


_NOT_MEASURED = {"trajectory_error": math.nan, "energy_error": math.nan,
                 "scheme_energy_residual": math.nan, "run_s": math.nan, "build_s": math.nan,
                 "cpu_s": math.nan, "repeats": 0, "steps": 0, **NOT_MADE,
                 **dict.fromkeys(SPREAD, math.nan)}


def _traits(method: Method, aims: bool = False) -> dict:
    return {"method": method.name, "knob": "target_error" if aims else method.knob,
            "order": method.order, "symplectic": method.symplectic,
            "energy_conserving": method.energy_conserving}


def failure_row(task: Task, error: str) -> dict:
    """The row of a run whose task raised or whose worker died."""
    status, message = describe_error(error)
    return {**_traits(METHODS[task.kwargs["method"]], task.kwargs.get("aims", False)),
            **_NOT_MEASURED, "value": task.kwargs["value"], "status": status,
            "message": message, "t_reached": math.nan, "reference": "", "scene": "",
            "chosen_tau0": math.nan}


def _measure(scene, config, method, value, reference, *, repeats, budget_s, compiler,
             cache_dir, max_steps, aims=False) -> dict:
    system = scene.system
    if aims:  # the pilot from the scene's first step; the march chooses its own
        knob, target = config.tau0, {"target_error": value}
    else:
        knob, target = value, {}

    def call():
        return method.run(system, config, knob, compiler=compiler, cache_dir=cache_dir,
                          max_steps=max_steps, **target)

    row = {"scene": scene.name, **_traits(method, aims), "value": value,
           "reference": reference.kind, "chosen_tau0": math.nan}
    try:
        solution, best, cpu, count, spread = _timed(call, repeats, budget_s)
    except InputError as exc:  # e.g. a step that needs more than max_steps, a failed pilot
        return {**row, **_NOT_MEASURED, "status": "not_run", "message": str(exc),
                "t_reached": config.t0}
    if aims:
        row["chosen_tau0"] = solution.march.target_error["tau0"]
    trajectory, energy = errors(system, reference, solution,
                                Compilation(compiler=compiler, cache_dir=cache_dir))
    residual = (float(np.max(np.abs(solution.energy_residual)))
                if method.energy_conserving and solution.energy_residual.size else math.nan)
    return {**row, "status": solution.status.code, "message": solution.message,
            "steps": solution.steps, "t_reached": float(solution.t[-1]), "run_s": best,
            "cpu_s": cpu, **spread, "build_s": solution.timing.get("build_s", 0.0),
            "repeats": count,
            "trajectory_error": trajectory, "energy_error": energy,
            "scheme_energy_residual": residual,
            **accuracy_columns(system, config, method, solution, compiler=compiler,
                               cache_dir=cache_dir)}


def succeeded(rows, method) -> list[dict]:
    """The rows of ``method`` that reached ``t_end``."""
    return [r for r in rows if r["method"] == method and r["status"] == Status.SUCCESS.code]


def methods_in(rows) -> list[str]:
    """The methods of the rows, in the order they first appear."""
    return list(dict.fromkeys(r["method"] for r in rows))


def pareto(rows, method, kind) -> list[tuple[float, float]]:
    """``(run time, error)`` of the successful runs of ``method`` that no cheaper run beats."""
    points = sorted((r["run_s"], r[kind]) for r in succeeded(rows, method)
                    if math.isfinite(r[kind]) and r[kind] > 0)
    front = []
    for seconds, error in points:
        if not front or error < front[-1][1]:
            front.append((seconds, error))
    return front


def time_to_reach(front, level) -> tuple[float, bool] | None:
    """Run time at which a method reaches error ``level``: log-log interpolation along its Pareto
    front; ``(time, True)`` if its cheapest run is already below the level (an upper bound);
    ``None`` if no run reaches it."""
    for i, (seconds, error) in enumerate(front):
        if error <= level:
            if i == 0:
                return seconds, True
            (t0, e0), (t1, e1) = front[i - 1], front[i]
            fraction = (math.log(level) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(t0) + fraction * (math.log(t1) - math.log(t0))), False
    return None


def error_levels(rows, kind) -> list[float]:
    """The decades of error the successful runs span, from at most 1e-1 down to at least
    `FINEST_LEVEL`, coarse to fine."""
    errors_seen = [r[kind] for r in rows if r["status"] == "success" and r[kind] > 0
                   and math.isfinite(r[kind])]
    if not errors_seen:
        return []
    top = math.floor(math.log10(max(errors_seen)))
    bottom = max(math.ceil(math.log10(min(errors_seen))), round(math.log10(FINEST_LEVEL)))
    return [10.0 ** k for k in range(min(top, -1), bottom - 1, -1)]


def cheapest(rows, kind, level):
    """Methods reaching ``level`` sorted by run time: ``[(method, seconds, upper_bound)]``."""
    found = []
    for method in methods_in(rows):
        hit = time_to_reach(pareto(rows, method, kind), level)
        if hit is not None:
            found.append((method, *hit))
    return sorted(found, key=lambda item: item[1])


def rankings(rows, kind) -> list[tuple[float, list]]:
    """``(level, cheapest(rows, kind, level))`` at every error level some method reaches."""
    found = [(level, cheapest(rows, kind, level)) for level in error_levels(rows, kind)]
    return [(level, ranking) for level, ranking in found if ranking]


def winner_spans(rows, kind) -> list[tuple[str, float, float]]:
    """``(method, coarsest level, finest level)`` of each run of levels one method wins."""
    spans = []
    for level, ranking in rankings(rows, kind):
        winner = ranking[0][0]
        if spans and spans[-1][0] == winner:
            spans[-1][2] = level
        else:
            spans.append([winner, level, level])
    return [tuple(span) for span in spans]


def time_ratios(rows, first, second, kind) -> list[tuple[float, float, float]] | None:
    """``(level, seconds of first, seconds of second)`` at the levels both reach by
    interpolation (no upper bounds); ``None`` if either has no successful run."""
    a_front, b_front = pareto(rows, first, kind), pareto(rows, second, kind)
    if not a_front or not b_front:
        return None
    found = []
    for level in error_levels(rows, kind):
        a, b = time_to_reach(a_front, level), time_to_reach(b_front, level)
        if a is None or b is None or a[1] or b[1]:
            continue
        found.append((level, a[0], b[0]))
    return found
