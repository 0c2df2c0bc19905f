"""``ddvp chaos``: a chaos map (MEGNO and the largest Lyapunov exponent of every cell of a grid
on a section at a fixed energy), its cells run as one ensemble on local workers or a cluster,
or one shard of them (``--shard K/N``, a SLURM array task), or the shards' parts joined
(``--merge DIR``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.atomic import output_folder
from ..io.chaos_files import arrays_writer, plot_chaos
from ..io.run_folder import figure_writer
from ..runner.journal import JournalInterrupted, commit_journal
from ..scenes import load_scene
from ..studies.chaos_map import (
    COLUMNS,
    chaos_map,
    map_arrays,
    merge_shards,
    parse_grid,
    parse_shard,
    shard_folder,
)
from .flags import flags
from .folders import default_or, holds
from .interrupts import INTERRUPTS, Stopped
from .parser import parse_settings


def run_chaos(args) -> int:
    """``ddvp chaos``: check everything, run the cells (or merge the shards), write the set."""
    if args.merge is not None:
        return _merge(args)
    missing = [flag for flag, value in (("SCENE", args.scene), ("--energy", args.energy),
                                        ("--grid", args.grid)) if value is None]
    if missing:
        raise InputError(f"ddvp chaos needs {', '.join(missing)} (or --merge DIR alone)")
    scene = load_scene(args.scene)
    params = parse_settings(args.settings)
    config = scene.resolve({k: v for k, v in params.items() if k in scene.params})
    tau0 = args.tau0 if args.tau0 is not None else config.tau0
    with flags("chaos_map"):  # the study names its fields (grid, section, shard)
        parse_grid(args.grid, args.section, scene.system.n)  # before any folder is made
        shard = parse_shard(args.shard)
    named = {"energy": args.energy, "grid": args.grid, "section": args.section,
             "t_end": args.t_end, "tau0": args.tau0, "params": params}
    target, owned = default_or(args, f"{scene.name}-chaos-E{args.energy:g}", named,
                               options=("section", "t_end", "tau0"),
                               defaults={"params": {}})
    folder = Path(target) / shard_folder(*shard) if shard else target
    try:
        with output_folder(folder, owned=owned + (1 if shard else 0)) as out:
            with flags("chaos_map"):  # its inputs are checked before any cell runs
                result, journal, rows = chaos_map(
                    scene.system, args.energy, args.grid, out, scene=args.scene, tau0=tau0,
                    section=args.section, t_end=args.t_end, params=params,
                    workers=args.workers, scheduler=args.scheduler, shard=args.shard,
                    resume=not args.fresh, progress=args.progress is not False)
            arrays = map_arrays(result, scene.system, scene.system.parameter_vector(params))
            meta = _meta(args, scene, tau0, params, result)
            with INTERRUPTS.saving():
                files = {("part.npz" if shard else "chaos.npz"): arrays_writer(arrays)}
                if not shard and not args.no_plot:
                    files["chaos.png"] = figure_writer(
                        out, "chaos.png", lambda handle: plot_chaos(arrays, handle),
                        INTERRUPTS.interruptible)
                commit_journal(journal, COLUMNS, rows, files, meta)
    except JournalInterrupted as exc:
        raise Stopped(str(exc)) from None
    _summary(arrays, result, folder, shard)
    failed = _failed(arrays["status"])
    return 0 if failed == 0 and not INTERRUPTS.requested else 1


def _meta(args, scene, tau0, params, result) -> dict:
    # the scene's hash beside its name: shards of two files of one name, or of a file edited
    # between shards, are not parts of one map (merge_shards compares the settings)
    settings = {"scene": scene.name, "scene_digest": scene.digest, "energy": float(args.energy),
                "grid": args.grid, "section": args.section, "t_end": float(args.t_end),
                "tau0": float(tau0), "params": params}
    status = result.status
    return {"command": "chaos", "settings": settings, "cells": int(status.size),
            "run": int(np.sum(status != "not_run")), "not_run": int(np.sum(status == "not_run")),
            "failed": _failed(status), "shard": list(result.shard) if result.shard else None,
            "blocks": result.blocks, "blocks_run_now": result.blocks_run,
            "cpu_s_of_blocks_run_now": round(result.cpu_s, 3)}


def _failed(status) -> int:
    return int(np.sum(~np.isin(status, ("success", "not_run", "other_shard"))))


def _summary(arrays, result, folder, shard) -> None:
    status = arrays["status"]
    mine = status == "success"
    megno = arrays["megno"][mine]
    part = f" (shard {shard[0]} of {shard[1]})" if shard else ""
    print(f"chaos map{part}: {int(np.sum(status != 'not_run'))} of {status.size} cells on the "
          f"energy surface; {int(mine.sum())} run, {_failed(status)} failed; "
          f"{result.blocks_run} of {result.blocks} blocks run now (the rest from the journal)")
    if megno.size:
        print(f"  <Y> <= 2.5 (regular) in {int(np.sum(megno <= 2.5))} cells, > 2.5 (chaotic) "
              f"in {int(np.sum(megno > 2.5))}; CPU of the blocks run now "
              f"{result.cpu_s:.1f} s")
    names = "part.npz, cells.csv" if shard else "chaos.npz, cells.csv, chaos.png"
    print(f"  written to {folder}/ ({names}, meta.json)")


def _merge(args) -> int:
    """``--merge DIR``: every shard's part joined into DIR's chaos.npz and chaos.png."""
    given = [flag for flag, value in (("SCENE", args.scene), ("--energy", args.energy),
                                      ("--grid", args.grid), ("--shard", args.shard))
             if value is not None]
    if given:
        raise InputError(f"--merge DIR takes the settings from the shards' parts: drop "
                         f"{', '.join(given)}")
    with flags("merge_shards"):
        arrays, parts = merge_shards(args.merge)
    meta = {"command": "chaos", "merged": sorted(parts),
            "settings": next(iter(parts.values())).get("settings"),
            "cells": int(arrays["status"].size),
            "run": int(np.sum(arrays["status"] != "not_run")),
            "failed": _failed(arrays["status"]),
            "cpu_s_of_blocks": round(sum(p.get("cpu_s_of_blocks_run_now", 0.0)
                                         for p in parts.values()), 3)}
    with output_folder(args.merge) as out:
        with INTERRUPTS.saving():
            files = {"chaos.npz": arrays_writer(arrays)}
            if not args.no_plot:
                files["chaos.png"] = figure_writer(out, "chaos.png",
                                                   lambda handle: plot_chaos(arrays, handle),
                                                   INTERRUPTS.interruptible)
            out.commit(files, meta)
    status = arrays["status"]
    print(f"merged {len(parts)} shards: {status.size} cells, "
          f"{int(np.sum(status == 'success'))} run, {meta['failed']} failed; written to "
          f"{args.merge}/ (chaos.npz, chaos.png, meta.json)")
    if INTERRUPTS.requested:
        raise Stopped(f"interrupted; {holds(out)}")
    return 0 if meta["failed"] == 0 else 1
