"""Stiff and extreme cases: where each scheme breaks, set beside where the theory says it should.

A *case* is a scene with its settings and one accuracy knob per method; every case runs every
method that applies (``lee`` only where ``H`` depends on ``t``: elsewhere its equations are the
``vddvp`` ones), each bounded by ``max_steps`` and ``time_limit`` so nothing hangs. A run gives one
row: status, steps, time reached, largest relative energy error
``max_k |H(z_k, t_k) - H_ref(t_k)| / max(1, |H(z_0, t_0)|)`` (``H_ref`` is ``H(z_0)`` for autonomous
``H``, else ``H`` along the DOP853 reference at rtol 1e-13), step-length range, and for failures
where and why (the result's message).

Predicted breakdown of the energy-determined step (THEORY.md section 5): a positive step exists
only while ``c(z) = -(f' H_zz f)/8`` keeps its sign along the orbit. ``w = f' H_zz f`` is sampled
at the nodes of the case's DOP853 run (rtol 1e-10); a sign change predicts a breakdown, and the
smallest ``|w|/max|w|`` says how close the orbit comes to one.
"""

from __future__ import annotations

import csv
import math
import os
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..physics.hamiltonian import site_density_weight_function
from ..scenes import load_scene
from ..solvers.compiler import find_compiler
from .compare import REFERENCE_RTOL, _comparable, _machine, _needs_p0, failure_table, reference_for
from .grid import Task, check_workers, describe_error, resolve_scheduler, run_grid
from .methods import METHODS

COLUMNS = ["key", "group", "case", "scene", "settings", "method", "knob", "value", "status",
           "steps", "t_reached", "t_end", "energy_error", "tau_min", "tau_max", "seconds",
           "predicted_breaks", "w_ratio", "message"]
STRESS_METHODS = ("vddvp", "lee", "midpoint", "stormer_verlet", "rk4", "dop853")
DOP853_RTOL = 1e-10
SHORT = {"success": "ok", "no_admissible_step": "no root", "newton_failed": "Newton",
         "non_finite": "NaN", "residual_too_large": "residual", "step_below_min": "tau<min",
         "step_above_max": "tau>max", "step_ratio": "ratio", "max_steps": "max steps",
         "time_limit": "time", "solver_failed": "failed", "energy_guard": "guard",
         "not_run": "not run"}


@dataclass
class Case:
    """One stress case: a scene, its settings and the step every fixed- or first-step method
    uses (DOP853 runs at rtol 1e-10)."""

    group: str
    name: str
    scene: str
    settings: dict
    tau: float
    note: str = ""
    methods: tuple = field(default=STRESS_METHODS)
    rtol: float = DOP853_RTOL


def default_cases(quick: bool = False) -> list[Case]:
    """The grid of the issue; ``quick`` keeps one or two cases per group on short horizons (for
    the tests)."""
    cases = []
    omegas = (50.0,) if quick else (50.0, 100.0, 300.0, 1000.0)
    products = (0.5, 4.0) if quick else (0.5, 1.0, 2.0, 4.0)
    for omega in omegas:
        for product in products:
            cases.append(Case("fpu", f"omega={omega:g}, omega*tau={product:g}", "fpu",
                              {"omega": omega, **({"t_end": 2.0} if quick else {})},
                              product / omega))
    for e in ((0.5, 0.9) if quick else (0.5, 0.7, 0.8, 0.9, 0.99)):
        cases.append(Case("kepler", f"e={e:g}", "kepler",
                          {"e": e, "t_end": (2 if quick else 20) * math.pi}, 0.01,
                          "ten periods" if not quick else "one period"))
    energies = [("H=2-1e-2", 2 - 1e-2), ("H=2.5 (rotation)", 2.5)] if quick else [
        ("H=2-1e-2", 2 - 1e-2), ("H=2-1e-4", 2 - 1e-4), ("H=2-1e-6", 2 - 1e-6),
        ("H=2.5 (rotation)", 2.5)]
    for label, H in energies:
        settings = {"q0": [0.0], "p0": [math.sqrt(2 * H)], "t_end": 10.0 if quick else 100.0}
        cases.append(Case("pendulum", label, "pendulum", settings, 0.05))
    periods = 10 if quick else 10_000
    cases.append(Case("long", f"harmonic, {periods} periods", "harmonic",
                      {"t_end": 2 * math.pi * periods}, 0.1))
    cases.append(Case("long", f"pendulum, {periods} periods", "pendulum",
                      {"t_end": _pendulum_period(0.5, 0.5) * periods}, 0.05))
    for tau0 in ((0.5, 5e-3) if quick else (0.5, 0.05, 5e-3, 5e-4)):
        cases.append(Case("paper_pendulum", f"tau0={tau0:g}", "paper_pendulum",
                          {"t_end": 20.0 if quick else 100.0}, tau0))
    return cases


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


def case_tasks(case: Case, *, compiler, cache_dir=None, max_steps: int = 2_000_000,
               time_limit: float = 60.0) -> list[Task]:
    """One task per method that applies to the case (``lee`` only where H depends on t)."""
    scene = load_scene(case.scene)
    _comparable(scene)
    system = scene.system
    config = scene.resolve(case.settings)
    _needs_p0(scene, config)
    tasks = []
    for name in case.methods:
        method = METHODS[name]
        if method.applies(system) or method.redundant(system):
            continue
        value = case.rtol if method.knob == "rtol" else case.tau
        # Larger first: the longest runs start early, so the workers finish together.
        cost = (config.t_end - config.t0) / (case.tau if method.knob != "rtol" else 0.05)
        tasks.append(Task(key=f"{case.group}|{case.name}|{name}|{value!r}",
                          function="ddvp_nlp.studies.stress:run_one",
                          kwargs={"group": case.group, "case": case.name, "scene": case.scene,
                                  "settings": case.settings, "method": name, "value": value,
                                  "compiler": compiler, "cache_dir": cache_dir,
                                  "max_steps": max_steps, "time_limit": time_limit},
                          priority=cost))
    return tasks


def run_one(*, group, case, scene, settings, method, value, compiler, cache_dir, max_steps,
            time_limit) -> dict:
    """One method on one case: its row (a grid task; runs in any process)."""
    loaded = load_scene(scene)
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
                "seconds": 0.0, "message": str(exc)}
    seconds = time.perf_counter() - started
    reference = reference_for(loaded, settings) if system.time_dependent else None
    tau = solution.tau
    row.update({"status": solution.status.code, "steps": solution.steps,
                "t_reached": float(solution.t[-1]),
                "energy_error": _energy_error(system, config, solution, reference),
                "tau_min": float(tau.min()) if tau.size else math.nan,
                "tau_max": float(tau.max()) if tau.size else math.nan,
                "seconds": seconds, "message": "" if solution.success else solution.message})
    if method == "dop853":
        prediction = predicted(system, config, solution)
        row["predicted_breaks"] = prediction["breaks"]
        row["w_ratio"] = prediction["w_ratio"]
    return row


def failure_row(task: Task, error: str) -> dict:
    """The row of a task that raised or whose worker died."""
    status, message = describe_error(error)
    k = task.kwargs
    return {"group": k["group"], "case": k["case"], "scene": k["scene"],
            "settings": _settings_text(k["settings"]), "method": k["method"],
            "knob": METHODS[k["method"]].knob, "value": k["value"], "status": status,
            "steps": 0, "t_reached": math.nan, "t_end": math.nan, "energy_error": math.nan,
            "tau_min": math.nan, "tau_max": math.nan, "seconds": math.nan,
            "message": message, "predicted_breaks": "", "w_ratio": math.nan}


def _settings_text(settings: dict) -> str:
    return ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                     for k, v in settings.items())


def stress(out: str | os.PathLike, *, quick: bool = False, compiler: str | None = "auto",
           cache_dir=None, max_steps: int = 2_000_000, time_limit: float = 60.0,
           cases: list[Case] | None = None, progress: bool = False, workers: int | None = 1,
           scheduler: str | None = None, resume: bool = False, name: str = "stress",
           title: str = "Stress cases: where each scheme breaks") -> list[dict]:
    """Run the grid and write ``NAME.csv``, ``NAME.md`` and ``NAME.png`` in ``out``.

    ``workers``/``scheduler``: see :func:`ddvp_nlp.grid.run_tasks` (default: in this process).
    ``resume``: keep the rows already in ``NAME.csv`` and run only the missing tasks.
    """
    from ..io.runs import prepare_folder
    from ..validation import check_integer, check_real

    max_steps = check_integer("max_steps", max_steps)
    time_limit = check_real("time_limit", time_limit, positive=True)
    workers = check_workers(workers)
    scheduler = resolve_scheduler(scheduler)
    compiler = find_compiler(compiler)
    cases = default_cases(quick) if cases is None else cases
    tasks = [task for case in cases for task in case_tasks(
        case, compiler=compiler, cache_dir=cache_dir, max_steps=max_steps,
        time_limit=time_limit)]
    out = prepare_folder(out)
    rows, _ = run_grid(tasks, out / f"{name}.csv", COLUMNS, failure_row=failure_row,
                       parse=parse_row, resume=resume, workers=workers, scheduler=scheduler,
                       progress=progress)
    predictions = {(r["case"], r["group"]): {"breaks": r["predicted_breaks"],
                                             "w_ratio": r["w_ratio"]}
                   for r in rows if r["method"] == "dop853" and r["status"] == "success"}
    context = {"cases": cases, "predictions": predictions, "compiler": compiler,
               "max_steps": max_steps, "time_limit": time_limit, "quick": quick,
               "title": title}
    plot_stress(rows, cases, out / f"{name}.png")
    (out / f"{name}.md").write_text(report(rows, context))
    return rows


def _cell(row, method="") -> str:
    if row is None:
        return "= vddvp" if method == "lee" else "n/a"
    error = row["energy_error"]
    error_text = f"{error:.0e}" if math.isfinite(error) else "-"
    if row["status"] == "success":
        return f"ok {error_text}"
    return f"**{SHORT.get(row['status'], row['status'])}** t={row['t_reached']:.3g}"


def report(rows, context) -> str:
    methods = [m for m in STRESS_METHODS if any(r["method"] == m for r in rows)]
    lines = [f"# {context.get('title', 'Stress cases: where each scheme breaks')}", "",
             "Each cell: `ok` and the largest relative energy error "
             "max |H - H_ref| / max(1, |H0|), or the failure and the time it was reached "
             "(details below). Bounds per run: "
             f"{context['max_steps']} steps, {context['time_limit']:g} s. Steps: the case's tau "
             f"for every step method (for `vddvp`/`lee` the first step); DOP853 at rtol = atol = "
             f"{DOP853_RTOL:g}. Energy reference for time-dependent H: DOP853 at "
             f"{REFERENCE_RTOL:g}. `lee` runs only where H depends on t (elsewhere its equations"
             " are `vddvp`'s).", ""]
    if context["quick"]:
        lines += ["*Quick grid (tests): short horizons, fewer cases.*", ""]
    header = "| case | tau | predicted for vddvp | " + " | ".join(f"`{m}`" for m in methods) + " |"
    rule = "|---|---|---|" + "---|" * len(methods)
    groups = list(dict.fromkeys(c.group for c in context["cases"]))
    for group in groups:
        lines += ["", f"## {group}", "", header, rule]
        for case in [c for c in context["cases"] if c.group == group]:
            prediction = context["predictions"].get((case.name, case.group))
            cells = []
            for m in methods:
                match = [r for r in rows if r["case"] == case.name and r["group"] == group
                         and r["method"] == m]
                cells.append(_cell(match[0] if match else None, m))
            lines.append(f"| {case.name} | {case.tau:.3g} | {_prediction_text(prediction)} | "
                         + " | ".join(cells) + " |")
    lines += ["", "## Predicted and observed breakdowns of the energy step", "",
              "Prediction: a positive step needs c(z) to keep its sign along the orbit (sampled "
              "at DOP853's nodes).", "",
              "| case | c(z) changes sign along the orbit | smallest abs(w)/max abs(w) | vddvp "
              "observed | vddvp steps | agrees |", "|---|---|---|---|---|---|"]
    unexplained = []
    for case in context["cases"]:
        prediction = context["predictions"].get((case.name, case.group))
        observed = [r for r in rows if r["case"] == case.name and r["group"] == case.group
                    and r["method"] == "vddvp"]
        if prediction is None or not observed:
            continue
        row = observed[0]
        broke = row["status"] != "success"
        agrees = broke == prediction["breaks"]
        if not agrees:
            unexplained.append((case, row))
        lines.append(f"| {case.group}: {case.name} | {'yes' if prediction['breaks'] else 'no'} | "
                     f"{prediction['w_ratio']:.1e} | {_cell(row)} | "
                     f"{row['tau_min']:.3g} .. {row['tau_max']:.3g} | "
                     f"{'yes' if agrees else '**no**'} |")
    if unexplained:
        lines += ["", "Where the sign of c(z) did not tell:", ""]
        for case, row in unexplained:
            what = (f"broke ({row['status']}) although c keeps its sign"
                    if row["status"] != "success" else
                    "reached t_end although c changes sign along the orbit")
            lines.append(f"- {case.group}: {case.name}: {what}; steps from {row['tau_min']:.3g}"
                         f" to {row['tau_max']:.3g}.")
    lines += failure_table(rows, "Where and why each failed run stopped",
                           ("case", lambda r: f"{r['group']}: {r['case']}"),
                           ("method", lambda r: f"`{r['method']}`"))
    lines += ["", "## Machine", "", _machine(context["compiler"]), ""]
    return "\n".join(lines)


def _prediction_text(prediction) -> str:
    if prediction is None:
        return "-"
    if prediction["breaks"]:
        return "breaks (c changes sign)"
    return f"runs (min abs(w)/max = {prediction['w_ratio']:.0e})"


def plot_stress(rows, cases, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import Normalize

    methods = [m for m in STRESS_METHODS if any(r["method"] == m for r in rows)]
    labels = [f"{c.group}: {c.name}" for c in cases]
    values = np.full((len(cases), len(methods)), np.nan)
    texts = [["" for _ in methods] for _ in cases]
    for i, case in enumerate(cases):
        for j, m in enumerate(methods):
            match = [r for r in rows if r["case"] == case.name and r["group"] == case.group
                     and r["method"] == m]
            if not match:
                texts[i][j] = "= vddvp" if m == "lee" else "n/a"
                continue
            r = match[0]
            if r["status"] == "success":
                values[i, j] = math.log10(max(r["energy_error"], 1e-16))
                texts[i][j] = f"{r['energy_error']:.0e}"
            else:
                texts[i][j] = SHORT.get(r["status"], r["status"])
    fig, ax = plt.subplots(figsize=(2.0 + 1.3 * len(methods), 1.2 + 0.32 * len(cases)),
                           constrained_layout=True)
    cmap = plt.get_cmap("viridis").with_extremes(bad="#d62728")
    image = ax.imshow(np.ma.masked_invalid(values), cmap=cmap, norm=Normalize(-16, 0),
                      aspect="auto")
    from matplotlib.patches import Rectangle

    for i in range(len(cases)):
        for j in range(len(methods)):
            skipped = texts[i][j] in ("= vddvp", "n/a")  # not run: grey, not failed red
            if skipped:
                ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, color="#dddddd"))
            dark = np.isnan(values[i, j]) and not skipped or values[i, j] < -8
            ax.text(j, i, texts[i][j], ha="center", va="center", fontsize=7,
                    color="white" if dark else "black")
    ax.set_xticks(range(len(methods)), methods, rotation=20)
    ax.set_yticks(range(len(cases)), labels, fontsize=8)
    fig.colorbar(image, ax=ax, label="log10 relative energy error (red: failed; grey: not run)")
    ax.set_title("stress grid: status and energy error")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def parse_row(row: dict) -> dict:
    """A row read back from the CSV, with its numbers and flags typed."""
    row = dict(row)
    for key in ("value", "t_reached", "t_end", "energy_error", "tau_min", "tau_max", "seconds",
                "w_ratio"):
        row[key] = float(row[key])
    row["steps"] = int(row["steps"])
    row["predicted_breaks"] = {"True": True, "False": False}.get(row["predicted_breaks"], "")
    return row


def read_rows(path) -> list[dict]:
    with open(path, newline="") as handle:
        return [parse_row(row) for row in csv.DictReader(handle)]


def status_counts(rows) -> dict:
    counts = {}
    for r in rows:
        counts.setdefault(r["method"], {}).setdefault(r["status"], 0)
        counts[r["method"]][r["status"]] += 1
    return counts


__all__ = ["COLUMNS", "Case", "case_tasks", "default_cases", "read_rows", "run_one", "stress"]
