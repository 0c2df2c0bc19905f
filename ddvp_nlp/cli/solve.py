"""``ddvp march``, ``bvp``, ``periodic`` and ``poincare``: resolve the scene, solve, write the
run folder, print its summary."""

from __future__ import annotations

import sys
from pathlib import Path

from ..discrete.scheme import RULES, Scheme
from ..errors import InputError
from ..scenes import Endpoints, PeriodicSettings, load_scene
from ..solvers.options import GridOptions, Output
from . import options
from .interrupts import INTERRUPTS, Stopped
from .parser import parse_settings
from .summary import print_summary


def run_solve(args) -> int:
    """``ddvp march`` and ``ddvp bvp`` on any scene: resolve, solve, write the run folder and
    print its summary."""
    from ..io.runs import default_folder, prepare_folder, write_run

    scene = load_scene(args.scene)
    higher = _higher(scene)
    args.scheme = _scheme_name(args, scene)
    scheme = _scheme(args, higher)
    overrides = parse_settings(args.settings)
    config = _resolve(args, scene, higher, overrides)
    resolved = dict(_resolved(config))
    if args.command == "bvp":
        if args.nodes is not None:
            overrides["nodes"] = args.nodes
        # the start and the solver can change which solution a bvp returns: a run with
        # another one gets a folder of its own (two runs differing only in --guess shared one)
        for name, value, default in (("guess", args.guess, "straight"),
                                     ("p_start", args.p_start, None),
                                     ("solver", args.solver, "auto")):
            if value != default:
                overrides[name] = resolved[name] = value
    infix = "-bvp" if args.command == "bvp" else ""
    target = args.out if args.out is not None else default_folder(
        f"{scene.name}{infix}-{args.scheme}", resolved, overrides)
    existed = Path(target).exists()
    out = prepare_folder(target)
    args.checkpoint = _checkpoint_saver(args, scene, out)
    if args.command == "march" and not higher:
        INTERRUPTS.mode = "flag"  # the march polls it (stop=) and ends cleanly
    solve = _SOLVERS[args.command, higher]
    try:
        solution, extra = solve(args, scene, config, scheme)
    except KeyboardInterrupt:
        removed = not existed and _remove_if_empty(out)
        raise Stopped("interrupted before the run had a result; nothing was written" +
                      (f" (the empty folder {out}/ is removed)" if removed else
                       f" to {out}/")) from None
    except InputError:
        if not existed:  # a refused run leaves no empty folder behind
            _remove_if_empty(out)
        raise
    with INTERRUPTS.saving():  # a second Ctrl-C or a SIGTERM waits until the set is written
        meta = write_run(out, command=args.command, scene=scene, config=config, scheme=scheme,
                         solution=solution, extra={**(extra or {}), "overrides": overrides},
                         plot=not args.no_plot)
    print_summary(meta, out)
    if INTERRUPTS.pending:
        print(f"ddvp {args.command}: interrupted while saving; the run above was written whole "
              f"to {out}/", file=sys.stderr)
    return 0 if solution.success and not INTERRUPTS.pending else 1


def _remove_if_empty(out) -> bool:
    """Remove the folder ``out`` if nothing but a lock file is in it; whether it was removed."""
    try:
        entries = [entry for entry in out.iterdir() if entry.name != ".ddvp.lock"]
        if entries:
            return False
        for entry in out.iterdir():
            entry.unlink()
        out.rmdir()
        return True
    except OSError:
        return False


def _checkpoint_saver(args, scene, out):
    """For a march of a scene with ``H`` or ``L``: ``save(t, z)`` writing the run so far to
    ``out`` (a checkpoint), interrupts held off while it writes."""
    if args.command != "march" or _higher(scene):
        return None
    from ..io.runs import write_checkpoint

    def save(t, z):
        with INTERRUPTS.saving():
            write_checkpoint(out, command="march", scene_name=scene.name, t=t, z=z,
                             n=scene.system.n)
    return save


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
    from ..solvers.march.solve import march

    if args.scheme not in RULES:
        return _march_method(args, scene, config)

    solution = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                     v0=config.v0, tau0=config.tau0, scheme=scheme, params=config.params,
                     steps=options.step_control(args),
                     accuracy=options.tolerance(args, exact=exact_motion(scene, config)),
                     compilation=options.compilation(args),
                     output=options.march_output(args, checkpoint=args.checkpoint,
                                                 stop=INTERRUPTS.stop_requested))
    stats = solution.stats
    return solution, {key: stats[key] for key in ("path", "fast_steps", "careful_steps",
                                                  "checkpoints")}


def _march_method(args, scene, config):
    """``ddvp march --scheme NAME`` for a compared method (``studies/methods.py``): its run at
    the knob ``tau0`` (``rtol = atol = --tol`` for DOP853), then its own residual check."""
    import numpy as np

    from ..solvers.compiler import find_compiler
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
    from ..solvers.bvp import Shooting, solve_bvp

    p_start = _momentum(args.p_start)
    if p_start is not None and args.guess != "march":
        raise InputError(f"--p-start {args.p_start} is the momentum shooting starts from: give "
                         f"it with --guess march (got --guess {args.guess})")
    progress = args.progress or (config.nodes >= AUTO_PROGRESS_NODES and sys.stderr.isatty())
    guess = Shooting(p_start) if p_start is not None else _bvp_guess(args.guess, scene.system.n)
    solution = solve_bvp(scene.system, config.q_start, config.q_end, config.t_span,
                         nodes=config.nodes, scheme=scheme, params=config.params, guess=guess,
                         options=options.grid_options(args, tol=args.tol),
                         output=Output(progress=progress))
    return solution, {"solver": solution.stats}


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
    """``straight``, ``march``, or the ``t``, ``q``, ``p`` of a ``result.npz`` (or of the one in
    a run folder); ``InputError`` if the file is missing or lacks them."""
    import numpy as np

    if value in ("straight", "march"):
        return value
    path = Path(value)
    path = path / "result.npz" if path.is_dir() else path
    if not path.is_file():
        raise InputError(f"--guess must be straight, march or a result.npz (or run folder), "
                         f"got {value!r}: no such file")
    try:
        with np.load(path, allow_pickle=False) as data:
            guess = {key: data[key] for key in ("t", "q", "p")}
    except (OSError, ValueError, KeyError, AttributeError):
        raise InputError(f"--guess {value!r}: {path} is not a result.npz with t, q and p "
                         f"arrays") from None
    if n is not None and (guess["q"].ndim != 2 or guess["q"].shape[1] != n):
        raise InputError(f"--guess {value!r}: its q has shape {guess['q'].shape}, this scene "
                         f"has n = {n} coordinates")
    return guess


def _march_higher(args, scene, config, scheme):
    from ..solvers.higher.solve import march_higher

    t_init, q_init = scene.start(config)
    return march_higher(scene.system, t_init, q_init, t_end=config.t_end,
                        scheme=scheme.rule, params=config.params, tol=args.tol,
                        max_steps=args.max_steps, time_limit=args.time_limit,
                        accuracy=options.tolerance(args, exact=_higher_exact(scene, config))
                        ), None


def _bvp_higher(args, scene, config, scheme):
    from ..solvers.higher.solve import solve_bvp_higher

    boundary = scene.boundary or Endpoints()
    nodes = args.nodes or boundary.nodes or 41
    t_span = boundary.t_span or (config.t0, config.t_end)
    t_a, q_a, t_b, q_b = scene.ends(config, nodes, t_span)
    return solve_bvp_higher(scene.system, t_a, q_a, t_b, q_b, nodes=nodes,
                            scheme=scheme.rule, params=config.params,
                            options=GridOptions(solver=args.solver, tol=args.tol,
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
    from ..io.periodic_runs import write_family, write_periodic
    from ..io.runs import prepare_folder
    from ..solvers.periodic.family import solve_periodic_family
    from ..solvers.periodic.solve import check_periodic, solve_periodic

    scene = load_scene(args.scene)
    defaults = getattr(scene, "periodic", None) or PeriodicSettings()
    params = parse_settings(args.settings)
    settings = {"section": args.section or defaults.section, "scheme": args.scheme,
                "params": params, "start": defaults.start, "integrals": defaults.integrals,
                "angles": defaults.angles, "options": options.grid_options(args)}
    nodes = args.nodes if args.nodes is not None else defaults.nodes
    guess = _bvp_guess(args.guess) if args.guess else None
    if args.family is not None:
        energies = _family_energies(args.family)
        for energy in (energies[0], energies[-1]):
            check_periodic(scene.system, energy=energy, nodes=nodes, **settings)
        out = prepare_folder(args.out or f"runs/{scene.name}-family")
        family = solve_periodic_family(scene.system, energies, nodes=nodes, guess=guess,
                                       **settings)
        rows = write_family(out, scene, family, params, plot=not args.no_plot)
        for row in rows:
            print(f"E = {row['energy']:<12.6g} {row['status']:14s} T = {row['period']:.10g}  "
                  f"residuals canonical {row['canonical']:.2e}, closure {row['closure']:.2e}")
        print(f"  written to {out}/ (family.csv, family.png, E=... folders)")
        return 0 if all(row["status"] == "success" for row in rows) else 1
    energy = args.energy if args.energy is not None else defaults.energy
    if energy is None:
        raise InputError(f"--energy is needed: scene {scene.name!r} declares no default energy")
    check_periodic(scene.system, energy=energy, nodes=nodes, **settings)
    out = prepare_folder(args.out or f"runs/{scene.name}-periodic")
    solution = solve_periodic(scene.system, energy=energy, nodes=nodes, guess=guess,
                              **settings)
    meta = write_periodic(out, scene, solution, params, plot=not args.no_plot)
    print(f"{scene.name} periodic [{meta['scheme']}]: {meta['status']} - {meta['message']}\n"
          f"  period {meta['period']:.12g} at E = {meta['energy']:.10g}, N = {meta['nodes']}; "
          f"written to {out}/")
    if solution.stats.get("accuracy"):
        from ..solvers.accuracy import describe

        accuracy = solution.stats["accuracy"]
        print(f"  accuracy check: {accuracy['verdict']} ({describe(accuracy)})")
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


def run_poincare(args) -> int:
    """``ddvp poincare``: the starts on the section, one ensemble, its crossings written."""
    from pathlib import Path

    from ..io.poincare_runs import write_section
    from ..studies.poincare import poincare_section
    from ..validation import check_integer, check_real

    scene = load_scene(args.scene)
    config = scene.resolve({})
    energy = check_real("--energy", args.energy)
    orbits = check_integer("--orbits", args.orbits)
    workers = check_integer("--workers", args.workers)
    section = poincare_section(scene.system, energy, section=args.section, orbits=orbits,
                               direction=args.direction, workers=workers, scene=args.scene,
                               scheduler=args.scheduler,
                               tau0=args.tau0 if args.tau0 is not None else config.tau0,
                               t_end=args.t_end if args.t_end is not None else config.t_end,
                               params=parse_settings(args.settings), seed=args.seed,
                               accuracy=options.tolerance(args))
    out = Path(args.out or f"runs/{scene.name}-poincare-E{args.energy:g}")
    write_section(out, section, plot=not args.no_plot)
    failed = sum(status != "reached t_end" for status in section.statuses)
    verdicts = [verdict for verdict, _ in section.verdicts]
    print(f"{len(section.statuses)} orbits, {section.points.shape[0]} crossings of "
          f"{args.section}; {failed} orbits failed; largest nodal energy error "
          f"{section.energy_errors.max():.2e}")
    print("  accuracy check of each orbit: " + ", ".join(
        f"{verdicts.count(v)} {v}" for v in ("accurate", "drifted", "inaccurate")) +
        " (orbits.csv: each orbit's verdict and t_drift)")
    print(f"  written to {out}/ (section.npz, section.csv, orbits.csv, section.png)")
    return 0 if failed == 0 else 1
