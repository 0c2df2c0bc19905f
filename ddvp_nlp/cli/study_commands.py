"""``ddvp compare``, ``stress``, ``sweep``, ``reproduce`` and ``scenes``: the commands that run
many solves (through ``studies/``) and write their reports (through ``io/``)."""

from __future__ import annotations

import sys
import warnings

from ..errors import InputError
from ..io.atomic import output_folder
from ..runner.journal import JournalInterrupted
from ..scenes import load_scene
from ..solvers import StepControl
from ..studies.comparison import compare
from ..studies.horizons import check_horizons, parse_horizons
from ..studies.horizons_report import horizons_study
from ..studies.methods import get_methods
from ..studies.reproduce import reproduce
from ..studies.stress_report import stress
from ..studies.sweep import SweepSpec, parse_axis, sweep_cases
from ..studies.sweep_file import load_grid_file
from ..studies.work_precision import ERROR_KINDS, CompareOptions, cheapest
from ..validation import check_real
from . import arguments as options
from .arguments import check_distinct
from .flags import flags
from .folders import default_or
from .interrupts import INTERRUPTS, Stopped
from .parser import parse_settings
from .summary import status_summary


def _grid_ended(command: str, rows: list[dict]) -> int:
    """0 if any task of the grid succeeded, 1 if every one failed (a sweep whose every task
    failed had exited 0), said on stderr."""
    if rows and not any(r["status"] == "success" for r in rows):
        print(f"ddvp {command}: every one of the {len(rows)} runs failed", file=sys.stderr)
        return 1
    return 0


def _interrupted(exc) -> Exception:
    """A grid's interrupt as the command's stop, with what was kept (the grid's message)."""
    return Stopped(str(exc) or "interrupted; nothing new was written")


def run_compare(args) -> int:

    scene = load_scene(args.scene)
    settings = parse_settings(args.settings)
    config = scene.resolve(settings)  # every name and value checked before a folder is made
    if args.horizons is not None:
        check_horizons(parse_horizons(args.horizons), args.time_unit, config)
    checked = CompareOptions(methods=args.methods, halvings=args.halvings, repeats=args.repeats,
                             target_errors=options.target_errors(args.target_errors))
    if checked.methods is not None:
        get_methods(checked.methods)
    named = {"settings": settings, "methods": args.methods, "halvings": args.halvings,
             "repeats": args.repeats, "no_compile": args.no_compile,
             "horizons": args.horizons, "time_unit": args.time_unit,
             "max_steps": args.max_steps, "run_budget": args.run_budget,
             "reference_span": args.reference_span, "target_errors": args.target_errors}
    target, owned = default_or(args, f"{scene.name}-compare", named,
                               options=[name for name in named if name != "settings"],
                               defaults={"settings": {}}, scene=scene)
    if args.horizons:
        with output_folder(target, owned=owned) as out, flags("comparison"):
            return _compare_horizons(args, scene, out)
    try:
        with output_folder(target, owned=owned) as out, flags("comparison"):
            # the Python compare itself, into the command's folder
            result = compare(scene, params=settings, options=checked,
                             compilation=options.compiled_or_not(args),
                             workers=options.workers(args), out=out,
                             progress=args.progress is not False,
                             interruptible=INTERRUPTS.interruptible)
    except JournalInterrupted as exc:
        raise _interrupted(exc) from None
    with INTERRUPTS.saving():  # written: a signal now ends it as interrupted (exit 1)
        return _compare_summary(scene, result, out)


def _compare_summary(scene, result, out) -> int:
    rows = result.rows
    failed = len(result.failed)
    print(f"{scene.name} compare: {len(rows)} runs, {failed} did not reach t_end")
    for kind, label in ERROR_KINDS.items():
        for level in (1e-4, 1e-8):
            ranking = cheapest(rows, kind, level)
            if ranking:
                name, seconds, bound = ranking[0]
                print(f"  {label.split(' max')[0]} <= {level:.0e}: cheapest {name} "
                      f"({'at most ' if bound else ''}{seconds * 1e3:.3g} ms)")
    print(f"  written to {out.path}/ (work_precision.csv, work_precision.png, summary.md)")
    return _grid_ended("compare", rows)


def _compare_horizons(args, scene, out) -> int:

    try:
        study = horizons_study(
            scene, args.horizons, out=out, unit=args.time_unit,
            overrides=parse_settings(args.settings),
            options=CompareOptions(methods=args.methods, halvings=args.halvings,
                                   repeats=args.repeats, max_steps=args.max_steps,
                                   target_errors=options.target_errors(args.target_errors)),
            compilation=options.compiled_or_not(args), workers=options.workers(args),
            run_budget_s=args.run_budget, reference_span=args.reference_span,
            progress=args.progress is not False)
    except JournalInterrupted as exc:
        raise _interrupted(exc) from None
    for horizon, result in study.results.items():
        rows = result.rows
        failed = sum(r["status"] != "success" for r in rows)
        print(f"{scene.name} compare, T = {horizon:g}: {len(rows)} runs, {failed} did not reach "
              "t_end")
    if len(study.results) > 1:
        print("  cheapest method along the horizons (wall time, best of repeats):")
        for line in study.crossover_words():
            print("   " + line.removeprefix("-"))
    print(f"  written to {out.path}/ (horizons.png, crossover.png, growth.png, horizons.md, "
          "horizon_T/)")
    return _grid_ended("compare", study.rows)


def run_stress(args) -> int:

    named = {"quick": args.quick, "max_steps": args.max_steps,
             "time_limit": args.time_limit, "no_compile": args.no_compile}
    target, owned = default_or(args, "stress", named, options=list(named))
    try:
        with output_folder(target, owned=owned) as out, warnings.catch_warnings():
            # the solvability warnings of breaking cases are expected here; stress.md says so
            warnings.simplefilter("ignore", RuntimeWarning)
            rows = stress(out, quick=args.quick,
                          steps=StepControl(max_steps=args.max_steps,
                                            time_limit=args.time_limit),
                          compilation=options.compiled_or_not(args),
                          workers=options.workers(args, default=None),
                          progress=args.progress is not False, resume=args.resume,
                          interruptible=INTERRUPTS.interruptible)
    except JournalInterrupted as exc:
        raise _interrupted(exc) from None
    with INTERRUPTS.saving():  # written: a signal now ends it as interrupted (exit 1), the
        # files whole, not "before anything was written"
        status_summary("stress", rows, out.path, "stress")
        return _grid_ended("stress", rows)


def run_sweep(args) -> int:

    spec = _sweep_spec(args)
    cases = sweep_cases(spec)
    named = {"scene": spec.scene, "axes": spec.axes, "methods": list(spec.methods),
             "settings": spec.settings, "max_steps": spec.max_steps,
             "time_limit": spec.time_limit, "no_compile": args.no_compile}
    scene = load_scene(spec.scene)
    target, owned = default_or(args, f"{scene.name}-sweep", named, scene=scene)
    try:
        with output_folder(target, owned=owned) as out, warnings.catch_warnings(), \
                flags("comparison"):
            warnings.simplefilter("ignore", RuntimeWarning)
            rows = stress(out, cases=cases,
                          steps=StepControl(max_steps=spec.max_steps,
                                            time_limit=spec.time_limit),
                          compilation=options.compiled_or_not(args),
                          workers=options.workers(args, default=None),
                          progress=args.progress is not False, resume=not args.fresh, name="sweep",
                          title=f"Sweep of {spec.scene} over {', '.join(spec.axes)}",
                          interruptible=INTERRUPTS.interruptible)
    except JournalInterrupted as exc:
        raise _interrupted(exc) from None
    with INTERRUPTS.saving():  # written: a signal now ends it as interrupted (exit 1), the
        # files whole, not "before anything was written"
        status_summary("sweep", rows, out.path, "sweep")
        return _grid_ended("sweep", rows)


def _sweep_spec(args):
    """The sweep of a grid file or of SCENE with --grid axes, with the command line's methods,
    settings and bounds on top; a scene file named inside a grid file only if the command line
    allows it (--allow-scene): a grid file runs no code the user did not name."""
    if args.file:
        if args.scene or args.grid:
            raise InputError("give either --file or SCENE with --grid, not both")
        with flags("load_grid_file"):
            spec = load_grid_file(args.file, allowed=args.allow_scene)
    else:
        if not args.scene or not args.grid:
            raise InputError("sweep needs SCENE and at least one --grid NAME=SPEC (or --file)")
        spec = SweepSpec(scene=args.scene, axes=_grid_axes(args.grid))
    if args.methods is not None:
        spec.methods = tuple(m.name for m in get_methods(args.methods))
    spec.settings = {**spec.settings, **parse_settings(args.settings)}
    if args.max_steps is not None:
        spec.max_steps = args.max_steps
    if args.time_limit is not None:
        spec.time_limit = args.time_limit
    StepControl(max_steps=spec.max_steps, time_limit=spec.time_limit)  # named checks

    for name, values in spec.axes.items():
        for value in values:
            check_real(f"grid axis {name}", value)
        check_distinct(f"grid axis {name}", values)
    clash = sorted(set(spec.settings) & set(spec.axes))
    if clash:
        raise InputError(f"{clash[0]!r} is both a grid axis and a fixed setting (--set or "
                         "[settings]); give it once")
    return spec


def _grid_axes(items: list[str]) -> dict:
    """``NAME=SPEC`` items of --grid, as axes: finite values, none twice, each name once."""
    axes = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name.strip():
            raise InputError(f"--grid expects NAME=SPEC, got {item!r}")
        name = name.strip()
        if name in axes:
            raise InputError(f"--grid {name} is given twice; give each axis once")
        with flags("parse_axis"):
            values = parse_axis(name, text)
        for value in values:
            check_real(f"--grid {name}", value)
        check_distinct(f"--grid {name}", values)
        axes[name] = values
    return axes


def run_reproduce(args) -> int:

    target, owned = default_or(args, "reproduce", {"quick": args.quick}, options=["quick"])
    with output_folder(target, owned=owned) as out:
        reproduce(out, quick=args.quick, workers=args.workers or 1, scheduler=args.scheduler)
    print(f"report written to {out.path / 'report.md'}")
    return 0


