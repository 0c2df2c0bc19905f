"""Stiff and extreme cases: where each scheme breaks, set beside where the theory says it should.

A *case* is a scene with its settings and one accuracy knob per method; every case runs every
method that applies (``lee`` only where ``H`` depends on ``t``: elsewhere its equations are the
``vddvp`` ones), each bounded by ``max_steps`` and ``time_limit`` so nothing hangs. A run gives one
row: status, steps, time reached, largest relative energy error
``max_k |H(z_k, t_k) - H_ref(t_k)| / max(1, |H(z_0, t_0)|)`` (``H_ref`` is ``H(z_0)`` for autonomous
``H``, else ``H`` along the DOP853 reference at rtol 1e-13), step-length range, and for failures
where and why (the result's message).

Predicted breakdown of the energy-determined step (docs/theory.md section 7): a positive step exists
only while ``c(z) = -(f' H_zz f)/8`` keeps its sign along the orbit. ``w = f' H_zz f`` is sampled
at the nodes of the case's DOP853 run (rtol 1e-10); a sign change predicts a breakdown, and the
smallest ``|w|/max|w|`` says how close the orbit comes to one.

`plan_stress` checks the bounds and makes the tasks, `run_stress` runs them into the
result file and returns a `StressResult` (rows, cases, predictions); the Markdown table
and figure are written by `ddvp_nlp.studies.stress_report`. The methods are the registry's
(`ddvp_nlp.studies.methods.METHODS`), and a report's columns are the methods that ran.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..physics import site_density_weight_function
from ..runner.journal import RowSchema, run_journalled
from ..runner.tasks import Task, Workers, describe_error, resolve_scheduler
from ..scenes import load_scene, scene_digest, scene_file
from ..solvers import Compilation, StepControl, coerce, find_compiler
from .comparable import check_comparable, check_starts_from_p0, reference_for
from .methods import METHODS
from .verdict_columns import COLUMNS as ACCURACY_COLUMNS
from .verdict_columns import NOT_MADE, accuracy_columns

ROWS = RowSchema(
    columns=("key", "group", "case", "scene", "settings", "method", "knob", "value", "status",
             "steps", "t_reached", "t_end", "energy_error", "tau_min", "tau_max", "seconds",
             "predicted_breaks", "w_ratio", *ACCURACY_COLUMNS, "message", "fingerprint",
             "row_sha256"),
    floats=("value", "t_reached", "t_end", "energy_error", "tau_min", "tau_max", "seconds",
            "w_ratio", "error_estimate"),
    integers=("steps",),
    flags=("predicted_breaks",))
COLUMNS = list(ROWS.columns)
# Methods of the registry a case leaves out unless asked for by name, and why.
_LATER = ("joined the registry after the stress grid was laid out; kept out of the default "
          "grid so its cost and table stay as they were (ask for it by name among the methods)")
NOT_BY_DEFAULT = {name: _LATER for name in ("lee_left", "leapfrog", "verlet_adaptive", "avf")}
DEFAULT_METHODS = tuple(name for name in METHODS if name not in NOT_BY_DEFAULT)
DOP853_RTOL = 1e-10


@dataclass
class StressCase:
    """One stress case: a scene, its settings and the step every fixed- or first-step method
    uses (DOP853 runs at rtol 1e-10)."""

    group: str
    name: str
    scene: str
    settings: dict
    tau: float
    note: str = ""
    methods: tuple = field(default=DEFAULT_METHODS)
    rtol: float = DOP853_RTOL


def default_cases(quick: bool = False) -> list[StressCase]:
    """The grid of the issue; ``quick`` keeps one or two cases per group on short horizons (for
    the tests)."""
    return [case for group in (_fpu_cases, _kepler_cases, _pendulum_cases, _long_cases,
                               _paper_cases) for case in group(quick)]


def _fpu_cases(quick):
    omegas = (50.0,) if quick else (50.0, 100.0, 300.0, 1000.0)
    products = (0.5, 4.0) if quick else (0.5, 1.0, 2.0, 4.0)
    return [StressCase("fpu", f"omega={omega:g}, omega*tau={product:g}", "fpu",
                       {"omega": omega, **({"t_end": 2.0} if quick else {})}, product / omega)
            for omega in omegas for product in products]


def _kepler_cases(quick):
    return [StressCase("kepler", f"e={e:g}", "kepler",
                       {"e": e, "t_end": (2 if quick else 20) * math.pi}, 0.01,
                       "ten periods" if not quick else "one period")
            for e in ((0.5, 0.9) if quick else (0.5, 0.7, 0.8, 0.9, 0.99))]


def _pendulum_cases(quick):
    energies = [("H=2-1e-2", 2 - 1e-2), ("H=2.5 (rotation)", 2.5)] if quick else [
        ("H=2-1e-2", 2 - 1e-2), ("H=2-1e-4", 2 - 1e-4), ("H=2-1e-6", 2 - 1e-6),
        ("H=2.5 (rotation)", 2.5)]
    return [StressCase("pendulum", label, "pendulum",
                       {"q0": [0.0], "p0": [math.sqrt(2 * H)], "t_end": 10.0 if quick else 100.0},
                       0.05) for label, H in energies]


def _long_cases(quick):
    periods = 10 if quick else 10_000
    return [StressCase("long", f"harmonic, {periods} periods", "harmonic",
                       {"t_end": 2 * math.pi * periods}, 0.1),
            StressCase("long", f"pendulum, {periods} periods", "pendulum",
                       {"t_end": _pendulum_period(0.5, 0.5) * periods}, 0.05)]


def _paper_cases(quick):
    return [StressCase("paper_pendulum", f"tau0={tau0:g}", "paper_pendulum",
                       {"t_end": 20.0 if quick else 100.0}, tau0)
            for tau0 in ((0.5, 5e-3) if quick else (0.5, 0.05, 5e-3, 5e-4))]


def _pendulum_period(q0, p0):
    """Period of the libration of H = p^2/2 + 1 - cos q through (q0, p0): 4 K(k) with
    k = sin(q_max/2)."""
    from scipy.special import ellipk

    H = p0**2 / 2 + 1 - math.cos(q0)
    k = math.sqrt(H / 2)
    return 4 * float(ellipk(k * k))


def _energy_error(system, config, solution, reference) -> float:
    theta = system.parameter_vector(config.params)
    H = system.energy(solution.q, solution.p, solution.t, theta)
    H0 = H[0]
    if system.time_dependent:
        z = reference(solution.t)
        target = system.energy(z[:, :system.n], z[:, system.n:], solution.t, theta)
    else:
        target = H0
    return float(np.max(np.abs(H - target)) / max(1.0, abs(H0)))


def predicted(system, config, dop853_solution) -> dict:
    """Sign and smallest relative size of ``w = f' H_zz f`` along the orbit (DOP853's nodes)."""
    theta = system.parameter_vector(config.params)
    solution = dop853_solution
    w = np.asarray(site_density_weight_function(system).map(solution.t.size)(
        solution.q.T, solution.p.T, solution.t[None, :], theta[:, None])).ravel()
    sign_change = bool(np.any(np.sign(w) != np.sign(w[0])))
    return {"breaks": sign_change, "w_ratio": float(np.min(np.abs(w)) / np.max(np.abs(w))),
            "sampled_to": float(solution.t[-1])}


def case_tasks(case: StressCase, *, compiler, cache_dir=None, max_steps: int = 2_000_000,
               time_limit: float = 60.0) -> list[Task]:
    """One task per method that applies to the case (``lee`` only where H depends on t)."""
    scene = load_scene(case.scene)
    check_comparable(scene)
    system = scene.system
    config = scene.resolve(case.settings)
    check_starts_from_p0(scene, config)
    tasks = []
    for name in case.methods:
        method = METHODS[name]
        if method.applies(system) or method.redundant(system):
            continue
        value = case.rtol if method.knob == "rtol" else case.tau
        # Larger first: the longest runs start early, so the workers finish together.
        cost = (config.t_end - config.t0) / (case.tau if method.knob != "rtol" else 0.05)
        tasks.append(Task(key=f"{case.group}|{case.name}|{name}|{value!r}",
                          function=TASK_FUNCTION,
                          kwargs={"group": case.group, "case": case.name,
                                  "scene": _portable(case.scene),
                                  "scene_digest": scene_digest(case.scene),
                                  "settings": case.settings, "method": name, "value": value,
                                  "compiler": compiler, "cache_dir": cache_dir,
                                  "max_steps": max_steps, "time_limit": time_limit},
                          priority=cost))
    return tasks


def _portable(scene: str) -> str:
    """A scene name as it is, a scene path made absolute: a worker must not resolve a relative
    path in its own folder."""
    return str(scene_file(scene).resolve()) if scene.endswith(".py") or "/" in scene else scene


def stress_run(*, group, case, scene, settings, method, value, compiler, cache_dir, max_steps,
            time_limit, scene_digest=None) -> dict:
    """One method on one case: its row (a grid task; runs in any process). ``scene_digest``:
    the file this process loads must be the one the grid was planned with."""
    loaded = load_scene(scene, digest=scene_digest)
    config = loaded.resolve(settings)
    system = loaded.system
    row = {"group": group, "case": case, "scene": scene, "settings": _settings_text(settings),
           "method": method, "knob": METHODS[method].knob, "value": value,
           "t_end": config.t_end, "predicted_breaks": "", "w_ratio": math.nan}
    started = time.perf_counter()
    try:
        with warnings.catch_warnings():  # breakdowns are what this grid is for; its report
            warnings.simplefilter("ignore", RuntimeWarning)  # says where they happen
            solution = METHODS[method].run(system, config, value, compiler=compiler,
                                           cache_dir=cache_dir, max_steps=max_steps,
                                           time_limit=time_limit)
    except InputError as exc:  # e.g. more fixed steps than max_steps
        return {**row, "status": "not_run", "steps": 0, "t_reached": config.t0,
                "energy_error": math.nan, "tau_min": math.nan, "tau_max": math.nan,
                "seconds": 0.0, "message": str(exc), **NOT_MADE}
    seconds = time.perf_counter() - started
    reference = reference_for(loaded, settings) if system.time_dependent else None
    tau = solution.tau
    row.update({"status": solution.status.code, "steps": solution.steps,
                "t_reached": float(solution.t[-1]),
                "energy_error": _energy_error(system, config, solution, reference),
                "tau_min": float(tau.min()) if tau.size else math.nan,
                "tau_max": float(tau.max()) if tau.size else math.nan,
                "seconds": seconds, "message": "" if solution.success else solution.message,
                **accuracy_columns(system, config, METHODS[method], solution,
                                   compiler=compiler, cache_dir=cache_dir)})
    if method == "dop853":
        prediction = predicted(system, config, solution)
        row["predicted_breaks"] = prediction["breaks"]
        row["w_ratio"] = prediction["w_ratio"]
    return row


# The task's function as journals name it: every row's fingerprint hashes this path, so a
# journal written before `stress_run` had its own name (it was `run_one`, the name of the
# command line's run too) is resumed, not run again; `run_one` stays for it.
run_one = stress_run
TASK_FUNCTION = "ddvp_nlp.studies.stress:run_one"


def failure_row(task: Task, error: str) -> dict:
    """The row of a task that raised or whose worker died."""
    status, message = describe_error(error)
    k = task.kwargs
    return {"group": k["group"], "case": k["case"], "scene": k["scene"],
            "settings": _settings_text(k["settings"]), "method": k["method"],
            "knob": METHODS[k["method"]].knob, "value": k["value"], "status": status,
            "steps": 0, "t_reached": math.nan, "t_end": math.nan, "energy_error": math.nan,
            "tau_min": math.nan, "tau_max": math.nan, "seconds": math.nan,
            "message": message, "predicted_breaks": "", "w_ratio": math.nan, **NOT_MADE}


def _settings_text(settings: dict) -> str:
    return ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                     for k, v in settings.items())


@dataclass
class StressPlan:
    """A checked grid, ready to run: its cases, their tasks and the bounds of each run."""

    cases: list[StressCase]
    tasks: list[Task]
    compiler: str | None
    max_steps: int
    time_limit: float
    quick: bool
    workers: int | None
    scheduler: str | None


@dataclass
class StressResult:
    """What a grid measured: one row per run (`COLUMNS`), the cases, the breakdown each
    case's DOP853 run predicts, and the bounds the runs had."""

    rows: list[dict]
    cases: list[StressCase]
    predictions: dict
    compiler: str | None
    max_steps: int
    time_limit: float
    quick: bool

    @property
    def methods(self) -> list[str]:
        """The methods that ran, in the registry's order: a report's columns."""
        return [m for m in METHODS if any(r["method"] == m for r in self.rows)]

    def row(self, case: StressCase, method: str) -> dict | None:
        """The row of ``method`` on ``case``, or ``None`` if it did not run there."""
        for r in self.rows:
            if r["case"] == case.name and r["group"] == case.group and r["method"] == method:
                return r
        return None


@dataclass
class Breakdown:
    """The energy step on one case: predicted (sign of ``c(z)``) against observed (``vddvp``)."""

    case: StressCase
    prediction: dict
    row: dict

    @property
    def broke(self) -> bool:
        return self.row["status"] != "success"

    @property
    def agrees(self) -> bool:
        return self.broke == self.prediction["breaks"]


# Each run's bounds when none are given: far past where any case breaks, short of a hang.
DEFAULT_STEPS = StepControl(max_steps=2_000_000, time_limit=60.0)


def plan_stress(*, quick: bool = False, cases: list[StressCase] | None = None,
                steps: StepControl | None = None, compilation: Compilation | None = None,
                workers: Workers | None = None) -> StressPlan:
    """Check the bounds and make every case's tasks (arguments as
    `ddvp_nlp.studies.stress_report.stress`; of ``steps`` each run takes ``max_steps`` and
    ``time_limit``)."""
    steps = DEFAULT_STEPS if steps is None else coerce(steps, StepControl, "steps")
    if steps.time_limit is None:
        raise InputError("steps.time_limit must be set for a grid of runs (a run that hangs "
                         "would hold the grid), got None")
    compilation = coerce(compilation, Compilation, "compilation")
    workers = coerce(workers, Workers, "workers")
    scheduler = resolve_scheduler(workers.scheduler)
    compiler = find_compiler(compilation.compiler)
    cases = default_cases(quick) if cases is None else cases
    tasks = [task for case in cases for task in case_tasks(
        case, compiler=compiler, cache_dir=compilation.cache_dir, max_steps=steps.max_steps,
        time_limit=steps.time_limit)]
    return StressPlan(cases, tasks, compiler, steps.max_steps, steps.time_limit, quick,
                      workers.count, scheduler)


def run_stress(plan: StressPlan, rows_path, *, resume: bool = False,
               progress: bool = False, commit: bool = True) -> StressResult:
    """Run a planned grid; its rows go to the result file ``rows_path`` as they finish
    (``resume``: keep the rows already there and run only the missing tasks)."""
    rows, _ = run_journalled(plan.tasks, rows_path, COLUMNS, failure_row=failure_row,
                       parse=ROWS.parse, resume=resume, workers=plan.workers,
                       scheduler=plan.scheduler, progress=progress, commit=commit,
                       finite=("t_reached", "energy_error"))
    predictions = {(r["case"], r["group"]): {"breaks": r["predicted_breaks"],
                                             "w_ratio": r["w_ratio"]}
                   for r in rows if r["method"] == "dop853" and r["status"] == "success"}
    return StressResult(rows, plan.cases, predictions, plan.compiler, plan.max_steps,
                        plan.time_limit, plan.quick)


def prediction_for(result: StressResult, case: StressCase) -> dict | None:
    """What the sign of ``c(z)`` along the case's DOP853 orbit predicts, if DOP853 succeeded."""
    return result.predictions.get((case.name, case.group))


def breakdowns(result: StressResult) -> list[Breakdown]:
    """Each case with both a prediction and a ``vddvp`` run, in the order of the cases."""
    found = []
    for case in result.cases:
        prediction, row = prediction_for(result, case), result.row(case, "vddvp")
        if prediction is not None and row is not None:
            found.append(Breakdown(case, prediction, row))
    return found


def status_counts(rows) -> dict:
    """``{method: {status: number of runs}}``."""
    counts = {}
    for r in rows:
        counts.setdefault(r["method"], {}).setdefault(r["status"], 0)
        counts[r["method"]][r["status"]] += 1
    return counts


__all__ = ["COLUMNS", "DEFAULT_METHODS", "ROWS", "Breakdown", "StressCase", "StressPlan",
           "StressResult", "breakdowns", "case_tasks", "default_cases", "plan_stress",
           "run_stress", "status_counts", "stress_run"]
