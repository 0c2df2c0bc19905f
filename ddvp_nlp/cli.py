"""The ``ddvp`` command. Exit codes: 0 success, 1 the solve failed (partial results written),
2 bad usage (the message names the argument)."""

from __future__ import annotations

import argparse
import sys

from .discrete.scheme import CLOCKS, RULES, Scheme
from .errors import InputError
from .scenes import VECTOR_SETTINGS, list_scenes, load_scene

# Seconds of marching between two checkpoints of `ddvp march` (a kill loses at most this).
CHECKPOINT_SECONDS = 5.0


def _parse_settings(items: list[str]) -> dict:
    """``NAME=VALUE`` pairs; ``q0``, ``p0``, ``q_start``, ``q_end`` take comma-separated lists."""
    from .validation import check_unique_settings

    check_unique_settings(items)
    settings = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise InputError(f"--set expects NAME=VALUE, got {item!r}")
        try:
            if name in VECTOR_SETTINGS:
                value = [float(v) for v in text.split(",")]
            else:
                value = float(text)
        except ValueError:
            raise InputError(f"--set {name}: value {text!r} is not a number") from None
        settings[name] = value
    return settings


def _scheme_arguments(parser: argparse.ArgumentParser, methods: tuple = ()) -> None:
    parser.add_argument("scene", help="a built-in scene name (see `ddvp scenes`) or a .py file")
    default = Scheme().rule
    parser.add_argument("--scheme", default=default, choices=RULES + methods,
                        help=f"energy rule: {', '.join(RULES)} (default: {default}, the paper's)"
                        + (f"; or a compared method, its knob tau0 (dop853: rtol = atol = "
                           f"--tol): {', '.join(methods)}" if methods else ""))
    parser.add_argument("--alpha", type=float, default=0.5,
                        help="weight alpha of the scheme, beta = 1 - alpha (default: 0.5)")
    parser.add_argument("--clock", default="midpoint", choices=CLOCKS,
                        help="time at which H is evaluated on an interval (default: midpoint)")
    parser.add_argument("--set", dest="settings", action="append", default=[],
                        metavar="NAME=VALUE",
                        help="override a scene parameter or t0, tau0, t_end, q0, p0 (march), "
                             "q_start, q_end, t0, t_end (bvp); vectors as comma lists; repeatable")
    parser.add_argument("--out", default=None,
                        help="output folder (default: runs/SCENE-SCHEME or runs/SCENE-bvp-SCHEME)")
    parser.add_argument("--tol", type=float, default=1e-10,
                        help="acceptance tolerance of the unscaled residuals (default: 1e-10)")


def _run_bounds(parser: argparse.ArgumentParser, *, defaults: bool) -> None:
    """Per-run bounds and options shared by the grid commands (``defaults=False``: ``None``,
    so a grid file's bounds apply unless given here)."""
    parser.add_argument("--max-steps", type=int, default=2_000_000 if defaults else None,
                        help="bound on the steps of each run (default: 2000000)")
    parser.add_argument("--time-limit", type=float, default=60.0 if defaults else None,
                        help="bound in seconds on each run (default: 60)")
    parser.add_argument("--no-compile", action="store_true",
                        help="run the compiled methods on CasADi's virtual machine instead")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _grid_arguments(parser: argparse.ArgumentParser, workers_default: str) -> None:
    parser.add_argument("--workers", type=int, default=None,
                        help=f"local worker processes (default: {workers_default})")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="run the tasks on this Dask scheduler, e.g. tcp://host:8786 "
                             "(default: $DDVP_SCHEDULER, else local)")


def _version() -> str:
    """The installed distribution's version (``pyproject.toml``)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("ddvp-nlp")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "unknown"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ddvp", description="Variable-time-step discrete mechanics (difference discrete "
                                 "variational principle) on CasADi.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    commands = parser.add_subparsers(dest="command", required=True)
    commands.add_parser("scenes", help="list the built-in scenes with their parameters")
    _march_command(commands)
    _bvp_command(commands)
    _compare_command(commands)
    _stress_command(commands)
    _sweep_command(commands)
    _reproduce_command(commands)
    _periodic_command(commands)
    _poincare_command(commands)
    return parser


def _poincare_command(commands) -> None:
    poincare = commands.add_parser(
        "poincare", help="a Poincare section at a fixed energy: many orbits marched together")
    poincare.add_argument("scene", help="a built-in scene name (see `ddvp scenes`) or a .py file")
    poincare.add_argument("--energy", type=float, required=True, help="the energy E")
    poincare.add_argument("--orbits", type=int, default=20, help="number of orbits M")
    poincare.add_argument("--section", default="q1=0", metavar="NAME=VALUE",
                          help="the section, NAME in q1..qn (default q1=0)")
    poincare.add_argument("--direction", default="+", choices=("+", "-"),
                          help="crossings with the section coordinate increasing (+)")
    poincare.add_argument("--t-end", type=float, default=None, help="end time of every orbit")
    poincare.add_argument("--tau0", type=float, default=None, help="first step")
    poincare.add_argument("--seed", type=int, default=0, help="seed of the starts")
    poincare.add_argument("--set", dest="settings", action="append", default=[],
                          metavar="NAME=VALUE", help="a parameter of the scene")
    poincare.add_argument("--out", default=None, help="output folder")
    poincare.add_argument("--no-plot", action="store_true", help="do not write the figure")


def _periodic_command(commands) -> None:
    periodic = commands.add_parser(
        "periodic", help="find a periodic orbit at a prescribed energy (or a family of them)")
    periodic.add_argument("scene", help="a built-in scene name (see `ddvp scenes`) or a .py file")
    periodic.add_argument("--energy", type=float, default=None,
                          help="the prescribed energy E (default: the scene's)")
    periodic.add_argument("--nodes", type=int, default=None,
                          help="number of intervals N (default: the scene's, else 200)")
    periodic.add_argument("--section", default=None, metavar="NAME=VALUE",
                          help="phase condition on node 0, NAME in q1..qn, p1..pn "
                               "(default: the scene's, else p1=0)")
    periodic.add_argument("--family", default=None, metavar="E1:E2:COUNT",
                          help="continue the orbit over COUNT energies from E1 to E2")
    periodic.add_argument("--scheme", default="vddvp", choices=("vddvp", "lee"),
                          help="energy rule (the same equations for autonomous H)")
    periodic.add_argument("--guess", default=None, metavar="FILE",
                          help="start from a run folder / result.npz (t, q, p over one period)")
    periodic.add_argument("--set", dest="settings", action="append", default=[],
                          metavar="NAME=VALUE", help="a parameter of the scene")
    periodic.add_argument("--out", default=None, help="output folder")
    periodic.add_argument("--no-plot", action="store_true", help="do not write the figures")


def _march_command(commands) -> None:
    from .studies.methods import METHODS

    march = commands.add_parser("march", help="solve an initial-value problem step by step")
    _scheme_arguments(march, tuple(name for name in METHODS if name not in RULES))
    march.add_argument("--max-steps", type=int, default=10_000_000)
    march.add_argument("--tau-min", type=float, default=None, help="smallest accepted step")
    march.add_argument("--tau-max", type=float, default=None, help="largest accepted step")
    march.add_argument("--max-step-ratio", type=float, default=10.0,
                       help="largest accepted ratio between consecutive steps (default: 10)")
    march.add_argument("--time-limit", type=float, default=None,
                       help="stop after this many seconds of stepping (status time_limit)")
    march.add_argument("--energy-guard", type=float, default=None,
                       help="stop when |H - H0| / max(1, |H0|) exceeds this at a node")
    march.add_argument("--least-squares", action="store_true",
                       help="where the energy step has no admissible root, take the least-squares "
                            "step (Kane-Marsden-Ortiz) within [tau-min, tau-max] and go on; each "
                            "such step is flagged in meta.json and result.npz")
    _accuracy_arguments(march)
    march.add_argument("--careful", action="store_true",
                       help="force the careful per-step path (default: compiled chunks of steps, "
                            "checked step by step; both accept the same steps)")
    march.add_argument("--checkpoint-every", type=float, default=CHECKPOINT_SECONDS,
                       metavar="SECONDS",
                       help="write the run so far to the output folder this often while "
                            f"marching, so a kill loses at most this much (default: "
                            f"{CHECKPOINT_SECONDS:g})")
    march.add_argument("--no-progress", action="store_true", help="no progress bar")
    march.add_argument("--no-plot", action="store_true", help="do not write trajectory.png")


def _accuracy_arguments(parser: argparse.ArgumentParser) -> None:
    """The accuracy check (``solvers/accuracy.py``): estimates that do not trust the scheme."""
    group = parser.add_argument_group(
        "accuracy check", "every step against one RK4 step of the exact flow, and the energy "
        "against H(z0); a run that fails ends with status inaccurate")
    group.add_argument("--rtol", type=float, default=1e-2,
                       help="local error test: delta_k <= atol + rtol |z| (default: 1e-2)")
    group.add_argument("--atol", type=float, default=1e-2, help="see --rtol (default: 1e-2)")
    group.add_argument("--energy-tol", type=float, default=0.1,
                       help="bound on the first step's energy level error and the nodal energy "
                            "drift, relative to max(1, |H0|) (default: 0.1)")
    group.add_argument("--global-tol", type=float, default=None,
                       help="bound on the global error estimate relative to max(1, |z|) "
                            "(default: none, reported only)")
    group.add_argument("--accept-inaccurate", action="store_true",
                       help="record the estimates and go on past a failed check")


def _bvp_command(commands) -> None:
    bvp = commands.add_parser("bvp", help="solve a fixed-endpoint problem on the whole grid")
    _scheme_arguments(bvp)
    bvp.add_argument("--nodes", type=int, default=None,
                     help="number of nodes (default: the scene's, else 101)")
    bvp.add_argument("--solver", default="auto", choices=("auto", "newton", "ipopt"),
                     help="auto (default: banded Newton, then IPOPT if its point fails the "
                          "verification), newton or ipopt")
    bvp.add_argument("--guess", default="straight", metavar="straight|march|FILE",
                     help="start: straight line (default), march (shooting from q_start), or "
                          "a run folder / result.npz whose t, q, p have --nodes rows")
    bvp.add_argument("--time-limit", type=float, default=None,
                     help="stop after this many seconds (status time_limit)")
    bvp.add_argument("--progress", action="store_true",
                     help="report each solver iteration on stderr")
    bvp.add_argument("--verbose", action="store_true", help="show IPOPT's output")
    bvp.add_argument("--no-plot", action="store_true", help="do not write trajectory.png")


def _compare_command(commands) -> None:
    from .studies.methods import METHODS

    compare = commands.add_parser(
        "compare", help="work-precision: error against run time for every method on a scene")
    compare.add_argument("scene", help="a built-in scene name (see `ddvp scenes`) or a .py file")
    compare.add_argument("--methods", default=None,
                         help="comma-separated methods (default: every one that applies); "
                              f"known: {', '.join(METHODS)}")
    compare.add_argument("--set", dest="settings", action="append", default=[],
                         metavar="NAME=VALUE",
                         help="override a scene parameter or t0, tau0, t_end, q0, p0; repeatable")
    compare.add_argument("--out", default=None,
                         help="output folder (default: runs/SCENE-compare)")
    compare.add_argument("--halvings", type=int, default=6,
                         help="step sweeps go from 2 tau0 down by this many halvings "
                              "(default: 6)")
    compare.add_argument("--repeats", type=int, default=3,
                         help="timed calls per run after one warm-up; best is kept (default: 3)")
    compare.add_argument("--no-compile", action="store_true",
                         help="run the compiled methods on CasADi's virtual machine instead")
    compare.add_argument("--no-progress", action="store_true", help="no progress bar")
    compare.add_argument("--horizons", default=None, metavar="T1,T2,...",
                         help="compare at each horizon t_end = t0 + T * --time-unit (e.g. "
                              "10,1000,100000): horizons.png, growth.png, horizons.md and a "
                              "report per horizon")
    compare.add_argument("--time-unit", type=float, default=1.0,
                         help="unit of --horizons, e.g. 6.283185307 for Kepler's period "
                              "(default: 1, the scene's time unit)")
    compare.add_argument("--max-steps", type=int, default=2_000_000,
                         help="with --horizons: runs needing more steps are left out "
                              "(default: 2000000)")
    _grid_arguments(compare, "1: the run times are what is compared")


def _stress_command(commands) -> None:
    stress = commands.add_parser(
        "stress", help="run every method on the stiff and extreme cases; say where each breaks")
    stress.add_argument("--out", default="runs/stress", help="output folder")
    stress.add_argument("--quick", action="store_true",
                        help="a few cases on short horizons (seconds)")
    _run_bounds(stress, defaults=True)
    stress.add_argument("--resume", action="store_true",
                        help="keep the rows already in OUT/stress.csv; run only the missing ones")
    _grid_arguments(stress, "one per core")


def _sweep_command(commands) -> None:
    from .studies.stress import DEFAULT_METHODS

    sweep = commands.add_parser(
        "sweep", help="run your own grid of settings x methods, locally or on a Dask cluster")
    sweep.add_argument("scene", nargs="?", default=None,
                       help="a built-in scene name or a .py file (or give --file)")
    sweep.add_argument("--grid", action="append", default=[], metavar="NAME=SPEC",
                       help="an axis: NAME=FROM:TO:COUNT or NAME=V1,V2,...; NAME is a scene "
                            "parameter, t_end, t0, tau0 (the step) or rtol (DOP853); repeatable")
    sweep.add_argument("--file", default=None, help="a TOML grid file (see `ddvp_nlp.sweep`)")
    sweep.add_argument("--methods", default=None,
                       help=f"comma-separated methods (default: {', '.join(DEFAULT_METHODS)} "
                            "where they apply)")
    sweep.add_argument("--set", dest="settings", action="append", default=[],
                       metavar="NAME=VALUE", help="a fixed scene parameter or setting")
    sweep.add_argument("--out", default=None, help="output folder (default: runs/SCENE-sweep)")
    sweep.add_argument("--fresh", action="store_true",
                       help="start afresh instead of resuming from OUT/sweep.csv")
    _run_bounds(sweep, defaults=False)
    _grid_arguments(sweep, "one per core")


def _reproduce_command(commands) -> None:
    reproduce = commands.add_parser(
        "reproduce", help="figures and report.md comparing the paper's claims with measurements")
    reproduce.add_argument("--out", default="runs/reproduce", help="output folder")
    reproduce.add_argument("--quick", action="store_true",
                           help="shorter runs and fewer step sizes (about 10 s)")
    _grid_arguments(reproduce, "1")


def _describe(name: str) -> str:
    scene = load_scene(name)
    params = ", ".join(f"{k}={v:g}" for k, v in scene.params.items())
    defaults = f"t0={scene.t0:g} tau0={scene.tau0:g} t_end={scene.t_end:g}"
    return (f"{name:16s} n={scene.n}  {params + '  ' if params else ''}{defaults}\n"
            f"{'':16s} {scene.description}")


def run_solve(args) -> int:
    """``ddvp march`` and ``ddvp bvp`` on any scene: resolve, solve, write the run folder and
    print its summary."""
    from .io.runs import prepare_folder, write_run

    scene = load_scene(args.scene)
    higher = _higher(scene)
    scheme = _scheme(args, higher)
    config = _resolve(args, scene, higher)
    infix = "-bvp" if args.command == "bvp" else ""
    out = prepare_folder(args.out if args.out is not None
                         else f"runs/{scene.name}{infix}-{args.scheme}")
    args.checkpoint = _checkpoint_saver(args, scene, out)
    if args.command == "march" and not higher:
        _INTERRUPTS.mode = "flag"  # the march polls it (stop=) and ends cleanly
    solve = _SOLVERS[args.command, higher]
    try:
        solution, extra = solve(args, scene, config, scheme)
    except KeyboardInterrupt:
        raise _Stopped(f"interrupted before the run had a result; nothing new was written to "
                       f"{out}/") from None
    with _INTERRUPTS.saving():  # a second Ctrl-C or a SIGTERM waits until the set is written
        meta = write_run(out, command=args.command, scene=scene, config=config, scheme=scheme,
                         solution=solution, extra=extra, plot=not args.no_plot)
    _summary(meta, out)
    if _INTERRUPTS.pending:
        print(f"ddvp {args.command}: interrupted while saving; the run above was written whole "
              f"to {out}/", file=sys.stderr)
    return 0 if solution.success and not _INTERRUPTS.pending else 1


def _checkpoint_saver(args, scene, out):
    """For a march of a scene with ``H`` or ``L``: ``save(t, z)`` writing the run so far to
    ``out`` (a checkpoint), interrupts held off while it writes."""
    if args.command != "march" or _higher(scene):
        return None
    from .io.runs import write_checkpoint

    def save(t, z):
        with _INTERRUPTS.saving():
            write_checkpoint(out, command="march", scene_name=scene.name, t=t, z=z,
                             n=scene.system.n)
    return save


def _higher(scene) -> bool:
    from .scenes import HigherOrderScene

    return isinstance(scene, HigherOrderScene)


def _scheme(args, higher: bool) -> Scheme:
    if higher and (args.alpha != 0.5 or args.clock != "midpoint"):
        raise InputError("--alpha and --clock do not apply to a higher-order Lagrangian "
                         "(differences are taken at the left node)")
    if args.scheme not in RULES:  # a compared method: its interval energies as fixed steps'
        return Scheme(rule="fixed")
    return Scheme(rule=args.scheme, alpha=args.alpha, clock=args.clock)


def _resolve(args, scene, higher: bool):
    settings = _parse_settings(args.settings)
    if args.command == "bvp" and not higher:
        return scene.resolve_boundary(settings, nodes=args.nodes)
    return scene.resolve(settings)


def _march(args, scene, config, scheme):
    from .solvers.march import march

    if args.scheme not in RULES:
        return _march_method(args, scene, config)

    solution = march(scene.system, config.q0, config.p0, v0=config.v0, tau0=config.tau0,
                     t_end=config.t_end,
                     t0=config.t0, scheme=scheme, params=config.params, tol=args.tol,
                     max_steps=args.max_steps, tau_min=args.tau_min, tau_max=args.tau_max,
                     max_step_ratio=args.max_step_ratio, progress=not args.no_progress,
                     fast=not args.careful, time_limit=args.time_limit,
                     energy_guard=args.energy_guard,
                     breakdown="least_squares" if args.least_squares else "stop",
                     rtol=args.rtol, atol=args.atol, energy_tol=args.energy_tol,
                     global_tol=args.global_tol, accept_inaccurate=args.accept_inaccurate,
                     checkpoint=args.checkpoint, checkpoint_interval=args.checkpoint_every,
                     stop=_INTERRUPTS.stop_requested)
    stats = solution.stats
    return solution, {key: stats[key] for key in ("path", "fast_steps", "careful_steps",
                                                  "checkpoints")}


def _march_method(args, scene, config):
    """``ddvp march --scheme NAME`` for a compared method (``studies/methods.py``): its run at
    the knob ``tau0`` (``rtol = atol = --tol`` for DOP853), then its own residual check."""
    import numpy as np

    from .solvers.compiler import find_compiler
    from .studies.methods import METHODS, run_method

    method = METHODS[args.scheme]
    value = args.tol if method.knob == "rtol" else config.tau0
    from .solvers.accuracy import Tolerance

    tolerance = Tolerance(rtol=args.rtol, atol=args.atol, energy_tol=args.energy_tol,
                          global_tol=args.global_tol, stop=not args.accept_inaccurate)
    solution = run_method(scene, config, args.scheme, value,
                          compiler=None if args.careful else find_compiler("auto"),
                          max_steps=args.max_steps, time_limit=args.time_limit, tol=args.tol,
                          tolerance=tolerance)
    extra = {"scheme": args.scheme, "method": method.description, "knob": {method.knob: value},
             "own_residual_max": solution.stats.get("own_residual_max"),
             "path": solution.stats.get("path")}
    if not scene.system.time_dependent and solution.t.size:
        # a compared method keeps no interval energy: its energy error is H's drift at the nodes
        H = scene.system.energy(solution.q, solution.p, solution.t,
                                scene.system.parameter_vector(config.params))
        extra.update(energy_error=float(np.max(np.abs(H - H[0]))),
                     energy_error_kind="largest drift of H at the nodes, max |H(z_k) - H(z_0)|")
    return solution, extra


def _bvp(args, scene, config, scheme):
    from .solvers.bvp import solve_bvp

    solution = solve_bvp(scene.system, config.q_start, config.q_end, t0=config.t_span[0],
                         t_end=config.t_span[1], nodes=config.nodes, scheme=scheme,
                         params=config.params, tol=args.tol,
                         solver=args.solver, verbose=args.verbose,
                         guess=_bvp_guess(args.guess), time_limit=args.time_limit,
                         progress=args.progress)
    return solution, {"solver": solution.stats}


def _bvp_guess(value: str):
    """``straight``, ``march``, or the ``t``, ``q``, ``p`` of a ``result.npz`` (or of the one in
    a run folder); ``InputError`` if the file is missing or lacks them."""
    from pathlib import Path

    import numpy as np

    if value in ("straight", "march"):
        return value
    path = Path(value)
    path = path / "result.npz" if path.is_dir() else path
    if not path.is_file():
        raise InputError(f"--guess must be straight, march or a result.npz (or run folder), "
                         f"got {value!r}: no such file")
    try:
        with np.load(path) as data:
            return {key: data[key] for key in ("t", "q", "p")}
    except (OSError, ValueError, KeyError) as error:
        raise InputError(f"--guess {value!r}: cannot read t, q and p from {path} "
                         f"({error})") from None


def _march_higher(args, scene, config, scheme):
    from .solvers.higher import march_higher

    t_init, q_init = scene.start(config)
    return march_higher(scene.system, t_init, q_init, t_end=config["t_end"],
                        scheme=scheme.rule, params=config["params"], tol=args.tol,
                        max_steps=args.max_steps, time_limit=args.time_limit), None


def _bvp_higher(args, scene, config, scheme):
    from .solvers.higher import solve_bvp_higher

    boundary = dict(scene.boundary or {})
    nodes = args.nodes or boundary.get("nodes", 41)
    t_span = boundary.get("t_span", (config["t0"], config["t_end"]))
    t_a, q_a, t_b, q_b = scene.ends(config, nodes, t_span)
    return solve_bvp_higher(scene.system, t_a, q_a, t_b, q_b, nodes=nodes,
                            scheme=scheme.rule, params=config["params"], tol=args.tol), None


# (command, higher-order scene) -> the solve: (args, scene, config, scheme) -> (solution, extra)
_SOLVERS = {("march", False): _march, ("bvp", False): _bvp,
            ("march", True): _march_higher, ("bvp", True): _bvp_higher}


def run_compare(args) -> int:
    from .io.work_precision import work_precision
    from .studies.compare import ERROR_KINDS, cheapest

    scene = load_scene(args.scene)
    out = args.out or f"runs/{scene.name}-compare"
    if args.horizons:
        return _compare_horizons(args, scene, out)
    rows = work_precision(scene, overrides=_parse_settings(args.settings), methods=args.methods,
                          out=out, halvings=args.halvings, repeats=args.repeats,
                          compiler=None if args.no_compile else "auto",
                          progress=not args.no_progress, workers=args.workers or 1,
                          scheduler=args.scheduler)
    failed = sum(r["status"] != "success" for r in rows)
    print(f"{scene.name} compare: {len(rows)} runs, {failed} did not reach t_end")
    for kind, label in ERROR_KINDS.items():
        for level in (1e-4, 1e-8):
            ranking = cheapest(rows, kind, level)
            if ranking:
                name, seconds, bound = ranking[0]
                print(f"  {label.split(' max')[0]} <= {level:.0e}: cheapest {name} "
                      f"({'at most ' if bound else ''}{seconds * 1e3:.3g} ms)")
    print(f"  written to {out}/ (work_precision.csv, work_precision.png, summary.md)")
    return 0


def _compare_horizons(args, scene, out) -> int:
    from .io.horizons import work_precision_horizons

    results = work_precision_horizons(
        scene, args.horizons, unit=args.time_unit, overrides=_parse_settings(args.settings),
        methods=args.methods, out=out, halvings=args.halvings, repeats=args.repeats,
        compiler=None if args.no_compile else "auto", max_steps=args.max_steps,
        progress=not args.no_progress, workers=args.workers or 1, scheduler=args.scheduler)
    for horizon, rows in results.items():
        failed = sum(r["status"] != "success" for r in rows)
        print(f"{scene.name} compare, T = {horizon:g}: {len(rows)} runs, {failed} did not reach "
              "t_end")
    print(f"  written to {out}/ (horizons.png, growth.png, horizons.md, horizon_T/)")
    return 0


def run_stress(args) -> int:
    import warnings

    from .io.stress_report import stress

    with warnings.catch_warnings():
        # the solvability warnings of breaking cases are expected here; stress.md reports them
        warnings.simplefilter("ignore", RuntimeWarning)
        rows = stress(args.out, quick=args.quick, compiler=None if args.no_compile else "auto",
                      max_steps=args.max_steps, time_limit=args.time_limit,
                      progress=not args.no_progress, workers=args.workers,
                      scheduler=args.scheduler, resume=args.resume)
    _status_summary("stress", rows, args.out, "stress")
    return 0


def run_sweep(args) -> int:
    import warnings

    from .io.stress_report import stress
    from .studies.sweep import sweep_cases

    spec = _sweep_spec(args)
    cases = sweep_cases(spec)
    out = args.out or f"runs/{load_scene(spec.scene).name}-sweep"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        rows = stress(out, cases=cases, compiler=None if args.no_compile else "auto",
                      max_steps=spec.max_steps, time_limit=spec.time_limit,
                      progress=not args.no_progress, workers=args.workers,
                      scheduler=args.scheduler, resume=not args.fresh, name="sweep",
                      title=f"Sweep of {spec.scene} over {', '.join(spec.axes)}")
    _status_summary("sweep", rows, out, "sweep")
    return 0


def _sweep_spec(args):
    """The sweep of a grid file or of SCENE with --grid axes, with the command line's methods,
    settings and bounds on top."""
    from .io.grid_file import load_grid_file
    from .studies.methods import get_methods
    from .studies.sweep import SweepSpec

    if args.file:
        if args.scene or args.grid:
            raise InputError("give either --file or SCENE with --grid, not both")
        spec = load_grid_file(args.file)
    else:
        if not args.scene or not args.grid:
            raise InputError("sweep needs SCENE and at least one --grid NAME=SPEC (or --file)")
        spec = SweepSpec(scene=args.scene, axes=_grid_axes(args.grid))
    if args.methods:
        spec.methods = tuple(m.name for m in get_methods(args.methods))
    spec.settings = {**spec.settings, **_parse_settings(args.settings)}
    if args.max_steps is not None:
        spec.max_steps = args.max_steps
    if args.time_limit is not None:
        spec.time_limit = args.time_limit
    return spec


def _grid_axes(items: list[str]) -> dict:
    """``NAME=SPEC`` items of --grid, as axes."""
    from .studies.sweep import parse_axis

    axes = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name.strip():
            raise InputError(f"--grid expects NAME=SPEC, got {item!r}")
        axes[name.strip()] = parse_axis(name.strip(), text)
    return axes


def run_reproduce(args) -> int:
    from .io.reproduce import reproduce
    from .io.runs import prepare_folder

    out = prepare_folder(args.out)
    reproduce(out, quick=args.quick, workers=args.workers or 1, scheduler=args.scheduler)
    print(f"report written to {out / 'report.md'}")
    return 0


def run_periodic(args) -> int:
    """``ddvp periodic``: one orbit (a run folder) or a family (``family.csv``, a folder per
    energy); every input checked before anything is built."""
    from .io.periodic_runs import write_family, write_periodic
    from .io.runs import prepare_folder
    from .solvers.periodic import check_periodic, solve_periodic
    from .solvers.periodic_family import solve_periodic_family

    scene = load_scene(args.scene)
    defaults = dict(getattr(scene, "periodic", None) or {})
    params = _parse_settings(args.settings)
    options = {"section": args.section or defaults.get("section", "p1=0"),
               "scheme": args.scheme, "params": params, "start": defaults.get("start"),
               "integrals": defaults.get("integrals", ())}
    nodes = args.nodes if args.nodes is not None else defaults.get("nodes", 200)
    guess = _bvp_guess(args.guess) if args.guess else None
    if args.family is not None:
        energies = _family_energies(args.family)
        for energy in (energies[0], energies[-1]):
            check_periodic(scene.system, energy=energy, nodes=nodes, **options)
        out = prepare_folder(args.out or f"runs/{scene.name}-family")
        family = solve_periodic_family(scene.system, energies, nodes=nodes, guess=guess,
                                       **options)
        rows = write_family(out, scene, family, params, plot=not args.no_plot)
        for row in rows:
            print(f"E = {row['energy']:<12.6g} {row['status']:14s} T = {row['period']:.10g}  "
                  f"residuals canonical {row['canonical']:.2e}, closure {row['closure']:.2e}")
        print(f"  written to {out}/ (family.csv, family.png, E=... folders)")
        return 0 if all(row["status"] == "success" for row in rows) else 1
    energy = args.energy if args.energy is not None else defaults.get("energy")
    if energy is None:
        raise InputError(f"--energy is needed: scene {scene.name!r} declares no default energy")
    check_periodic(scene.system, energy=energy, nodes=nodes, **options)
    out = prepare_folder(args.out or f"runs/{scene.name}-periodic")
    solution = solve_periodic(scene.system, energy=energy, nodes=nodes, guess=guess, **options)
    meta = write_periodic(out, scene, solution, params, plot=not args.no_plot)
    print(f"{scene.name} periodic [{meta['scheme']}]: {meta['status']} - {meta['message']}\n"
          f"  period {meta['period']:.12g} at E = {meta['energy']:.10g}, N = {meta['nodes']}; "
          f"written to {out}/")
    return 0 if solution.success else 1


def _family_energies(text: str):
    """``E1:E2:COUNT`` as ``COUNT`` energies from ``E1`` to ``E2``."""
    import numpy as np

    parts = text.split(":")
    try:
        first, last, count = float(parts[0]), float(parts[1]), int(parts[2])
        if len(parts) != 3:
            raise ValueError
    except (ValueError, IndexError):
        raise InputError(f"--family must be E1:E2:COUNT, got {text!r}") from None
    if count < 2 or not np.isfinite(first) or not np.isfinite(last):
        raise InputError(f"--family needs finite E1, E2 and COUNT >= 2, got {text!r}")
    return np.linspace(first, last, count)


def run_scenes(args) -> int:
    print("\n".join(_describe(name) for name in list_scenes()))
    return 0


def _status_summary(command, rows, out, name) -> None:
    from .studies.stress import status_counts

    print(f"{command}: {len(rows)} runs")
    for method, counts in status_counts(rows).items():
        failed = ", ".join(f"{k} {v}" for k, v in counts.items() if k != "success")
        print(f"  {method:15s} {counts.get('success', 0)} reached t_end"
              + (f"; {failed}" if failed else ""))
    print(f"  written to {out}/ ({name}.csv, {name}.md, {name}.png)")


def _summary(meta: dict, out) -> None:
    lines = [f"{meta['scene']} {meta['command']} [{meta['scheme']}]: {meta['status']} - "
             f"{meta['message']}",
             f"  steps {meta['steps']}, t reached {meta['t_reached']:.10g}"]
    if meta.get("tau_min") is not None:
        lines.append(f"  tau in [{meta['tau_min']:.6g}, {meta['tau_max']:.6g}]")
    lines.extend(_accuracy_lines(meta))
    if "own_residual_max" in meta:
        own = meta["own_residual_max"]
        lines.append("  own residual check: " + ("none (no equation on its nodes)" if own is None
                                                 else f"largest step residual {own:.3e}"))
    lines.append(f"  scheme's energy residual {meta['energy_error']:.3e} "
                 f"({meta['energy_error_kind']})")
    if "solvability_warning" in meta:
        warning = meta["solvability_warning"]
        lines.append(f"  solvability warning at step {warning['step']}, t = {warning['t']:.6g}: "
                     f"{warning['reason']}")
    if "least_squares_steps" in meta:
        lines.append(f"  {meta['least_squares_steps']} least-squares steps, largest energy "
                     f"defect {meta['least_squares_defect_max']:.3e}")
    if "note" in meta:
        lines.append(f"  {meta['note']}")
    if "error_vs_exact" in meta:
        lines.append(f"  error against the exact solution {meta['error_vs_exact']:.3e}")
    path = f" ({meta['path']} path)" if "path" in meta else ""
    lines.append(f"  build {meta['timing']['build_s']:.3f} s, solve {meta['timing']['solve_s']:.3f}"
                 f" s{path}; written to {out}/")
    print("\n".join(lines))


def _accuracy_lines(meta: dict) -> list[str]:
    """The estimates that do not trust the scheme, before the scheme's own residual."""
    accuracy = meta.get("accuracy")
    if not accuracy:
        return []
    lines = []
    if "node_energy_error" in meta:
        lines.append(f"  energy error {meta['node_energy_error']:.3e} (largest |H(z_k) - H0| / "
                     "max(1, |H0|) at the nodes)")
    if accuracy.get("level") is not None:
        lines.append(f"  energy level of the first step {accuracy['level']:.10g} against "
                     f"H0 = {meta['H0']:.10g} (error {accuracy['level_error']:.3e} of "
                     "max(1, |H0|))")
    estimate = f"{accuracy['global_error_estimate']:.3e} at the end"
    if accuracy.get("global_error_saturated"):
        estimate = (f">= {accuracy['global_error_estimate']:.3g} at the end (as large as the "
                    "orbit: the phase is lost over this horizon; checked only with --global-tol)")
    lines.append(f"  estimated error (against the exact flow): local <= "
                 f"{accuracy['local_error_max']:.3e} per step, global {estimate}; "
                 f"{accuracy['verdict']}")
    return lines


def _format_warning(message, category, filename, lineno, line=None):
    return f"ddvp: warning: {message}\n"


COMMANDS = {"scenes": run_scenes, "march": run_solve, "bvp": run_solve,
            "compare": run_compare, "stress": run_stress, "sweep": run_sweep,
            "reproduce": run_reproduce, "periodic": run_periodic}


def run_poincare(args) -> int:
    """``ddvp poincare``: the starts on the section, one ensemble, its crossings written."""
    from pathlib import Path

    from .io.poincare_runs import write_section
    from .studies.poincare import poincare_section
    from .validation import check_integer

    scene = load_scene(args.scene)
    config = scene.resolve({})
    orbits = check_integer("--orbits", args.orbits)
    section = poincare_section(scene.system, args.energy, section=args.section, orbits=orbits,
                               direction=args.direction,
                               tau0=args.tau0 if args.tau0 is not None else config.tau0,
                               t_end=args.t_end if args.t_end is not None else config.t_end,
                               params=_parse_settings(args.settings), seed=args.seed)
    out = Path(args.out or f"runs/{scene.name}-poincare-E{args.energy:g}")
    write_section(out, section, plot=not args.no_plot)
    failed = sum(status != "reached t_end" for status in section.statuses)
    print(f"{len(section.statuses)} orbits, {section.points.shape[0]} crossings of "
          f"{args.section}; {failed} orbits failed; largest nodal energy error "
          f"{section.energy_errors.max():.2e}")
    print(f"  written to {out}/ (section.npz, section.csv, orbits.csv, section.png)")
    return 0 if failed == 0 else 1


COMMANDS["poincare"] = run_poincare


class _Stopped(Exception):
    """The command was interrupted; the message says what was written."""


class _Interrupts:
    """SIGINT and SIGTERM, handled alike. During a march (``mode="flag"``) the first one only
    asks the march to stop: it ends after its current chunk of steps with status
    ``interrupted`` and every accepted node (raising inside a CasADi call could tear it). With
    ``mode="raise"`` the first one raises ``KeyboardInterrupt`` (a grid keeps its rows). Once a
    run is stopping or being saved (:meth:`saving`), later ones are only noted, so a second
    Ctrl-C cannot cut the files of a run short; a second one before the march polled the
    first (during its build) raises."""

    def __init__(self):
        self.mode = "raise"
        self.requested = False
        self.stopping = False
        self.pending = False
        self.holding = 0

    def install(self, mode: str):
        import signal
        import threading

        self.__init__()
        self.mode = mode
        if threading.current_thread() is not threading.main_thread():
            return lambda: None  # handlers can only be set from the main thread
        previous = {sig: signal.signal(sig, self.handle)
                    for sig in (signal.SIGINT, signal.SIGTERM)}
        return lambda: [signal.signal(sig, handler) for sig, handler in previous.items()]

    def handle(self, signum, frame):
        if self.holding or self.stopping:
            self.pending = True
            print("ddvp: still saving the run; it stops once the files are written",
                  file=sys.stderr)
            return
        if self.mode == "flag" and not self.requested:
            self.requested = True
            return
        raise KeyboardInterrupt

    def stop_requested(self) -> bool:
        """Polled by the march after each chunk: whether to stop (and from then on hold)."""
        if self.requested:
            self.stopping = True
        return self.requested

    def saving(self):
        import contextlib

        @contextlib.contextmanager
        def held():
            self.holding += 1
            try:
                yield
            finally:
                self.holding -= 1
        return held()


_INTERRUPTS = _Interrupts()


def _check_common(args) -> None:
    """Options several commands share, checked before anything is loaded: ``--workers`` (0 was
    silently taken as 1)."""
    from .validation import check_integer

    if getattr(args, "workers", None) is not None:
        check_integer("--workers", args.workers)


def main(argv: list[str] | None = None) -> int:
    import warnings

    from .errors import OutputError

    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command not in COMMANDS:
        parser.error(f"unknown command {args.command!r}")
    original_format = warnings.formatwarning
    warnings.formatwarning = _format_warning  # one line, no source echo
    restore = _INTERRUPTS.install("raise")
    try:
        _check_common(args)
        return COMMANDS[args.command](args)
    except InputError as exc:
        print(f"ddvp {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except OutputError as exc:
        print(f"ddvp {args.command}: error: {exc}; the run was not saved (the folder keeps "
              "what it held before)", file=sys.stderr)
        return 1
    except _Stopped as exc:
        print(f"ddvp {args.command}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # a grid keeps its rows
        print(f"ddvp {args.command}: interrupted; the rows finished so far are in the output "
              "folder (ddvp sweep, and ddvp stress --resume, go on from them)", file=sys.stderr)
        return 1
    finally:
        restore()
        warnings.formatwarning = original_format


if __name__ == "__main__":
    sys.exit(main())
