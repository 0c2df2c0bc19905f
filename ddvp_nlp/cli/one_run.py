"""One run of a scene into a folder, shared by ``ddvp march`` and ``ddvp bvp``: the scene and its
settings resolved, the output times and events parsed, the folder named by every input that
changes the result (the settings, ``--t-eval``, ``--event``, a scene file's and a guess file's
content), the solve, the run written whole (interrupts held), the summary printed."""

from __future__ import annotations

import shlex
import sys

from ..discrete import RULES, Scheme
from ..errors import InputError, OutputError
from ..io.atomic import output_folder
from ..io.run_folder import default_folder, read_guess, write_checkpoint, write_run
from ..scenes import HigherOrderScene, is_builtin, load_scene, scene_fingerprint
from ..solution import Status
from .events import parse_event, parse_times
from .folders import content_inputs, holds
from .interrupts import INTERRUPTS, Stopped
from .parser import parse_settings
from .summary import print_summary


def run_scene(args, solvers: dict) -> int:
    """``ddvp march`` or ``ddvp bvp`` on a scene: resolve, solve, write the run folder, print
    its summary. ``solvers[higher]`` is the solve ``(args, scene, config, scheme) ->
    (solution, extra)`` of a first-order (``False``) or higher-order (``True``) scene."""
    if args.scene is None:
        raise InputError(f"ddvp {args.command} needs a scene (a name from `ddvp scenes` or a "
                         ".py file)" + (", or --resume FOLDER" if args.command == "march" else ""))
    if args.t_end is not None:  # ran silently to the scene's t_end before
        args = args.but(settings=[*args.settings, f"t_end={args.t_end!r}"])
    scene = load_scene(args.scene)
    higher = isinstance(scene, HigherOrderScene)
    args = args.but(scheme=scheme_name(args, scene))
    scheme = scheme_of(args, higher)
    overrides = parse_settings(args.settings)
    config = resolve(args, scene, higher, overrides)
    args = args.but(requested=requested_output(args, scene, config, higher))  # before a folder
    if args.command == "bvp" and args.guess not in ("straight", "march"):
        args = args.but(guess_data=read_guess(args.guess, scene.system.n))  # checked now; names
    target, owned, overrides = run_folder(args, scene, config, overrides)
    with output_folder(target, owned=owned) as out:
        args = args.but(checkpoint=checkpoint_saver(args, scene, out, resume_record(
            args, scene, config, overrides)))
        try:
            solution, extra = solvers[higher](args, scene, config, scheme)
        except KeyboardInterrupt:
            raise Stopped(f"interrupted ({INTERRUPTS.name or 'SIGINT'}) before the run had a "
                          f"node to keep; nothing new was written: {holds(out)}") from None
        if INTERRUPTS.requested and len(solution.t) < 2:
            # its start alone is not a run (a run folder holds at least one step; the faults
            # page found "written whole (1 nodes, up to t = 0)" beside an unreadable result)
            raise Stopped(f"interrupted ({INTERRUPTS.name}) before the run's first step; "
                          f"nothing new was written: {holds(out)}")
        meta = write_whole(args, out, scene, config, scheme, solution,
                        {**(extra or {}), "overrides": overrides})
    print_summary(meta, out.path)
    print_requested(meta, solution)
    if INTERRUPTS.requested:
        print(f"ddvp {args.command}: interrupted ({INTERRUPTS.name}); the run was written whole "
              f"to {out.path}/ ({interrupted_words(args, meta, solution, out.path)})",
              file=sys.stderr)
    return 0 if solution.success and not INTERRUPTS.requested else 1


def interrupted_words(args, meta: dict, solution, path) -> str:
    """What an interrupted run kept and how to go on: the command that resumes it (the scene
    file named, since a run folder never runs the file it names), or, when the interrupt came
    after the run had reached its end, that there is nothing to resume."""
    kept = f"{meta['nodes']} nodes, up to t = {meta['t_reached']:.10g}"
    if solution.success:
        return f"{kept}; the run had reached its end before the interrupt: nothing to resume"
    if args.command != "march" or not meta.get("resume"):
        return kept
    named = args.scene or meta.get("scene", "")
    scene = "" if is_builtin(named) else f" {shlex.quote(str(named))}"
    return f"{kept}; `ddvp march{scene} --resume {path}` goes on from there"


def write_whole(args, out, scene, config, scheme, solution, extra) -> dict:
    """The run's set written with interrupts held (only the figure may be cut short); on a
    write failure, what the folder holds is said."""
    try:
        with INTERRUPTS.saving():
            return write_run(out, command=args.command, scene=scene, config=config,
                             scheme=scheme, solution=solution, extra=extra,
                             plot=not args.no_plot, interruptible=INTERRUPTS.interruptible,
                             figure_format=args.figure_format)
    except OutputError as exc:
        raise OutputError.because(exc, f"the run ({solution.steps} steps) was not saved; "
                                       f"{holds(out)}") from None


# The start and the solver can change which solution a bvp returns: a run with another one
# gets a folder of its own (two runs differing only in --guess shared one).
BVP_CHOICES = ("guess", "p_start", "solver", "energy")


def run_folder(args, scene, config, overrides):
    """The output folder (``--out``, else the default named by every setting that changes
    the result), how many of its trailing components ddvp chose, and the overrides recorded
    in ``meta.json``."""
    resolved = dict(config.as_dict())
    if args.command == "bvp":
        if args.nodes is not None:
            overrides["nodes"] = args.nodes
        for name, value in args.changed(BVP_CHOICES).items():
            overrides[name] = resolved[name] = value
    options = {**result_options(args), **requested_options(args),
               **content_inputs(scene, args.guess_data)}
    resolved.update(options)
    if args.out is not None:
        return args.out, 1, overrides
    infix = "-bvp" if args.command == "bvp" else ""
    return default_folder(f"{scene.name}{infix}-{args.scheme}", resolved,
                          {**overrides, **options}), 2, overrides


# Options of march and bvp that change the result: a run that changes one from its default
# gets a folder of its own (--alpha, --clock and --tol had shared the default one).
RESULT_OPTIONS = ("alpha", "clock", "tol", "tau_min", "tau_max", "max_step_ratio", "max_steps",
                  "time_limit", "energy_guard", "least_squares", "rtol", "atol", "energy_tol",
                  "global_tol", "require_accurate", "accept_inaccurate", "careful", "keep_every",
                  "keep", "target_error")


def requested_options(args) -> dict:
    """``--t-eval`` and ``--event`` as given, when given: they add arrays to the run."""
    found = {}
    if args.t_eval is not None:
        found["t_eval"] = args.t_eval
    if args.events:
        found["events"] = list(args.events)
    return found


def result_options(args) -> dict:
    """The options of ``args`` in `RESULT_OPTIONS` whose value is not their default."""
    return args.changed(RESULT_OPTIONS)


def checkpoint_saver(args, scene, out, record: dict):
    """For a march of a scene with ``H`` or ``L``: ``save(t, z, carried)`` writing the run so
    far to ``out`` (a checkpoint, with what ``--resume`` needs), interrupts held off while it
    writes."""
    if args.command != "march" or isinstance(scene, HigherOrderScene):
        return None

    def save(t, z, carried):  # called from the march's checkpoint thread: the main thread polls
        write_checkpoint(out, command="march", scene_name=scene.name, t=t, z=z,
                         n=scene.system.n, extra={"carried": carried, "resume": record})
    return save


# What `ddvp march --resume` reads back to rebuild the run's options exactly (the bounds
# --max-steps and --time-limit, the checkpoints, progress and plot are the resuming command's).
RESUME_OPTIONS = ("scheme", "alpha", "clock", "tol", "tau_min", "tau_max", "max_step_ratio",
                  "energy_guard", "least_squares", "rtol", "atol", "energy_tol", "global_tol",
                  "accept_inaccurate", "careful")


def resume_record(args, scene, config, overrides: dict) -> dict:
    """The scene (name or file), the SHA-256 of its file, the fingerprint of its file and the
    resolved settings (`scene_fingerprint`: what ``--resume`` checks the scene it is given
    against), the ``--set`` overrides and the march's options."""
    return {"scene": scene.source or scene.name, "scene_sha256": scene.digest,
            "fingerprint": scene_fingerprint(scene, config.as_dict()), "overrides": overrides,
            "options": {**dict.fromkeys(RESUME_OPTIONS), **args.having(RESUME_OPTIONS)}}


def scheme_name(args, scene) -> str:
    """``--method``, else ``--scheme``, else the scheme the scene declares, else the paper's
    ``vddvp``; a scene's declared name is checked here, where the names are known."""
    method = args.method
    if args.scheme is not None and args.scheme not in RULES:
        if args.scheme in method_names():
            raise InputError(f"--scheme {args.scheme}: {args.scheme} is a compared method, not an "
                             f"energy rule ({', '.join(RULES)}); give --method {args.scheme}")
        raise InputError(f"--scheme must be one of {', '.join(RULES)}, got {args.scheme!r}")
    if method is not None and args.scheme is not None:
        raise InputError(f"give --scheme (an energy rule) or --method (a compared method), not "
                         f"both (got --scheme {args.scheme} --method {method})")
    if method is not None or args.scheme is not None:
        return method or args.scheme
    declared = getattr(scene, "scheme", None)
    if declared is None:
        return Scheme().rule
    known = RULES if args.command == "bvp" else RULES + method_names()
    if declared not in known:
        raise InputError(f"scene {scene.name!r} declares scheme {declared!r}, which ddvp "
                         f"{args.command} does not know (known: {', '.join(known)})")
    return declared


def method_names() -> tuple:
    """The compared methods ``ddvp march --method`` runs (every method but the energy rules;
    ``parser.COMPARED_METHODS``, held equal to the registry by a test)."""
    from .parser import COMPARED_METHODS

    return COMPARED_METHODS


def scheme_of(args, higher: bool) -> Scheme:
    """The `Scheme` of the run (``fixed`` for a compared method: its interval energies are
    those of fixed steps)."""
    if higher and (args.alpha != args.default("alpha")
                   or args.clock != args.default("clock")):
        raise InputError("--alpha and --clock do not apply to a higher-order Lagrangian "
                         "(differences are taken at the left node)")
    if args.scheme not in RULES:
        return Scheme(rule="fixed")
    return Scheme(rule=args.scheme, alpha=args.alpha, clock=args.clock)


def resolve(args, scene, higher: bool, settings: dict):
    """The run's resolved settings: the boundary data of a bvp, else the march's."""
    if args.command == "bvp" and not higher:
        return scene.resolve_boundary(settings, nodes=args.nodes)
    return scene.resolve(settings)


def requested_output(args, scene, config, higher: bool):
    """``(t_eval, events)`` of ``--t-eval`` and ``--event`` (``cli/events.py``), checked
    against the scene's names and the run's span, before a folder is made or anything is
    built; ``(None, [])`` when neither is given."""
    t_eval, texts = args.t_eval, list(args.events)
    if t_eval is None and not texts:
        return None, []
    if higher:
        raise InputError(f"--t-eval and --event are not available for the higher-order scene "
                         f"{scene.name!r} (its march has no dense output)")
    if args.scheme not in RULES:
        raise InputError(f"--t-eval and --event use the dense output of the scheme's own "
                         f"march; --method {args.scheme} is a compared method")
    times = None if t_eval is None else parse_times(t_eval, (config.t0, config.t_end))
    events = [parse_event(text, scene.system.n, config.params) for text in texts]
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
