"""``ddvp march``: an initial-value problem on a scene (an energy rule, or a compared method
with ``--method``), and ``--resume``, its continuation from a run folder."""

from __future__ import annotations

import numpy as np

from ..discrete import RULES
from ..errors import InputError
from ..io.atomic import output_folder
from ..io.run_folder import read_run
from ..scenes import load_scene
from ..solvers import MarchState, continue_march, find_compiler, march
from . import arguments as options
from .interrupts import INTERRUPTS
from .one_run import (
    checkpoint_saver,
    requested_meta,
    requested_output,
    resume_record,
    run_one,
    save_run,
    scheme_of,
)
from .parser import parse_settings
from .summary import print_summary


def run_march(args) -> int:
    """``ddvp march SCENE`` or ``ddvp march --resume FOLDER``."""
    if args.resume:
        if args.t_eval is not None or args.events:
            raise InputError("--t-eval and --event apply to a march from its start, not to "
                             "--resume (the crossings before the resumed node are not "
                             "searched again)")
        return run_resume(args)
    return run_one(args, {False: _march, True: _march_higher})


def run_resume(args) -> int:
    """``ddvp march --resume FOLDER [--t-end T]``: the march in ``FOLDER`` (its last checkpoint
    or its finished run) continued to its ``t_end`` or a later one, with the options it ran
    with, written back to ``FOLDER``; the nodes are an uninterrupted run's bit for bit."""
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
    scheme = scheme_of(args, False)
    config = scene.resolve(record["overrides"])
    t_end = config.t_end if args.t_end is None else args.t_end
    state = MarchState.of(arrays["t"], arrays["q"], arrays["p"], config.t_end,
                          meta.get("carried"))
    with output_folder(args.resume, owned=0) as out:
        saver = checkpoint_saver(args, scene, out, record)
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
        meta = save_run(args, out, scene, config, scheme, solution, extra)
    print_summary(meta, out.path)
    return 0 if solution.success and not INTERRUPTS.requested else 1


# Statuses of a march that --resume continues: a checkpoint, a stop, a bound, a finished run.
RESUMABLE = ("running", "interrupted", "max_steps", "time_limit", "success")


def _march(args, scene, config, scheme):
    times, events = requested_output(args, scene, config)
    if args.scheme not in RULES:
        if times is not None or events:
            raise InputError(f"--t-eval and --event use the dense output of the scheme's own "
                             f"march; --method {args.scheme} is a compared method")
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
    stats = solution.stats
    return solution, {**{key: stats[key] for key in ("path", "fast_steps", "careful_steps",
                                                     "fallbacks", "first_fallback",
                                                     "target_error",
                                                     "checkpoints", "checkpoints_landed_s")
                         if key in stats},
                      "carried": stats["carried"],
                      "resume": resume_record(args, scene, parse_settings(args.settings)),
                      **requested_meta(solution, events)}


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
             "own_residual_max": solution.stats.get("own_residual_max"),
             "path": solution.stats.get("path")}
    if not scene.system.time_dependent and solution.t.size:
        # a compared method keeps no interval energy: its energy error is H's drift at the nodes
        H = scene.system.energy(solution.q, solution.p, solution.t,
                                scene.system.parameter_vector(config.params))
        extra.update(energy_error=float(np.max(np.abs(H - H[0]))),
                     energy_error_kind="largest drift of H at the nodes, max |H(z_k) - H(z_0)|")
    return solution, extra


def _march_higher(args, scene, config, scheme):
    from ..solvers import march_higher  # the grid families load only for a higher-order scene

    if args.t_eval is not None or args.events:
        raise InputError(f"--t-eval and --event are not available for the higher-order scene "
                         f"{scene.name!r} (its march has no dense output)")
    t_init, q_init = scene.start(config)
    return march_higher(scene.system, t_init, q_init, config.t_end, scheme=scheme.rule,
                        params=config.params, steps=options.step_control(args),
                        accuracy=options.tolerance(args, exact=scene.exact_positions(config))
                        ), None
