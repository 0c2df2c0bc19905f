"""``ddvp poincare``: a Poincare section at a fixed energy, many orbits marched together (on
local workers or a Dask cluster), their crossings written."""

from __future__ import annotations

from ..errors import InputError
from ..io.atomic import output_folder
from ..io.section_files import write_section
from ..scenes import load_scene
from ..studies.poincare import poincare_section
from ..validation import check_memory
from . import arguments as options
from .folders import default_or, holds
from .interrupts import INTERRUPTS, Stopped
from .parser import parse_settings


def run_poincare(args) -> int:
    """``ddvp poincare``: the starts on the section, one ensemble, its crossings written."""
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
    target, owned = default_or(args, f"{scene.name}-poincare-E{args.energy:g}", named,
                               options=("orbits", "section", "direction", "t_end", "tau0",
                                        "seed"), defaults={"params": {}}, scene=scene)
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
