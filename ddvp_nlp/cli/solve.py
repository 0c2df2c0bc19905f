"""``ddvp march``, ``bvp``, ``periodic`` and ``poincare``: resolve the scene, solve, write the
run folder, print its summary."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

from ..discrete import RULES, Scheme
from ..errors import InputError
from ..scenes import Endpoints, PeriodicSettings, load_scene
from ..solution import Status
from ..solvers import Output
from . import arguments as options
from .arguments import check_grid_memory, family_energies
from .folders import default_or, holds
from .interrupts import INTERRUPTS, Stopped
from .parser import parse_settings
from .summary import print_summary


def run_solve(args) -> int:
    """``ddvp march`` and ``ddvp bvp`` on any scene: resolve, solve, write the run folder and
    print its summary."""
    from ..io.atomic import output_folder

    if getattr(args, "resume", None):
        if args.t_eval is not None or args.events:
            raise InputError("--t-eval and --event apply to a march from its start, not to "
                             "--resume (the crossings before the resumed node are not "
                             "searched again)")
        return run_resume(args)
    if args.scene is None:
        raise InputError(f"ddvp {args.command} needs a scene (a name from `ddvp scenes` or a "
                         ".py file)" + (", or --resume FOLDER" if args.command == "march" else ""))
    if getattr(args, "t_end", None) is not None:  # ran silently to the scene's t_end before
        args.settings = [*args.settings, f"t_end={args.t_end!r}"]
    scene = load_scene(args.scene)
    higher = _higher(scene)
    args.scheme = _scheme_name(args, scene)
    scheme = _scheme(args, higher)
    overrides = parse_settings(args.settings)
    config = _resolve(args, scene, higher, overrides)
    target, owned, overrides = _run_folder(args, scene, config, overrides)
    with output_folder(target, owned=owned) as out:
        args.checkpoint = _checkpoint_saver(args, scene, out, resume_record(args, scene,
                                                                            overrides))
        try:
            solution, extra = _SOLVERS[args.command, higher](args, scene, config, scheme)
        except KeyboardInterrupt:
            raise Stopped(f"interrupted ({INTERRUPTS.name or 'SIGINT'}) before the run had a "
                          f"node to keep; nothing new was written: {holds(out)}") from None
        meta = _save(args, out, scene, config, scheme, solution,
                     {**(extra or {}), "overrides": overrides})
    print_summary(meta, out.path)
    print_requested(meta, solution)
    if INTERRUPTS.requested:
        kept = f"{meta['nodes']} nodes, up to t = {meta['t_reached']:.10g}"
        print(f"ddvp {args.command}: interrupted ({INTERRUPTS.name}); the run was written whole "
              f"to {out.path}/ ({kept})", file=sys.stderr)
    return 0 if solution.success and not INTERRUPTS.requested else 1


def _save(args, out, scene, config, scheme, solution, extra) -> dict:
    """The run's set written with interrupts held (only the figure may be cut short); on a
    write failure, what the folder holds is said."""
    from ..errors import OutputError
    from ..io.run_folder import write_run

    try:
        with INTERRUPTS.saving():
            return write_run(out, command=args.command, scene=scene, config=config,
                             scheme=scheme, solution=solution, extra=extra,
                             plot=not args.no_plot, interruptible=INTERRUPTS.interruptible,
                             figure_format=args.figure_format)
    except OutputError as exc:
        raise OutputError.because(exc, f"the run ({solution.steps} steps) was not saved; "
                                       f"{holds(out)}") from None


def _run_folder(args, scene, config, overrides):
    """The output folder (``--out``, else the default named by every setting that changes
    the result), how many of its trailing components ddvp chose, and the overrides recorded
    in ``meta.json``."""
    from ..io.run_folder import default_folder

    resolved = dict(_resolved(config))
    if args.command == "bvp":
        if args.nodes is not None:
            overrides["nodes"] = args.nodes
        # the start and the solver can change which solution a bvp returns: a run with
        # another one gets a folder of its own (two runs differing only in --guess shared one)
        for name, value, default in (("guess", args.guess, "straight"),
                                     ("p_start", args.p_start, None),
                                     ("solver", args.solver, "auto"),
                                     ("energy", args.energy, None)):
            if value != default:
                overrides[name] = resolved[name] = value
    options = result_options(args)
    resolved.update(options)
    if args.out is not None:
        return args.out, 1, overrides
    infix = "-bvp" if args.command == "bvp" else ""
    return default_folder(f"{scene.name}{infix}-{args.scheme}", resolved,
                          {**overrides, **options}), 2, overrides


# Options of march and bvp that change the result, with their defaults: a run that changes one
# gets a folder of its own (--alpha, --clock and --tol had shared the default one).
RESULT_OPTIONS = {"alpha": 0.5, "clock": "midpoint", "tol": 1e-10, "tau_min": None,
                  "tau_max": None, "max_step_ratio": 10.0, "max_steps": 10_000_000,
                  "time_limit": None, "energy_guard": None, "least_squares": False,
                  "rtol": 1e-2, "atol": None, "energy_tol": 0.1, "global_tol": 1e-2,
                  "require_accurate": False, "accept_inaccurate": False, "careful": False}


def result_options(args) -> dict:
    """The options of ``args`` in `RESULT_OPTIONS` whose value is not the default."""
    return {name: getattr(args, name) for name, default in RESULT_OPTIONS.items()
            if hasattr(args, name) and getattr(args, name) != default}


def _checkpoint_saver(args, scene, out, record: dict):
    """For a march of a scene with ``H`` or ``L``: ``save(t, z, carried)`` writing the run so
    far to ``out`` (a checkpoint, with what ``--resume`` needs), interrupts held off while it
    writes."""
    if args.command != "march" or _higher(scene):
        return None
    from ..io.run_folder import write_checkpoint

    def save(t, z, carried):  # called from the march's checkpoint thread: the main thread polls
        write_checkpoint(out, command="march", scene_name=scene.name, t=t, z=z,
                         n=scene.system.n, extra={"carried": carried, "resume": record})
    return save


# What `ddvp march --resume` reads back to rebuild the run's options exactly (the bounds
# --max-steps and --time-limit, the checkpoints, progress and plot are the resuming command's).
RESUME_OPTIONS = ("scheme", "alpha", "clock", "tol", "tau_min", "tau_max", "max_step_ratio",
                  "energy_guard", "least_squares", "rtol", "atol", "energy_tol", "global_tol",
                  "accept_inaccurate", "careful")


def resume_record(args, scene, overrides: dict) -> dict:
    """The scene (name or file), the ``--set`` overrides and the march's options."""
    return {"scene": scene.source or scene.name, "overrides": overrides,
            "options": {name: getattr(args, name, None) for name in RESUME_OPTIONS}}


def run_resume(args) -> int:
    """``ddvp march --resume FOLDER [--t-end T]``: the march in ``FOLDER`` (its last checkpoint
    or its finished run) continued to its ``t_end`` or a later one, with the options it ran
    with, written back to ``FOLDER``; the nodes are an uninterrupted run's bit for bit."""
    from ..io.atomic import output_folder
    from ..io.run_folder import read_run
    from ..solvers import MarchState, continue_march

    arrays, meta = read_run(args.resume)
    record = meta.get("resume")
    if meta.get("command") != "march" or not isinstance(record, dict):
        raise InputError(f"--resume: {args.resume} holds no march this ddvp can continue "
                         f"(command {meta.get('command')!r}, no resume record)")
    if meta.get("status") not in RESUMABLE:
        raise InputError(f"--resume: the run in {args.resume} ended with status "
                         f"{meta.get('status')!r}; only {', '.join(RESUMABLE)} can be continued")
    for name, value in record["options"].items():
        setattr(args, name, value)
    scene = load_scene(record["scene"])
    scheme = _scheme(args, False)
    config = scene.resolve(record["overrides"])
    t_end = config.t_end if args.t_end is None else args.t_end
    state = MarchState.of(arrays["t"], arrays["q"], arrays["p"], config.t_end,
                          meta.get("carried"))
    with output_folder(args.resume, owned=0) as out:
        saver = _checkpoint_saver(args, scene, out, record)
        solution = continue_march(
            scene.system, state, t_end, tau0=config.tau0, scheme=scheme, params=config.params,
            steps=options.step_control(args), accuracy=options.tolerance(args),
            compilation=options.compilation(args),
            output=options.march_output(args, checkpoint=saver,
                                        stop=INTERRUPTS.stop_requested))
        config.t_end = t_end
        extra = {"carried": solution.stats["carried"], "resume": record,
                 "resumed_from": {"nodes": int(state.t.size), "t": float(state.t[-1])},
                 "overrides": record["overrides"]}
        meta = _save(args, out, scene, config, scheme, solution, extra)
    print_summary(meta, out.path)
    return 0 if solution.success and not INTERRUPTS.requested else 1


# Statuses of a march that --resume continues: a checkpoint, a stop, a bound, a finished run.
RESUMABLE = ("running", "interrupted", "max_steps", "time_limit", "success")


def _higher(scene) -> bool:
    from ..scenes import HigherOrderScene

    return isinstance(scene, HigherOrderScene)


def _scheme_name(args, scene) -> str:
    """``--scheme``, else the scheme the scene declares, else the paper's ``vddvp``; a scene's
    declared name is checked here, where the names are known."""
    if args.scheme is not None:
        return args.scheme
    declared = getattr(scene, "scheme", None)
    if declared is None:
        return Scheme().rule
    known = RULES if args.command == "bvp" else RULES + _method_names()
    if declared not in known:
        raise InputError(f"scene {scene.name!r} declares scheme {declared!r}, which ddvp "
                         f"{args.command} does not know (known: {', '.join(known)})")
    return declared


def exact_motion(scene, config):
    """The scene's exact solution through the run's start as ``exact(t) -> z`` (rows), for the
    accuracy check, or ``None`` (no exact solution, a start it does not cover, a start from
    ``v0`` whose ``p0`` the march computes)."""
    import numpy as np

    if scene.exact is None or getattr(config, "p0", None) is None:
        return None
    q0, p0, t0, params = config.q0, config.p0, config.t0, config.params
    try:
        scene.exact(np.array([t0]), q0, p0, t0, **params)
    except ValueError:
        return None

    def exact(t):
        q, p = scene.exact(np.asarray(t, float), q0, p0, t0, **params)
        return np.hstack([np.reshape(q, (np.size(t), -1)), np.reshape(p, (np.size(t), -1))])
    return exact


def _method_names() -> tuple:
    from ..studies.methods import METHODS

    return tuple(name for name in METHODS if name not in RULES)


def _resolved(config) -> dict:
    """The resolved settings of a run as plain values (what the folder's hash is taken of)."""
    return config.as_dict()


def _scheme(args, higher: bool) -> Scheme:
    if higher and (args.alpha != 0.5 or args.clock != "midpoint"):
        raise InputError("--alpha and --clock do not apply to a higher-order Lagrangian "
                         "(differences are taken at the left node)")
    if args.scheme not in RULES:  # a compared method: its interval energies as fixed steps'
        return Scheme(rule="fixed")
    return Scheme(rule=args.scheme, alpha=args.alpha, clock=args.clock)


def _resolve(args, scene, higher: bool, settings: dict):
    if args.command == "bvp" and not higher:
        return scene.resolve_boundary(settings, nodes=args.nodes)
    return scene.resolve(settings)


def _march(args, scene, config, scheme):
    from ..solvers import march

    times, events = requested_output(args, scene, config)
    if args.scheme not in RULES:
        if times is not None or events:
            raise InputError(f"--t-eval and --event use the dense output of the scheme's own "
                             f"march; --scheme {args.scheme} is a compared method")
        return _march_method(args, scene, config)

    solution = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                     v0=config.v0, tau0=config.tau0, scheme=scheme, params=config.params,
                     steps=options.step_control(args),
                     accuracy=options.tolerance(args, exact=exact_motion(scene, config)),
                     compilation=options.compilation(args),
                     output=options.march_output(args, checkpoint=args.checkpoint,
                                                 stop=INTERRUPTS.stop_requested,
                                                 t_eval=times, events=events))
    stats = solution.stats
    return solution, {**{key: stats[key] for key in ("path", "fast_steps", "careful_steps",
                                                     "checkpoints", "checkpoints_landed_s")
                         if key in stats},
                      "carried": stats["carried"],
                      "resume": resume_record(args, scene, parse_settings(args.settings)),
                      **requested_meta(solution, events)}


def _march_method(args, scene, config):
    """``ddvp march --scheme NAME`` for a compared method (``studies/methods.py``): its run at
    the knob ``tau0`` (``rtol = atol = --tol`` for DOP853), then its own residual check."""
    import numpy as np

    from ..solvers import find_compiler
    from ..studies.methods import METHODS, run_method

    method = METHODS[args.scheme]
    value = args.tol if method.knob == "rtol" else config.tau0
    solution = run_method(scene, config, args.scheme, value,
                          compiler=None if args.careful else find_compiler("auto"),
                          max_steps=args.max_steps, time_limit=args.time_limit, tol=args.tol,
                          tolerance=options.tolerance(args,
                                                      exact=exact_motion(scene, config)))
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
    from ..solvers import AtEnergy, Shooting, solve_bvp
    from .stability import transfer_note

    p_start = _momentum(args.p_start)
    if p_start is not None and args.guess != "march":
        raise InputError(f"--p-start {args.p_start} is the momentum shooting starts from: give "
                         f"it with --guess march (got --guess {args.guess})")
    progress = args.progress if args.progress is not None else (
        config.nodes >= AUTO_PROGRESS_NODES and sys.stderr.isatty())
    guess = Shooting(p_start) if p_start is not None else _bvp_guess(args.guess, scene.system.n)
    span = config.t_span
    if args.energy is not None:  # the scene's span is the transfer time's guess
        span = AtEnergy(args.energy, t0=span[0], duration=span[1] - span[0])
    solution = solve_bvp(scene.system, config.q_start, config.q_end, span,
                         nodes=config.nodes, scheme=scheme, params=config.params, guess=guess,
                         options=options.grid_options(args, tol=args.tol),
                         output=Output(progress=progress))
    extra = {"solver": solution.stats}
    if args.energy is not None and "transfer_time" in solution.stats:
        extra["note"] = transfer_note(solution.stats)
    return solution, extra


# A bvp of at least this many nodes reports its iterations on a terminal without --progress
# (Newton takes about 1 s an iteration at 1e6 nodes; a 1e7-node solve ran silently).
AUTO_PROGRESS_NODES = 100_000


def _momentum(text: str | None):
    """``--p-start``'s comma-separated numbers (``None`` if not given)."""
    if text is None:
        return None
    try:
        return [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"--p-start must be comma-separated numbers, got {text!r}") from None


def _bvp_guess(value: str, n: int | None = None):
    """``straight``, ``march``, or the ``t``, ``q``, ``p`` of a run folder's last complete
    set, or of a ``result.npz`` file (checked: a zip of real, finite arrays, ``t`` increasing,
    ``q`` and ``p`` of shape ``(N, n)``; beside a ``meta.json``, the file that one describes);
    ``InputError`` naming the file and the reason otherwise."""
    import numpy as np

    from ..io.run_folder import META, check_run_arrays, read_run
    from ..validation import check_file_size

    if value in ("straight", "march"):
        return value
    path = Path(value)
    if path.is_dir() or (path.name == "result.npz" and (path.parent / META).exists()):
        try:
            arrays, _ = read_run(path if path.is_dir() else path.parent)
        except InputError as exc:
            raise InputError(f"--guess {value!r}: {exc}") from None
    else:
        if not path.is_file():
            raise InputError(f"--guess must be straight, march or a result.npz (or run "
                             f"folder), got {value!r}: no such file")
        check_file_size(f"--guess {value!r}", path.stat().st_size)
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {key: data[key] for key in ("t", "q", "p")}
        except Exception:  # not a zip, not npy, a missing array, a pickled object
            raise InputError(f"--guess {value!r}: {path} is not a result.npz with t, q and p "
                             f"arrays") from None
    check_run_arrays(f"--guess {value!r}", arrays)
    guess = {key: np.asarray(arrays[key], dtype=float) for key in ("t", "q", "p")}
    if n is not None and guess["q"].shape[1] != n:
        raise InputError(f"--guess {value!r}: its q has shape {guess['q'].shape}, this scene "
                         f"has n = {n} coordinates")
    return guess


def requested_output(args, scene, config):
    """``(t_eval, events)`` of ``--t-eval`` and ``--event`` (``cli/events.py``), checked
    against the scene's names and the run's span."""
    from .events import parse_event, parse_times

    times = None if args.t_eval is None else parse_times(args.t_eval, (config.t0,
                                                                       config.t_end))
    events = [parse_event(text, scene.system.n, config.params) for text in args.events]
    return times, events


def requested_meta(solution, events) -> dict:
    """``meta.json``'s record of the output times and each event's crossings (the arrays are
    in ``result.npz``: ``t_eval``, ``z_eval``, ``t_events_K``, ``z_events_K``)."""
    meta = {}
    if solution.t_eval is not None:
        meta["t_eval"] = {"count": int(solution.t_eval.size),
                          "first": float(solution.t_eval[0]) if solution.t_eval.size else None,
                          "last": float(solution.t_eval[-1]) if solution.t_eval.size else None}
    if events:
        meta["events"] = [{**event.describe(), "count": int(times.size),
                           "times": [float(t) for t in times[:EVENT_TIMES_IN_META]]}
                          for event, times in zip(events, solution.t_events, strict=True)]
    return meta


# Crossing times listed in meta.json per event (all of them are in result.npz).
EVENT_TIMES_IN_META = 20


def print_requested(meta: dict, solution) -> None:
    """A line for the output times and one per event."""
    if "t_eval" in meta:
        told = meta["t_eval"]
        print(f"  t_eval: the state at {told['count']} times"
              + (f" from {told['first']:.10g} to {told['last']:.10g}" if told["count"] else "")
              + " (result.npz: t_eval, z_eval)")
    for k, event in enumerate(meta.get("events", ())):
        times = event["times"]
        where = (f", first at t = {times[0]:.12g}" if times else "")
        ended = (" - ended the march" if solution.status is Status.EVENT
                 and event["terminal"] and event["count"] >= event["terminal"] else "")
        plural = "" if event["count"] == 1 else "s"
        print(f"  event {k} '{event['expression']}' ({event['direction']}): "
              f"{event['count']} crossing{plural}{where}{ended} (result.npz: t_events_{k}, "
              f"z_events_{k})")


def _march_higher(args, scene, config, scheme):
    from ..solvers import march_higher

    if args.t_eval is not None or args.events:
        raise InputError(f"--t-eval and --event are not available for the higher-order scene "
                         f"{scene.name!r} (its march has no dense output)")
    t_init, q_init = scene.start(config)
    return march_higher(scene.system, t_init, q_init, config.t_end, scheme=scheme.rule,
                        params=config.params, steps=options.step_control(args),
                        accuracy=options.tolerance(args, exact=_higher_exact(scene, config))
                        ), None


def _bvp_higher(args, scene, config, scheme):
    from ..solvers import solve_bvp_higher

    if args.energy is not None:
        raise InputError(f"--energy: scene {scene.name!r} is a higher-order scene; a transfer at "
                         f"a prescribed energy needs a Hamiltonian (or first-order Lagrangian) "
                         f"scene")
    boundary = scene.boundary or Endpoints()
    nodes = args.nodes or boundary.nodes or 41
    t_span = boundary.t_span or (config.t0, config.t_end)
    t_a, q_a, t_b, q_b = scene.ends(config, nodes, t_span)
    return solve_bvp_higher(scene.system, t_a, q_a, t_b, q_b, nodes=nodes,
                            scheme=scheme.rule, params=config.params,
                            options=replace(options.grid_options(args, tol=args.tol),
                                            accuracy=options.tolerance(
                                                args, exact=_higher_exact(scene, config)))
                            ), None


def _higher_exact(scene, config):
    """A higher-order scene's exact motion as ``exact(t) -> q`` (rows), for the check."""
    return lambda t: scene.exact_motion(t, config.params)


# (command, higher-order scene) -> the solve: (args, scene, config, scheme) -> (solution, extra)
_SOLVERS = {("march", False): _march, ("bvp", False): _bvp,
            ("march", True): _march_higher, ("bvp", True): _bvp_higher}


def run_periodic(args) -> int:
    """``ddvp periodic``: one orbit (a run folder) or a family (``family.csv``, a folder per
    energy); every input checked before anything is built."""
    from ..solvers import check_periodic
    from .stability import scene_guess

    scene = load_scene(args.scene)
    defaults = getattr(scene, "periodic", None) or PeriodicSettings()
    params = parse_settings(args.settings)
    scene.resolve({k: v for k, v in params.items() if k in scene.params})  # ranges, names
    settings = {"section": args.section or defaults.section, "scheme": args.scheme,
                "params": params, "start": defaults.start, "integrals": defaults.integrals,
                "angles": defaults.angles, "options": options.grid_options(args)}
    nodes = args.nodes if args.nodes is not None else defaults.nodes
    guess = _bvp_guess(args.guess, scene.system.n) if args.guess else None
    named = {"nodes": nodes, "section": settings["section"], "scheme": args.scheme,
             "solver": args.solver, "params": params, "guess": args.guess}
    if args.follow is not None or args.stability:
        from .stability import run_periodic_stability

        return run_periodic_stability(args, scene, settings, nodes, guess, params, named)
    if args.family is not None:
        energies = family_energies(args.family, scene.system.n, nodes)
        guess = guess or scene_guess(scene, energies[0], params)
        for energy in (energies[0], energies[-1]) if guess is None else ():
            check_periodic(scene.system, energy=energy, nodes=nodes, **settings)
        return _periodic_family(args, scene, energies, nodes, guess, settings,
                                {**named, "family": args.family})
    energy = args.energy if args.energy is not None else defaults.energy
    if energy is None:
        raise InputError(f"--energy is needed: scene {scene.name!r} declares no default energy")
    guess = guess or scene_guess(scene, energy, params)
    if guess is None:
        check_periodic(scene.system, energy=energy, nodes=nodes, **settings)
    check_grid_memory("--nodes", nodes, scene.system.n, 1)
    return _periodic_orbit(args, scene, energy, nodes, guess, settings,
                           {**named, "energy": energy}, defaults)


def _periodic_orbit(args, scene, energy, nodes, guess, settings, named, defaults) -> int:
    from ..io.atomic import output_folder
    from ..io.orbit_files import write_periodic
    from ..solvers import solve_periodic

    target, owned = default_or(args, f"{scene.name}-periodic", named, {
        "nodes": defaults.nodes, "section": defaults.section, "scheme": "vddvp",
        "solver": "auto", "params": {}, "guess": None, "energy": defaults.energy})
    with output_folder(target, owned=owned) as out:
        try:
            solution = solve_periodic(scene.system, energy=energy, nodes=nodes, guess=guess,
                                      **settings)
        except KeyboardInterrupt:
            raise Stopped(f"interrupted ({INTERRUPTS.name or 'SIGINT'}) while solving; nothing "
                          f"new was written: {holds(out)}") from None
        with INTERRUPTS.saving():
            meta = write_periodic(out, scene, solution, settings["params"],
                                  plot=not args.no_plot, interruptible=INTERRUPTS.interruptible)
    print(f"{scene.name} periodic [{meta['scheme']}]: {meta['status']} - {meta['message']}\n"
          f"  period {meta['period']:.12g} at E = {meta['energy']:.10g}, N = {meta['nodes']}; "
          f"written to {out.path}/")
    if solution.stats.get("accuracy"):
        from ..solvers import describe

        accuracy = solution.stats["accuracy"]
        print(f"  accuracy check: {accuracy['verdict']} ({describe(accuracy)})")
    return 0 if solution.success and not INTERRUPTS.requested else 1


def _periodic_family(args, scene, energies, nodes, guess, settings, named) -> int:
    from ..io.atomic import output_folder
    from ..io.orbit_files import write_family
    from ..solvers import solve_periodic_family

    target, owned = default_or(args, f"{scene.name}-family", named, {})
    with output_folder(target, owned=owned) as out:
        try:
            family = solve_periodic_family(scene.system, energies, nodes=nodes, guess=guess,
                                           **settings)
        except KeyboardInterrupt:
            raise Stopped(f"interrupted ({INTERRUPTS.name or 'SIGINT'}) while solving the "
                          f"family; nothing new was written: {holds(out)}") from None
        with INTERRUPTS.saving():
            rows = write_family(out, scene, family, settings["params"], plot=not args.no_plot,
                                section=settings["section"],
                                interruptible=INTERRUPTS.interruptible)
    for row in rows:
        print(f"E = {row['energy']:<12.6g} {row['status']:14s} T = {row['period']:.10g}  "
              f"residuals canonical {row['canonical']:.2e}, closure {row['closure']:.2e}")
    print(f"  written to {out.path}/ (family.csv, family.png, E=... folders)")
    return 0 if all(row["status"] == "success" for row in rows) and not INTERRUPTS.requested \
        else 1


def run_poincare(args) -> int:
    """``ddvp poincare``: the starts on the section, one ensemble, its crossings written."""
    from ..io.atomic import output_folder
    from ..io.section_files import write_section
    from ..studies.poincare import poincare_section
    from ..validation import check_memory

    scene = load_scene(args.scene)
    params = parse_settings(args.settings)
    config = scene.resolve({k: v for k, v in params.items() if k in scene.params})
    tau0 = args.tau0 if args.tau0 is not None else config.tau0
    t_end = args.t_end if args.t_end is not None else config.t_end
    n = scene.system.n
    check_memory("--orbits", args.orbits, args.orbits * (2 * n * 8.0 * 64 + 4096),
                 "the orbits' starts and results")
    if args.t_end is not None and not t_end > 0:
        raise InputError(f"--t-end must be > 0 (the orbits start at t = 0), got {t_end!r}")
    named = {"orbits": args.orbits, "section": args.section, "direction": args.direction,
             "t_end": args.t_end, "tau0": args.tau0, "seed": args.seed, "params": params}
    target, owned = default_or(args, f"{scene.name}-poincare-E{args.energy:g}", named, {
        "orbits": 50, "section": "q1=0", "direction": "+", "t_end": 2000.0, "tau0": None,
        "seed": 0, "params": {}})
    with output_folder(target, owned=owned) as out:
        try:
            section = poincare_section(scene.system, args.energy, section=args.section,
                                       orbits=args.orbits, direction=args.direction,
                                       workers=args.workers, scene=args.scene,
                                       scheduler=args.scheduler, tau0=tau0, t_end=t_end,
                                       params=params, seed=args.seed,
                                       progress=args.progress is not False,
                                       accuracy=options.tolerance(args))
        except KeyboardInterrupt:
            raise Stopped(f"interrupted ({INTERRUPTS.name or 'SIGINT'}) while the orbits ran "
                          "(a section is written once all its orbits are done); nothing new "
                          f"was written: {holds(out)}") from None
        with INTERRUPTS.saving():
            write_section(out, section, plot=not args.no_plot,
                          interruptible=INTERRUPTS.interruptible)
    failed = sum(status != "success" for status in section.statuses)
    verdicts = [verdict for verdict, _ in section.verdicts]
    print(f"{len(section.statuses)} orbits, {section.points.shape[0]} crossings of "
          f"{args.section}; {failed} orbits failed; largest nodal energy error "
          f"{section.energy_errors.max():.2e}")
    print("  accuracy check of each orbit: " + ", ".join(
        f"{verdicts.count(v)} {v}" for v in ("accurate", "drifted", "inaccurate")) +
        " (orbits.csv: each orbit's verdict and t_drift)")
    print(f"  written to {out.path}/ (section.npz, section.csv, orbits.csv, section.png)")
    return 0 if failed == 0 and not INTERRUPTS.requested else 1
