"""``ddvp periodic SCENE --search --energy E --section q2=0``: the periodic orbits at an energy
found from a section alone (``find_periodic_orbits``), written as ``orbits.csv``,
``failures.csv`` and ``orbits.png`` and listed on stdout; "none found in the region searched"
with what was searched when there are none (exit 1)."""

from __future__ import annotations

from ..errors import InputError
from ..io.atomic import output_folder
from ..io.search_files import write_search
from ..solvers import find_periodic_orbits
from ..validation import check_integer, check_real
from .arguments import api_default
from .folders import default_or
from .interrupts import INTERRUPTS, Stopped


def run_search(args, scene, params: dict, nodes: int, defaults) -> int:
    """The search (module docstring); every input checked before a flow runs."""
    for flag in ("family", "follow", "guess"):
        if getattr(args, flag, None) is not None:
            raise InputError(f"--search finds orbits from the section alone: --{flag} does not "
                             "go with it")
    energy = args.energy if args.energy is not None else defaults.energy
    if energy is None:
        raise InputError(f"--energy is needed: scene {scene.name!r} declares no default energy")
    check_real("--energy", energy)
    section = args.section
    if section is None:
        raise InputError("--section is needed with --search: the position coordinate the "
                         "orbits cross, e.g. --section q2=0")
    seeds = check_integer("--seeds", default_of("seeds", args.seeds))
    max_returns = check_integer("--max-returns", default_of("max_returns", args.max_returns))
    reversing = default_of("reversing", args.reversing)
    jitter = getattr(args, "jitter", None)
    if jitter is not None:
        jitter = check_integer("--jitter", jitter, minimum=0)
    workers = check_integer("--workers", default_of("workers", args.workers))
    tol = check_real("--stability-tol", args.stability_tol, positive=True)
    named = {"energy": energy, "section": section, "seeds": seeds, "max_returns": max_returns,
             "reversing": reversing, "nodes": nodes, "params": params, "jitter": jitter}
    target, owned = default_or(args, f"{scene.name}-search", named, scene=scene)
    with output_folder(target, owned=owned) as out:
        try:
            search = find_periodic_orbits(scene.system, energy=energy, section=section,
                                          reversing=reversing, seeds=seeds,
                                          max_returns=max_returns, nodes=nodes, params=params,
                                          refine=True, jitter=jitter, workers=workers,
                                          stability_tol=tol)
        except KeyboardInterrupt:
            raise Stopped(f"interrupted ({INTERRUPTS.name or 'SIGINT'}) while searching; "
                          "nothing was written") from None
        with INTERRUPTS.saving():
            rows = write_search(out, scene.name, search, plot=not args.no_plot,
                                interruptible=INTERRUPTS.interruptible)
    print(f"{scene.name} periodic search: {search.summary()}")
    print(f"  verdict: the exact flow's stability index, marginal within {tol:g} of +-2; "
          "grid: the orbit refined on the grid and its accuracy verdict")
    for j, row in enumerate(rows):
        print(f"  {j + 1:2d}. T = {row['period']:.10g}  index {row['index']:.8g}  "
              f"{row['verdict']:8s} returns {row['returns']}, {row['seeds']} seed(s), "
              f"{crossing_said(row, search.searched.section)}; {grid_said(row)}")
    reasons: dict = {}
    for failed in search.failures:
        key = failed.reason.split(" (")[0].split(":")[0]
        reasons[key] = reasons.get(key, 0) + 1
    if reasons:
        print("  failed seeds: " + "; ".join(f"{n} {why}" for why, n in reasons.items()))
    print(f"  {search.seconds:.1f} s CPU; written to {out.path}/ (orbits.csv, failures.csv"
          f"{', orbits.png' if rows and not args.no_plot else ''})")
    return 0 if search.found and not INTERRUPTS.requested else 1


def crossing_said(row: dict, section: str) -> str:
    """Where the orbit's listed start crosses the section upwards: the other position and its
    momentum (``orbits.csv``'s columns of them). Orbits of one period, as mirror images under a
    symmetry are, are told apart by it. A momentum below ``1e-9`` of the start's largest
    component is round-off on the symmetric line and said as 0."""
    other = "1" if section.lstrip().startswith("q2") else "2"
    q, p = row[f"q{other}"], row[f"p{other}"]
    size = max(abs(row[name]) for name in ("q1", "q2", "p1", "p2"))
    p = 0.0 if abs(p) <= 1e-9 * size else p
    return f"up through q{other} = {q:.7g}, p{other} = {p:.7g}"


def grid_said(row: dict) -> str:
    """The grid's refinement of one orbit in words: its verdict, period and index where it
    refines the orbit; where it landed on another orbit, that, with the gaps (not this orbit's
    period); else why there is none."""
    if row["grid_verdict"] == "another orbit":
        landed = f"{row['grid_landed']}, " if row["grid_landed"] else ""
        return (f"grid: landed on another orbit ({landed}T = {row['grid_period']:.10g}, "
                f"{row['grid_period_gap']:.1e} of the period and start "
                f"{row['grid_start_gap']:.1e} away, its own error {row['grid_error']:.1e}): "
                "not refined")
    if row["grid_period"] == row["grid_period"]:
        off = (f" (the exact flow's differs by {row['grid_index_gap']:.2g} of it, far beyond "
               f"the grid's error {row['grid_error']:.1e}: the grid's index is not this "
               "orbit's)" if row["grid_index_off"] else "")
        return (f"grid {row['grid_verdict']}: T = {row['grid_period']:.10g}, index "
                f"{row['grid_index']:.8g}{off}")
    return row["note"][:90]


def default_of(dest: str, value):
    """``value``, or the API's default of the search's option ``dest`` when not given."""
    return api_default("periodic", dest) if value is None else value
