"""``ddvp compare``, ``stress``, ``sweep``, ``reproduce`` and ``scenes``: the commands that run
many solves (through ``studies/``) and write their reports (through ``io/``)."""

from __future__ import annotations

import warnings

from ..errors import InputError
from ..scenes import list_scenes, load_scene
from ..solvers.options import StepControl
from ..validation import check_real
from . import options
from .parser import parse_settings
from .summary import status_summary


def _describe(name: str) -> str:
    """A scene's entry of ``ddvp scenes``: parameters and run defaults, description, initial
    state, fixed-endpoint data and the scheme ``march`` and ``bvp`` use by default."""
    from ..discrete.scheme import Scheme
    from ..scenes import HigherOrderScene

    scene = load_scene(name)
    params = ", ".join(f"{k}={v:g}" for k, v in scene.params.items())
    defaults = f"t0={scene.t0:g} tau0={scene.tau0:g} t_end={scene.t_end:g}"
    scheme = (f"{scene.scheme} (the scene's)" if scene.scheme
              else f"{Scheme().rule} (default)")
    indent = " " * 17
    lines = [f"{name:16s} n={scene.n}  {params + '  ' if params else ''}{defaults}",
             f"{indent}{scene.description}"]
    if isinstance(scene, HigherOrderScene):
        lines.append(f"{indent}start: the exact motion at {2 * scene.order} nodes tau0 apart "
                     "from t0")
        ends = scene.boundary
        span = (ends and ends.t_span) or (scene.t0, scene.t_end)
        lines.append(f"{indent}fixed ends: the exact motion's {scene.order} first and last "
                     f"nodes, t in [{span[0]:g}, {span[1]:g}], {(ends and ends.nodes) or 41} "
                     f"nodes")
    else:
        config = scene.resolve({})
        start = (f"p0={_vector(config.p0)}" if config.p0 is not None
                 else f"v0={_vector(config.v0)}")
        lines.append(f"{indent}start: q0={_vector(config.q0)} {start}")
        lines.append(f"{indent}fixed ends: {_boundary(scene)}")
    lines.append(f"{indent}scheme: {scheme}")
    return "\n".join(lines)


def _vector(values) -> str:
    return "[" + ", ".join(f"{v:.6g}" for v in values) + "]"


def _boundary(scene) -> str:
    if scene.boundary is None:
        return "none (give --set q_start=... --set q_end=... --set t_end=... --nodes N)"
    data = scene.resolve_boundary({})
    return (f"q_start={_vector(data.q_start)} q_end={_vector(data.q_end)}, "
            f"t in [{data.t_span[0]:g}, {data.t_span[1]:g}], {data.nodes} nodes")


def run_compare(args) -> int:
    from ..io.work_precision import work_precision
    from ..studies.compare import ERROR_KINDS, CompareOptions, cheapest

    scene = load_scene(args.scene)
    out = args.out or f"runs/{scene.name}-compare"
    if args.horizons:
        return _compare_horizons(args, scene, out)
    rows = work_precision(scene, out=out, overrides=parse_settings(args.settings),
                          options=CompareOptions(methods=args.methods, halvings=args.halvings,
                                                 repeats=args.repeats),
                          compilation=options.compiled_or_not(args),
                          workers=options.workers(args), progress=not args.no_progress)
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
    from ..io.horizons import work_precision_horizons
    from ..studies.compare import CompareOptions

    results = work_precision_horizons(
        scene, args.horizons, out=out, unit=args.time_unit,
        overrides=parse_settings(args.settings),
        options=CompareOptions(methods=args.methods, halvings=args.halvings,
                               repeats=args.repeats, max_steps=args.max_steps),
        compilation=options.compiled_or_not(args), workers=options.workers(args),
        run_budget_s=check_real("--run-budget", args.run_budget, positive=True),
        reference_span=check_real("--reference-span", args.reference_span, positive=True),
        progress=not args.no_progress)
    for horizon, rows in results.items():
        failed = sum(r["status"] != "success" for r in rows)
        print(f"{scene.name} compare, T = {horizon:g}: {len(rows)} runs, {failed} did not reach "
              "t_end")
    print(f"  written to {out}/ (horizons.png, growth.png, horizons.md, horizon_T/)")
    return 0


def run_stress(args) -> int:

    from ..io.stress_report import stress

    with warnings.catch_warnings():
        # the solvability warnings of breaking cases are expected here; stress.md reports them
        warnings.simplefilter("ignore", RuntimeWarning)
        rows = stress(args.out, quick=args.quick,
                      steps=StepControl(max_steps=args.max_steps, time_limit=args.time_limit),
                      compilation=options.compiled_or_not(args),
                      workers=options.workers(args, default=None),
                      progress=not args.no_progress, resume=args.resume)
    status_summary("stress", rows, args.out, "stress")
    return 0


def run_sweep(args) -> int:

    from ..io.stress_report import stress
    from ..studies.sweep import sweep_cases

    spec = _sweep_spec(args)
    cases = sweep_cases(spec)
    out = args.out or f"runs/{load_scene(spec.scene).name}-sweep"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        rows = stress(out, cases=cases,
                      steps=StepControl(max_steps=spec.max_steps, time_limit=spec.time_limit),
                      compilation=options.compiled_or_not(args),
                      workers=options.workers(args, default=None),
                      progress=not args.no_progress, resume=not args.fresh, name="sweep",
                      title=f"Sweep of {spec.scene} over {', '.join(spec.axes)}")
    status_summary("sweep", rows, out, "sweep")
    return 0


def _sweep_spec(args):
    """The sweep of a grid file or of SCENE with --grid axes, with the command line's methods,
    settings and bounds on top."""
    from ..io.grid_file import load_grid_file
    from ..studies.methods import get_methods
    from ..studies.sweep import SweepSpec

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
    spec.settings = {**spec.settings, **parse_settings(args.settings)}
    if args.max_steps is not None:
        spec.max_steps = args.max_steps
    if args.time_limit is not None:
        spec.time_limit = args.time_limit
    return spec


def _grid_axes(items: list[str]) -> dict:
    """``NAME=SPEC`` items of --grid, as axes."""
    from ..studies.sweep import parse_axis

    axes = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name.strip():
            raise InputError(f"--grid expects NAME=SPEC, got {item!r}")
        axes[name.strip()] = parse_axis(name.strip(), text)
    return axes


def run_reproduce(args) -> int:
    from ..io.reproduce import reproduce
    from ..io.runs import prepare_folder

    out = prepare_folder(args.out)
    reproduce(out, quick=args.quick, workers=args.workers or 1, scheduler=args.scheduler)
    print(f"report written to {out / 'report.md'}")
    return 0


def run_scenes(args) -> int:
    print("\n\n".join(_describe(name) for name in list_scenes()))
    return 0
