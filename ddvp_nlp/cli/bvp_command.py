"""``ddvp bvp``: a fixed-endpoint problem on a scene's boundary data (or a transfer at a
prescribed energy with ``--energy``), solved on the whole grid."""

from __future__ import annotations

import sys
from dataclasses import replace

from ..errors import InputError
from ..io.run_folder import read_guess
from ..scenes import Endpoints
from ..solvers import AtEnergy, Output, Shooting, solve_bvp
from . import arguments as options
from .one_run import run_scene


def run_bvp(args) -> int:
    """``ddvp bvp SCENE``."""
    return run_scene(args, {False: _bvp, True: _bvp_higher})


def _bvp(args, scene, config, scheme):
    p_start = _momentum(args.p_start)
    if p_start is not None and args.guess != "march":
        raise InputError(f"--p-start {args.p_start} is the momentum shooting starts from: give "
                         f"it with --guess march (got --guess {args.guess})")
    progress = args.progress if args.progress is not None else (
        config.nodes >= AUTO_PROGRESS_NODES and sys.stderr.isatty())
    guess = Shooting(p_start) if p_start is not None else (
        args.guess_data or read_guess(args.guess, scene.system.n))
    span = config.t_span
    if args.energy is not None:  # the scene's span is the transfer time's guess
        span = AtEnergy(args.energy, t0=span[0], duration=span[1] - span[0])
    solution = solve_bvp(scene.system, config.q_start, config.q_end, span,
                         nodes=config.nodes, scheme=scheme, params=config.params, guess=guess,
                         options=options.grid_options(args),
                         output=Output(progress=progress))
    extra = {"solver": solver_record(solution)}
    if args.energy is not None and solution.transfer is not None:
        extra["note"] = transfer_note(solution.transfer)
    return solution, extra


def solver_record(solution) -> dict:
    """``meta.json``'s ``solver``: the solve's stats with its verdict (``accuracy``) where
    the file has always had it, before what the solve added after judging (``exact``,
    ``fixed_time_start``)."""
    stats = solution.written_stats()
    if solution.verdict is None:
        return stats
    later = {key: stats.pop(key) for key in ("exact", "fixed_time_start") if key in stats}
    return {**stats, "accuracy": solution.verdict.as_dict(), **later}


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


def _bvp_higher(args, scene, config, scheme):
    from ..solvers import solve_bvp_higher  # the higher-order family loads only for its scenes

    if args.energy is not None:
        raise InputError(f"--energy: scene {scene.name!r} is a higher-order scene; a transfer at "
                         f"a prescribed energy needs a Hamiltonian (or first-order Lagrangian) "
                         f"scene")
    boundary = scene.boundary or Endpoints()
    nodes = scene.boundary_nodes(args.nodes)
    t_span = boundary.t_span or (config.t0, config.t_end)
    t_a, q_a, t_b, q_b = scene.ends(config, nodes, t_span)
    return solve_bvp_higher(scene.system, t_a, q_a, t_b, q_b, nodes=nodes,
                            scheme=scheme.rule, params=config.params,
                            options=replace(options.grid_options(args),
                                            accuracy=options.tolerance(
                                                args, exact=scene.exact_positions(config)))
                            ), None


def transfer_note(transfer) -> str:
    """One line on a transfer at a prescribed energy and its check by shooting."""
    exact = transfer.exact or {}
    text = f"transfer time {transfer.transfer_time:.12g} at energy {transfer.energy:.10g}"
    if exact.get("converged"):
        text += (f"; the exact flow's shooting: {exact['transfer_time']:.12g} (difference "
                 f"{exact['time_difference']:.2e}), path difference {exact['path_difference']:.2e}")
    elif exact:
        text += "; the exact flow's shooting did not converge from this transfer"
    return text
