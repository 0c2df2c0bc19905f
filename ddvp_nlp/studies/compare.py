"""Work-precision comparison: error against run time for every method on one scene.

For each method a sweep of its accuracy knob; for each run:

- run time: one warm-up call (it pays the build and compile, reported apart as ``build_s``), then
  the best of up to ``repeats`` timed calls (fewer once the repeats add up to ``budget_s``);
- trajectory error: ``max_k |z_k - z_ref(t_k)|_inf`` at the method's own node times, against the
  scene's exact solution or else DOP853 at ``rtol = atol = 1e-13`` with dense output;
- energy error: autonomous ``H``: ``max_k |H(z_k) - H(z_0)|`` (the drift of ``H`` at the nodes);
  time-dependent ``H``: ``max_k |H(z_k, t_k) - H(z_ref(t_k), t_k)|``;
- scheme energy residual: for the schemes with an energy equation, its largest residual (what the
  scheme itself conserves, e.g. ``H`` at interval midpoints for ``vddvp``).

A run that fails keeps its row, with its status and message and the errors of the nodes it
accepted; the sweep goes on. Writes ``work_precision.csv``, ``work_precision.png`` and
``summary.md``.
"""

from __future__ import annotations

import csv
import datetime
import math
import os
import platform
import time
from collections.abc import Mapping, Sequence

import numpy as np

from ..errors import InputError
from ..scenes import RunConfig, Scene, load_scene
from ..solution import Status
from ..solvers.compiler import find_compiler
from .grid import Task, check_workers, describe_error, resolve_scheduler, run_grid
from .methods import METHODS, Method, dop853, get_methods

COLUMNS = ["key", "scene", "method", "knob", "value", "status", "steps", "t_reached", "run_s",
           "build_s", "repeats", "trajectory_error", "energy_error", "scheme_energy_residual",
           "order", "symplectic", "energy_conserving", "reference", "message"]
ERROR_KINDS = {"trajectory_error": "trajectory error max |z - z_ref|",
               "energy_error": "energy error"}
REFERENCE_RTOL = 1e-13
# Error levels the summary ranks: decades from 1e-1 down to this; below it errors are round-off
# (and the DOP853 reference's own error) and a ranking would rank noise.
FINEST_LEVEL = 1e-12


class Reference:
    """``z_ref(t)`` of a run configuration: the scene's exact solution or a DOP853 solution."""

    def __init__(self, scene: Scene, config: RunConfig):
        self.system = scene.system
        self.config = config
        self.theta = scene.system.parameter_vector(config.params)
        started = time.perf_counter()
        if scene.exact is not None:
            self.kind = "exact solution"
            self._exact = scene.exact
            self._dense = None
        else:
            self.kind = f"DOP853 at rtol = atol = {REFERENCE_RTOL:g}"
            solution = dop853(scene.system, config, REFERENCE_RTOL, dense_output=True)
            if not solution.success:
                raise RuntimeError(f"the reference solution failed: {solution.message}")
            self._dense = solution.dense
            self.steps = solution.steps
        self.seconds = time.perf_counter() - started

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Reference states at times ``t``, shape ``(N, 2n)``."""
        c = self.config
        if self._dense is None:
            q, p = self._exact(t, c.q0, c.p0, c.t0, **c.params)
            return np.hstack([np.reshape(q, (t.size, -1)), np.reshape(p, (t.size, -1))])
        return self._dense(t).T


def errors(system, reference: Reference, solution) -> tuple[float, float]:
    """Trajectory and energy errors of a solution's nodes (see the module docstring)."""
    t = solution.t
    z = np.hstack([solution.q, solution.p])
    z_ref = reference(t)
    trajectory = float(np.max(np.abs(z - z_ref)))
    theta = reference.theta
    H = system.energy(solution.q, solution.p, t, theta)
    n = system.n
    if system.time_dependent:
        H_ref = system.energy(z_ref[:, :n], z_ref[:, n:], t, theta)
        energy = float(np.max(np.abs(H - H_ref)))
    else:
        energy = float(np.max(np.abs(H - H[0])))
    return trajectory, energy


def _timed(call, repeats: int, budget_s: float):
    """Warm-up call, then the best of up to ``repeats`` timed calls, stopping once they add up to
    ``budget_s``. Returns (solution of the warm-up, best seconds, number of timed calls)."""
    first = call()
    best, spent, count = math.inf, 0.0, 0
    while count < repeats and (count == 0 or spent < budget_s):
        started = time.perf_counter()
        call()
        elapsed = time.perf_counter() - started
        best, spent, count = min(best, elapsed), spent + elapsed, count + 1
    return first, best, count


def default_methods(system) -> tuple[list[Method], list[str]]:
    """Every method that applies and does not repeat another on this system, and the reasons
    for the ones left out."""
    chosen, left_out = [], []
    for method in METHODS.values():
        reason = method.applies(system) or method.redundant(system)
        if reason:
            left_out.append(f"`{method.name}`: {reason}")
        else:
            chosen.append(method)
    return chosen, left_out


def work_precision(scene: Scene, *, overrides: Mapping[str, object] | None = None,
                   methods: Sequence[str] | str | None = None, out: str | os.PathLike,
                   halvings: int = 6, repeats: int = 3, budget_s: float = 3.0,
                   compiler: str | None = "auto", cache_dir=None, max_steps: int = 5_000_000,
                   knobs: Mapping[str, Sequence[float]] | None = None,
                   progress: bool = False, workers: int | None = 1,
                   scheduler: str | None = None) -> list[dict]:
    """Run the comparison and write ``work_precision.csv``, ``.png`` and ``summary.md`` in
    ``out`` (created). Returns the rows.

    Args:
        scene: the scene; ``overrides`` as for :meth:`Scene.resolve` (parameters, ``t_end``, ...).
        methods: names (list or comma-separated); default every method that applies and is not
            the same as another on this scene.
        halvings: number of halvings of the step in the default sweeps (``2 tau0`` down).
        repeats, budget_s: timed calls per run after the warm-up, and the time after which the
            repeats stop early.
        compiler: for the compiled methods, as in :func:`ddvp_nlp.march`.
        knobs: per-method knob values replacing the default sweep.
        max_steps: bound on the steps of each run.
        workers, scheduler: where the runs go (:func:`ddvp_nlp.grid.run_tasks`). The default
            runs them one after the other in this process, because the run times are what is
            compared: two runs at once on a 2-core machine slow each other down.
    """
    from ..io.runs import prepare_folder

    _comparable(scene)
    config = scene.resolve(overrides)
    system = scene.system
    _needs_p0(scene, config)
    halvings = _count("halvings", halvings, minimum=0)
    repeats = _count("repeats", repeats)
    if methods is None:
        chosen, left_out = default_methods(system)
    else:
        chosen, left_out = get_methods(methods), []
        for method in chosen:
            reason = method.applies(system)
            if reason:
                raise InputError(f"method {method.name!r} does not apply to scene "
                                 f"{scene.name!r}: {reason}")
    knobs = dict(knobs or {})
    unknown = sorted(set(knobs) - {m.name for m in chosen})
    if unknown:
        raise InputError(f"knobs given for method {unknown[0]!r}, which is not compared")
    plan = [(m, float(v)) for m in chosen for v in knobs.get(m.name, m.sweep(config, halvings))]
    for method, value in plan:
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"{method.knob} of method {method.name!r} must be > 0, got {value!r}")
        if method.knob != "rtol" and value > config.t_end - config.t0:
            raise InputError(f"{method.knob} of method {method.name!r} must not exceed "
                             f"t_end - t0 = {config.t_end - config.t0!r}, got {value!r}")
    workers = check_workers(workers)
    scheduler = resolve_scheduler(scheduler)
    if (scheduler is not None or workers != 1) and not scene.source:
        raise InputError(f"scene {scene.name!r} was made in Python, not loaded from a file: "
                         "other processes cannot load it (use workers=1)")
    compiler = find_compiler(compiler)
    out = prepare_folder(out)

    reference = reference_for(scene, overrides or {})
    where = scene.source or scene  # a scene made in Python runs in this process only
    tasks = [Task(key=f"{method.name}|{value!r}", function="ddvp_nlp.studies.compare:run_one",
                  kwargs={"scene": where, "overrides": dict(overrides or {}),
                          "method": method.name, "value": value, "repeats": repeats,
                          "budget_s": budget_s, "compiler": compiler, "cache_dir": cache_dir,
                          "max_steps": max_steps})
             for method, value in plan]
    rows, _ = run_grid(tasks, out / "work_precision.csv", COLUMNS, failure_row=failure_row,
                       parse=parse_row, resume=False, workers=workers, scheduler=scheduler,
                       progress=progress)
    context = {"scene": scene, "config": config, "reference": reference, "left_out": left_out,
               "compiler": compiler, "repeats": repeats, "budget_s": budget_s}
    plot_work_precision(rows, out / "work_precision.png",
                        title=f"{scene.name}: error against run time")
    (out / "summary.md").write_text(summary(rows, context))
    return rows


def _comparable(scene) -> None:
    """The compared methods need H (or a first-order L): not a higher-order scene."""
    if not isinstance(scene, Scene):
        raise InputError(f"scene {scene.name!r} has higher derivatives; compare, stress and "
                         "sweep take Hamiltonian and first-order Lagrangian scenes")


def _needs_p0(scene, config) -> None:
    """The compared methods all start from (q0, p0); a march from v0 has a p0 of its own."""
    if config.p0 is None:
        raise InputError(f"scene {scene.name!r} starts from v0; the comparison needs p0 "
                         "(--set p0=...)")


def _count(name, value, minimum=1):
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return value


_REFERENCES: dict = {}


def reference_for(scene: Scene, overrides: Mapping[str, object]) -> Reference:
    """The reference of a scene and its overrides, computed once per process."""
    key = (scene.source or id(scene), scene.name, repr(sorted(dict(overrides).items())))
    if key not in _REFERENCES:
        _REFERENCES[key] = Reference(scene, scene.resolve(overrides))
    return _REFERENCES[key]


def run_one(*, scene, overrides, method, value, repeats, budget_s, compiler, cache_dir,
            max_steps) -> dict:
    """One run of the comparison, timed and measured: its row (a grid task)."""
    scene = load_scene(scene) if isinstance(scene, str) else scene
    config = scene.resolve(overrides)
    return _measure(scene, config, METHODS[method], value, reference_for(scene, overrides),
                    repeats=repeats, budget_s=budget_s, compiler=compiler,
                    cache_dir=cache_dir, max_steps=max_steps)


def failure_row(task: Task, error: str) -> dict:
    """The row of a run whose task raised or whose worker died."""
    status, message = describe_error(error)
    method = METHODS[task.kwargs["method"]]
    return {"method": method.name, "knob": method.knob, "value": task.kwargs["value"],
            "status": status, "message": message, "steps": 0, "t_reached": math.nan,
            "run_s": math.nan, "build_s": math.nan, "repeats": 0,
            "trajectory_error": math.nan, "energy_error": math.nan,
            "scheme_energy_residual": math.nan, "order": method.order,
            "symplectic": method.symplectic, "energy_conserving": method.energy_conserving,
            "reference": "", "scene": ""}


def _measure(scene, config, method, value, reference, *, repeats, budget_s, compiler,
             cache_dir, max_steps) -> dict:
    system = scene.system

    def call():
        return method.run(system, config, value, compiler=compiler, cache_dir=cache_dir,
                          max_steps=max_steps)

    row = {"scene": scene.name, "method": method.name, "knob": method.knob, "value": value,
           "order": method.order, "symplectic": method.symplectic,
           "energy_conserving": method.energy_conserving, "reference": reference.kind}
    try:
        solution, best, count = _timed(call, repeats, budget_s)
    except InputError as exc:  # e.g. a step that needs more than max_steps
        return {**row, "status": "not_run", "message": str(exc), "steps": 0,
                "t_reached": config.t0, "run_s": math.nan, "build_s": math.nan, "repeats": 0,
                "trajectory_error": math.nan, "energy_error": math.nan,
                "scheme_energy_residual": math.nan}
    trajectory, energy = errors(system, reference, solution)
    residual = (float(np.max(np.abs(solution.energy_residual)))
                if method.energy_conserving and solution.energy_residual.size else math.nan)
    timing = solution.timing
    return {**row, "status": solution.status.code, "message": solution.message,
            "steps": solution.steps, "t_reached": float(solution.t[-1]), "run_s": best,
            "build_s": timing.get("build_s", 0.0), "repeats": count,
            "trajectory_error": trajectory, "energy_error": energy,
            "scheme_energy_residual": residual}


def parse_row(row: dict) -> dict:
    """A row read back from ``work_precision.csv``, with numbers as numbers."""
    row = dict(row)
    for key in ("value", "t_reached", "run_s", "build_s", "trajectory_error", "energy_error",
                "scheme_energy_residual"):
        row[key] = float(row[key])
    for key in ("steps", "repeats", "order"):
        row[key] = int(row[key])
    for key in ("symplectic", "energy_conserving"):
        row[key] = row[key] == "True"
    return row


def read_rows(path) -> list[dict]:
    """Rows of a ``work_precision.csv`` with numbers as numbers."""
    with open(path, newline="") as handle:
        return [parse_row(row) for row in csv.DictReader(handle)]


def _succeeded(rows, method):
    return [r for r in rows if r["method"] == method and r["status"] == Status.SUCCESS.code]


def pareto(rows, method, kind) -> list[tuple[float, float]]:
    """``(run time, error)`` of the successful runs of ``method`` that no cheaper run beats."""
    points = sorted((r["run_s"], r[kind]) for r in _succeeded(rows, method)
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


def plot_work_precision(rows, path, *, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = list(dict.fromkeys(r["method"] for r in rows))
    fig, axes = plt.subplots(1, len(ERROR_KINDS), figsize=(12, 4.6), constrained_layout=True)
    markers = "os^vD<>ph*"
    for ax, (kind, label) in zip(axes, ERROR_KINDS.items(), strict=True):
        for i, method in enumerate(methods):
            good = [r for r in _succeeded(rows, method) if r[kind] > 0]
            failed = [r for r in rows if r["method"] == method and r["status"] != "success"
                      and r["run_s"] > 0 and r[kind] > 0]
            if good:
                line, = ax.loglog([r["run_s"] for r in good], [r[kind] for r in good],
                                  marker=markers[i % len(markers)], label=method)
                colour = line.get_color()
            else:
                colour = f"C{i}"
            if failed:
                ax.loglog([r["run_s"] for r in failed], [r[kind] for r in failed], "x",
                          color=colour, label=f"{method} (failed before t_end)")
        ax.set_xlabel("run time [s] (best of repeats, build excluded)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _levels(rows, kind):
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
    for method in dict.fromkeys(r["method"] for r in rows):
        hit = time_to_reach(pareto(rows, method, kind), level)
        if hit is not None:
            found.append((method, *hit))
    return sorted(found, key=lambda item: item[1])


def _seconds(value):
    return f"{value * 1e3:.3g} ms" if value < 1 else f"{value:.3g} s"


def summary(rows, context) -> str:
    scene, config, reference = context["scene"], context["config"], context["reference"]
    methods = list(dict.fromkeys(r["method"] for r in rows))
    lines = [f"# Work-precision: `{scene.name}`", "",
             f"{scene.description}", "",
             f"Run: t from {config.t0:g} to {config.t_end:g}, q0 = {config.q0.tolist()}, "
             f"p0 = {config.p0.tolist()}"
             + (", " + ", ".join(f"{k} = {v:g}" for k, v in config.params.items())
                if config.params else "") + ".",
             f"Reference: {reference.kind}"
             + (f" ({reference.steps} steps, {reference.seconds:.1f} s)."
                if reference.kind != "exact solution" else "."),
             "Energy error: " + ("the deviation of H(z_k, t_k) from the reference's "
                                 "H(z_ref(t_k), t_k) (H depends on t)."
                                 if scene.system.time_dependent else
                                 "the largest drift of H at the nodes, max |H(z_k) - H(z_0)|."),
             f"Run time: best of up to {context['repeats']} calls after one warm-up (repeats stop "
             f"after {context['budget_s']:g} s); build and compile time excluded.", "",
             "| method | order | symplectic | energy-conserving | knob | runs | failed |",
             "|---|---|---|---|---|---|---|"]
    for method in methods:
        m = METHODS[method]
        mine = [r for r in rows if r["method"] == method]
        failed = sum(r["status"] != "success" for r in mine)
        lines.append(f"| `{method}` | {m.order} | {'yes' if m.symplectic else 'no'} | "
                     f"{'yes' if m.energy_conserving else 'no'} | {m.knob} | {len(mine)} | "
                     f"{failed} |")
    if context["left_out"]:
        lines += ["", "Left out on this scene: " + "; ".join(context["left_out"]) + "."]
    for kind, label in ERROR_KINDS.items():
        lines += ["", f"## Cheapest method at each {label.split(' max')[0]} level", "",
                  "| error at most | cheapest | run time | next | ratio |",
                  "|---|---|---|---|---|"]
        for level in _levels(rows, kind):
            ranking = cheapest(rows, kind, level)
            if not ranking:
                continue
            name, seconds, bound = ranking[0]
            upper = "at most " if bound else ""
            if len(ranking) > 1:
                other, other_seconds, other_bound = ranking[1]
                ratio = other_seconds / seconds
                next_text = f"`{other}`"
                # An "at most" time makes the ratio a bound (winner) or unknown (both).
                ratio_text = "-" if bound else f"{'<= ' if other_bound else ''}{ratio:.2g}x"
            else:
                next_text, ratio_text = "none reaches it", "-"
            lines.append(f"| {level:.0e} | `{name}` | {upper}{_seconds(seconds)} | {next_text} |"
                         f" {ratio_text} |")
        lines += ["", _in_words(rows, kind, methods)]
    lines += ["", "## vddvp against DOP853 at equal energy error", "", _ratio_text(rows)]
    lines += failure_table(rows, "Runs that did not reach t_end",
                           ("method", lambda r: f"`{r['method']}`"),
                           ("knob", lambda r: f"{r['knob']} = {r['value']:.3g}"))
    residuals = [r for r in rows if r["status"] == "success"
                 and math.isfinite(r["scheme_energy_residual"])]
    if residuals:
        worst = max(residuals, key=lambda r: r["scheme_energy_residual"])
        lines += ["", f"The energy-conserving schemes' own energy equations held to "
                  f"{worst['scheme_energy_residual']:.1e} at worst (`{worst['method']}`, "
                  f"{worst['knob']} = {worst['value']:.3g}); the energy error above is H at the "
                  f"nodes, which these schemes keep within O(tau^2) without drift."]
    lines += ["", "## Machine", "", _machine(context["compiler"]), ""]
    return "\n".join(lines)


def failure_table(rows, title, *columns) -> list[str]:
    """Markdown lines: a section ``title`` with one row per failed run: the given
    ``(header, cell)`` columns, then its status and message."""
    failures = [r for r in rows if r["status"] != "success"]
    if not failures:
        return []
    headers = [h for h, _ in columns] + ["status", "where and why"]
    lines = ["", f"## {title}", "", "| " + " | ".join(headers) + " |",
             "|" + "---|" * len(headers)]
    for r in failures:
        cells = [cell(r) for _, cell in columns] + [r["status"],
                                                    r["message"].replace("|", "/")]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _in_words(rows, kind, methods) -> str:
    """Which method to use, per range of error levels, in one sentence each."""
    spans = []
    for level in _levels(rows, kind):
        ranking = cheapest(rows, kind, level)
        if not ranking:
            continue
        winner = ranking[0][0]
        if spans and spans[-1][0] == winner:
            spans[-1][2] = level
        else:
            spans.append([winner, level, level])
    if not spans:
        return "No method reached any error level in this sweep."
    parts = [f"`{w}` from {hi:.0e} down to {lo:.0e}" if hi != lo else f"`{w}` at {hi:.0e}"
             for w, hi, lo in spans]
    missing = [m for m in methods if not pareto(rows, m, kind)]
    text = "In words: cheapest is " + "; then ".join(parts) + "."
    if missing:
        text += " No successful run: " + ", ".join(f"`{m}`" for m in missing) + "."
    return text


def _ratio_text(rows) -> str:
    kind = "energy_error"
    vddvp, dop = pareto(rows, "vddvp", kind), pareto(rows, "dop853", kind)
    if not vddvp or not dop:
        return "Not measured here (both `vddvp` and `dop853` need successful runs)."
    parts = []
    for level in _levels(rows, kind):
        a, b = time_to_reach(vddvp, level), time_to_reach(dop, level)
        if a is None or b is None or a[1] or b[1]:
            continue
        parts.append(f"| {level:.0e} | {_seconds(a[0])} | {_seconds(b[0])} | "
                     f"{a[0] / b[0]:.3g} |")
    if not parts:
        return ("The two sweeps do not overlap in energy error (interpolated levels only), so no "
                "ratio at equal error is measured.")
    return "\n".join(["| energy error | vddvp | DOP853 | time ratio vddvp / DOP853 |",
                      "|---|---|---|---|", *parts])


def _machine(compiler) -> str:
    import casadi
    import scipy

    return (f"{platform.platform()}, {os.cpu_count()} cores, Python "
            f"{platform.python_version()}, CasADi {casadi.__version__}, NumPy {np.__version__}, "
            f"SciPy {scipy.__version__}; compiled methods: "
            f"{'gcc-compiled chunks (' + compiler + ')' if compiler else 'CasADi virtual machine'}"
            f"; generated {datetime.date.today().isoformat()}.")
