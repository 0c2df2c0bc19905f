"""``ddvp march``: an initial-value problem on a scene (an energy rule, or a compared method
with ``--method``), and ``--resume``, its continuation from a run folder."""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import math
import os

import numpy as np

from ..discrete import RULES
from ..errors import InputError, OutputError
from ..io.atomic import FolderBusy, open_folder
from ..io.run_folder import read_run
from ..scenes import is_builtin, load_scene, scene_digest, scene_fingerprint
from ..solvers import MarchState, continue_march, find_compiler, march
from ..validation import check_real
from . import arguments as options
from .arguments import check_options
from .interrupts import INTERRUPTS
from .one_run import (
    RESUME_OPTIONS,
    checkpoint_saver,
    requested_meta,
    resume_record,
    run_scene,
    scheme_of,
    write_whole,
)
from .parser import parse_settings
from .summary import print_summary


def run_march_command(args) -> int:
    """``ddvp march SCENE`` or ``ddvp march --resume FOLDER``."""
    if args.resume:
        if args.t_eval is not None or args.events:
            raise InputError("--t-eval and --event apply to a march from its start, not to "
                             "--resume (the crossings before the resumed node are not "
                             "searched again)")
        if _thinned(args):
            raise InputError("--keep-every and --keep apply to a march from its start: a "
                             "thinned run cannot be continued with --resume")
        return run_resume(args)
    if args.keep == "t_eval" and args.t_eval is None and not args.events:
        raise InputError("--keep t_eval keeps only the --t-eval states and the --event "
                         "crossings: give --t-eval or --event")
    if _thinned(args) and args.changed(["checkpoint_every"]):
        # asked for, the checkpoints would otherwise be left out without a word
        raise InputError(f"--checkpoint-every {args.checkpoint_every:g} does not apply to a "
                         "thinned march (--keep-every or --keep t_eval): a checkpoint is for "
                         "--resume, which needs every node; give one or the other")
    return run_scene(args, {False: _march, True: _march_higher})


def run_resume(args) -> int:
    """``ddvp march [SCENE] --resume FOLDER [--t-end T]``: the march in ``FOLDER`` (its last
    checkpoint or its finished run) continued to its ``t_end`` or a later one, with the options
    it ran with, written back to ``FOLDER``; the nodes are an uninterrupted run's bit for bit.

    The folder is data, never code or authority: the system is rebuilt from ``SCENE`` on the
    command line (or from the built-in scene the run names; a scene file it names is never
    run), and only if that scene's file and the run's settings have the fingerprint the run
    recorded (`scene_fingerprint`); the recorded options are the march's own names, each
    checked as the command line checks it. The folder is locked before it is read: a folder
    that another ddvp process is writing is busy (exit 2)."""
    folder = args.resume
    if not os.path.isdir(folder):
        raise InputError(f"--resume {folder}: no such folder (give the folder of a march)")
    with _locked(folder) as out:
        arrays, meta = read_run(folder)
        record = resume_record_of(folder, meta)
        scene = resume_scene(args, folder, record)
        args = args.but(**record["options"])  # the options the run was made with
        try:
            check_options(args)
        except InputError as exc:  # the folder's value, not one the user typed: say so
            raise InputError(f"--resume {folder}: the run's recorded options are refused "
                             f"(meta.json resume.options; not a value given on this command "
                             f"line): {exc}") from None
        if args.scheme not in RULES:
            raise InputError(f"--resume: the resume record of {folder} gives the scheme "
                             f"{args.scheme!r}; a march continues with one of {', '.join(RULES)}")
        scheme = scheme_of(args, False)
        config = scene.resolve(record["overrides"])
        found = scene_fingerprint(scene, config.as_dict())
        if found != record["fingerprint"]:
            raise InputError(
                f"--resume {folder}: the scene {args.scene or record['scene']!r} with the run's "
                f"settings (fingerprint {found[:16]}) is not what the run was computed from "
                f"({record['scene']!r}, fingerprint {record['fingerprint'][:16]}): its file or "
                "its settings changed; start a new march instead")
        if arrays["q"].shape[1] != scene.system.n:
            raise InputError(f"--resume {folder}: the run has {arrays['q'].shape[1]} "
                             f"coordinates, the scene {scene.name!r} has {scene.system.n}")
        t_end = config.t_end if args.t_end is None else args.t_end
        state = MarchState.of(arrays["t"], arrays["q"], arrays["p"], config.t_end,
                              checked_carried(folder, meta.get("carried")))
        saver = checkpoint_saver(args, scene, out, record)
        tau0, accuracy = _resumed_step(folder, meta, config.tau0, options.tolerance(args))
        solution = continue_march(
            scene.system, state, t_end, tau0=tau0, scheme=scheme, params=config.params,
            steps=options.step_control(args), accuracy=accuracy,
            compilation=options.compilation(args),
            output=options.march_output(args, checkpoint=saver,
                                        stop=INTERRUPTS.stop_requested))
        config.t_end = t_end
        extra = {"carried": solution.march.carried, "resume": record,
                 "resumed_from": {"nodes": int(state.t.size), "t": float(state.t[-1])},
                 "overrides": record["overrides"]}
        meta = write_whole(args, out, scene, config, scheme, solution, extra)
    print_summary(meta, out.path)
    return 0 if solution.success and not INTERRUPTS.requested else 1


@contextlib.contextmanager
def _locked(folder):
    """The run folder opened and locked for this process before anything of it is read; a
    folder another ddvp process holds is busy: an `InputError` (exit 2), not a half-read
    run."""
    try:
        out = open_folder(folder, owned=0)
    except OutputError as exc:
        if exc.errno == errno.EBUSY:
            raise FolderBusy(f"--resume {folder}: the folder is busy: {exc}") from None
        raise
    try:
        yield out
    finally:
        out.close()


# Statuses of a march that --resume continues: a checkpoint, a stop, a bound, a finished run.
RESUMABLE = ("running", "interrupted", "max_steps", "time_limit", "success")


def resume_record_of(folder, meta: dict) -> dict:
    """The run's resume record, checked as data: the scene it names (a string), the
    ``--set`` overrides (names to numbers or lists of numbers), the march's options (only
    `RESUME_OPTIONS`) and the scene's fingerprint."""
    record = meta.get("resume")
    if meta.get("command") != "march" or not isinstance(record, dict):
        raise InputError(f"--resume: {folder} holds no march this ddvp can continue "
                         f"(command {meta.get('command')!r}, no resume record)")
    kept = meta.get("kept")
    if isinstance(kept, dict) and (kept.get("keep_every") != 1 or kept.get("keep") != "nodes"):
        raise InputError(f"--resume: the run in {folder} kept only some of its nodes "
                         f"(keep_every {kept.get('keep_every')!r}, keep {kept.get('keep')!r}): "
                         "a march goes on only from consecutive nodes; start a new march")
    if meta.get("status") not in RESUMABLE:
        raise InputError(f"--resume: the run in {folder} ended with status "
                         f"{meta.get('status')!r}; only {', '.join(RESUMABLE)} can be continued")
    scene, overrides = record.get("scene"), record.get("overrides")
    given, fingerprint = record.get("options"), record.get("fingerprint")
    if not isinstance(fingerprint, str) or len(fingerprint) != 64:
        raise InputError(f"--resume: the run in {folder} records no fingerprint of its scene "
                         "(written by an older ddvp): it cannot be checked against a scene, so "
                         "it is not continued; start a new march")
    if not isinstance(scene, str) or not isinstance(overrides, dict) or \
            not isinstance(given, dict):
        raise InputError(f"--resume: the resume record of {folder} is not one ddvp wrote")
    for name, value in overrides.items():
        if not isinstance(name, str) or not _numbers(value):
            raise InputError(f"--resume: the resume record of {folder} sets {name!r} to "
                             f"{value!r}, which is not a number or a list of numbers")
    unknown = sorted(set(given) - set(RESUME_OPTIONS))
    if unknown:
        raise InputError(f"--resume: the resume record of {folder} names the option "
                         f"{unknown[0]!r}, which --resume does not take from a run")
    kinds = {"scheme": str, "clock": str, "least_squares": bool, "careful": bool,
             "accept_inaccurate": bool}
    for name, value in given.items():
        kind = kinds.get(name)
        fine = isinstance(value, kind) if kind else (
            value is None or (isinstance(value, (int, float)) and not isinstance(value, bool)))
        if not fine:
            raise InputError(f"--resume: the resume record of {folder} gives {name} = "
                             f"{value!r}, not what ddvp march takes")
    return record


def _numbers(value) -> bool:
    if isinstance(value, list):
        return 0 < len(value) <= 1 << 20 and all(_numbers(v) for v in value)
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def resume_scene(args, folder, record: dict):
    """The scene a resumed march is rebuilt from: ``SCENE`` of the command line, else the
    built-in scene the run names; a scene file is never run because a file names it (the
    user names it). The named file's content is checked against the run's before it runs."""
    named = args.scene
    if named is None:
        if not is_builtin(record["scene"]):
            raise InputError(
                f"--resume {folder}: the run was made from the scene file "
                f"{record['scene'][:200]!r}; name it on the command line (ddvp march SCENE "
                "--resume FOLDER): ddvp runs no scene file that a run folder names")
        named = record["scene"]
    digest = record.get("scene_sha256")
    if isinstance(digest, str) and scene_digest(named) != digest:
        raise InputError(
            f"--resume {folder}: the scene {named!r} (SHA-256 {scene_digest(named)[:16]}) is "
            f"not the file the run was computed from ({record['scene'][:200]!r}, SHA-256 "
            f"{digest[:16]}); it was not run. Give that scene, or start a new march")
    return load_scene(named)


def checked_carried(folder, carried):
    """The march's carried state as the run recorded it, checked: a finite drift and two
    counts."""
    if not isinstance(carried, dict):
        return carried  # MarchState.of says what is missing
    drift, left, phase = (carried.get(k) for k in ("drift", "careful_left", "phase"))
    counts = all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 1 << 31
                 for v in (left, phase))
    if not (isinstance(drift, (int, float)) and not isinstance(drift, bool)
            and math.isfinite(drift)) or not counts:
        raise InputError(f"--resume: the carried state of {folder} ({carried!r:.200}) is not "
                         "one ddvp wrote (a finite drift and two counts)")
    return carried


def _march(args, scene, config, scheme):
    times, events = args.requested  # checked by run_scene before the folder was made
    if args.scheme not in RULES:
        if _thinned(args):
            raise InputError(f"--keep-every and --keep thin a march of this package's schemes; "
                             f"--method {args.scheme} is a compared method")
        if args.target_error is not None:
            raise InputError(f"--target-error chooses the step of this package's schemes; "
                             f"--method {args.scheme} is a compared method (ddvp compare runs "
                             f"it over its knob)")
        return _march_method(args, scene, config)

    solution = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                     v0=config.v0, tau0=config.tau0, scheme=scheme, params=config.params,
                     steps=options.step_control(args),
                     accuracy=options.tolerance(args, exact=scene.exact_states(config)),
                     compilation=options.compilation(args),
                     output=options.march_output(args, checkpoint=args.checkpoint,
                                                 stop=INTERRUPTS.stop_requested,
                                                 t_eval=times, events=events),
                     target_error=args.target_error)
    stats = solution.written_stats()
    return solution, {**{key: stats[key] for key in ("path", "fast_steps", "careful_steps",
                                                     "fallbacks", "first_fallback",
                                                     "target_error",
                                                     "checkpoints", "checkpoints_landed_s",
                                                     "kept")
                         if key in stats},
                      **({"accuracy_skipped": solution.accuracy_skipped}
                         if solution.accuracy_skipped is not None else {}),
                      **_all_residuals(solution.march.kept),
                      "carried": solution.march.carried,
                      "resume": resume_record(args, scene, config,
                                              parse_settings(args.settings)),
                      **requested_meta(solution, events)}


def _resumed_step(folder, meta: dict, tau0: float, accuracy):
    """``(tau0, accuracy)`` a resumed march goes on with: the scene's, or for a run that chose
    its own first step for a target error (``--target-error``) the step it chose and the
    tolerance it was judged by (the scene's ``tau0`` did not make its first step)."""
    chosen = meta.get("target_error")
    if not isinstance(chosen, dict) or "target" not in chosen:
        return tau0, accuracy
    if chosen.get("tau0") is None:
        raise InputError(f"--resume {folder}: this --target-error run chose no step (its pilot "
                         "march ended before a run was made): start a new march")
    step = check_real("the run's chosen tau0 (meta.json target_error)", chosen["tau0"],
                      positive=True)
    target = check_real("the run's target error (meta.json target_error)", chosen["target"],
                        positive=True)
    return step, dataclasses.replace(accuracy, global_tol=target)


def _thinned(args) -> bool:
    """Whether ``--keep-every`` or ``--keep t_eval`` was given."""
    return args.keep_every is not None or args.keep != "nodes"


def _all_residuals(kept: dict | None) -> dict:
    """A thinned march's largest residuals over every step, not only the kept ones."""
    if not kept:
        return {}
    return {"canonical_residual_max": kept["canonical_residual_max"],
            "energy_residual_max": kept["energy_residual_max"]}


def _march_method(args, scene, config):
    """``ddvp march --method NAME`` for a compared method (``studies/methods.py``): its run at
    the knob ``tau0`` (``rtol = atol = --tol`` for DOP853), then its own residual check."""
    from ..studies.methods import METHODS, run_method  # the baselines load only for a method

    method = METHODS[args.scheme]
    value = args.tol if method.knob == "rtol" else config.tau0
    solution = run_method(scene, config, args.scheme, value,
                          compiler=None if args.careful else find_compiler("auto"),
                          max_steps=args.max_steps, time_limit=args.time_limit, tol=args.tol,
                          tolerance=options.tolerance(args, exact=scene.exact_states(config)))
    extra = {"scheme": args.scheme, "method": method.description, "knob": {method.knob: value},
             "own_residual_max": solution.own_residual_max,
             "path": solution.stats.get("path")}
    if not scene.system.time_dependent and solution.t.size:
        # a compared method keeps no interval energy: its energy error is H's drift at the nodes
        H = scene.system.energy(solution.q, solution.p, solution.t,
                                scene.system.parameter_vector(config.params))
        extra.update(energy_error=float(np.max(np.abs(H - H[0]))),
                     energy_error_kind="largest drift of H at the nodes, max |H(z_k) - H(z_0)|")
    return solution, extra


def _march_higher(args, scene, config, scheme):
    if _thinned(args):
        raise InputError(f"--keep-every and --keep thin a march of a first-order scene; "
                         f"{scene.name!r} is a higher-order scene")
    from ..solvers import march_higher  # the grid families load only for a higher-order scene

    t_init, q_init = scene.start(config)
    return march_higher(scene.system, t_init, q_init, config.t_end, scheme=scheme.rule,
                        params=config.params, steps=options.step_control(args),
                        accuracy=options.tolerance(args, exact=scene.exact_positions(config))
                        ), None
