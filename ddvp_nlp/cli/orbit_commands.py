"""``ddvp periodic``: a periodic orbit at a prescribed energy, a family over energies
(``--family``), their stability (``--stability``) and a family followed by pseudo-arclength
continuation with its bifurcations (``--follow``) and, at a branch point, both halves of the new
branch (``--switch``), written to the run folder and summed up on stdout."""

from __future__ import annotations

import sys

from ..errors import InputError
from ..io.atomic import output_folder
from ..io.orbit_files import write_family, write_periodic
from ..io.run_folder import read_guess
from ..io.stability_files import write_family_stability, write_followed_family, write_stability
from ..scenes import PeriodicSettings, load_scene
from ..solvers import (
    Continuation,
    Switch,
    check_periodic,
    describe,
    follow_periodic_family,
    periodic_stability,
    solve_periodic,
    solve_periodic_family,
)
from ..validation import check_integer, check_real
from . import arguments as options
from .arguments import check_grid_memory, family_energies
from .folders import default_or, holds
from .interrupts import INTERRUPTS, Stopped
from .parser import parse_settings


def switch_tol(args) -> dict:
    """``--switch-tol``'s ``Switch`` keyword: ``{}`` when not given, ``{"tol": None}`` for
    'none', else a positive number; refused by name without ``--switch``."""
    text = getattr(args, "switch_tol", None)
    if text is None:
        return {}
    if getattr(args, "switch", None) is None:
        raise InputError(f"--switch-tol {text} needs --switch: it is the halves' error target")
    if str(text).strip().lower() == "none":
        return {"tol": None}
    try:
        value = float(text)
    except ValueError:
        value = None
    if value is None or not (value > 0 and value < float("inf")):
        raise InputError(f"--switch-tol must be a positive number or 'none', got {text!r}")
    return {"tol": value}


def run_periodic(args) -> int:
    """``ddvp periodic``: one orbit (a run folder) or a family (``family.csv``, a folder per
    energy); every input checked before anything is built."""
    if not getattr(args, "search", False):
        refuse_search_flags(args)
    if getattr(args, "switch", None) is not None:
        if args.follow is None:
            raise InputError("--switch needs --follow E_END: branches are "
                             "switched onto at a branch point located on a followed family")
        check_integer("--switch", args.switch, minimum=2)
    switch_tol(args)  # refused without --switch, or not a positive number nor 'none'
    scene = load_scene(args.scene)
    defaults = getattr(scene, "periodic", None) or PeriodicSettings()
    params = parse_settings(args.settings)
    scene.resolve({k: v for k, v in params.items() if k in scene.params})  # ranges, names
    settings = {"section": args.section or defaults.section, "scheme": args.scheme,
                "params": params, "start": defaults.start, "integrals": defaults.integrals,
                "angles": defaults.angles, "options": options.grid_options(args)}
    nodes = args.nodes if args.nodes is not None else defaults.nodes
    guess = read_guess(args.guess, scene.system.n) if args.guess else None
    named = {"nodes": nodes, "section": settings["section"], "scheme": args.scheme,
             "solver": args.solver, "params": params, "guess": args.guess}
    if getattr(args, "search", False):
        from .search_command import run_search
        return run_search(args, scene, params, nodes, defaults)
    if args.follow is not None or args.stability:

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

    target, owned = default_or(args, f"{scene.name}-periodic", named,
                               options=("scheme", "solver", "guess"),
                               defaults={"nodes": defaults.nodes, "section": defaults.section,
                                         "params": {}, "energy": defaults.energy},
                               scene=scene, guess=guess if args.guess else None)
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
          f"  {_period_line(solution, meta)}; written to {out.path}/")
    _print_accuracy(solution)
    return 0 if solution.success and not INTERRUPTS.requested else 1


def _print_accuracy(solution) -> None:
    """The accuracy check's verdict line (as ``march`` and ``bvp`` print theirs)."""
    if solution.verdict is not None:
        print(f"  accuracy check: {solution.verdict.name} ({describe(solution.verdict)})")


def _period_line(solution, meta) -> str:
    """The period of a found orbit; none for an orbit not found (its last iterate's period is
    no orbit's: a search of the section, --search, says which orbits exist there)."""
    if solution.success:
        return (f"period {meta['period']:.12g} at E = {meta['energy']:.10g}, {meta['nodes']} "
                "nodes")
    if meta["status"] in ("inaccurate", "drifted"):  # a discrete orbit, off the motion
        return (f"period {meta['period']:.12g} of a discrete orbit that does not follow the "
                f"motion, at E = {meta['energy']:.10g}, {meta['nodes']} nodes")
    return (f"no period: no orbit was found at E = {meta['energy']:.10g} ({meta['nodes']} "
            "nodes); --search --section qK=V looks for the orbits that cross a section")


def _periodic_family(args, scene, energies, nodes, guess, settings, named) -> int:

    target, owned = default_or(args, f"{scene.name}-family", named, scene=scene,
                               guess=guess if args.guess else None)
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


def scene_guess(scene, energy: float, params: dict):
    """The scene's own start at ``energy`` (``PeriodicSettings.guess``), or ``None``."""
    defaults = getattr(scene, "periodic", None) or PeriodicSettings()
    if defaults.guess is None:
        return None
    values = {**scene.params, **params}
    try:
        return defaults.guess(energy, **values)
    except ValueError as error:
        raise InputError(f"--energy {energy!r}: scene {scene.name!r} has no start there: "
                         f"{error}") from None


def run_periodic_stability(args, scene, settings: dict, nodes: int, guess, params: dict,
                           named: dict) -> int:
    """``--stability`` on one orbit or a ``--family``, or ``--follow``; ``named``: the
    settings that name the default run folder (``folders.default_or``)."""
    defaults = getattr(scene, "periodic", None) or PeriodicSettings()
    tol = check_real("--stability-tol", args.stability_tol, positive=True)
    if args.follow is not None:
        if args.family is not None:
            raise InputError("--follow and --family are two ways through a family: give one")
        return _follow(args, scene, settings, nodes, guess, params, tol, defaults,
                       {**named, "follow": args.follow})
    if args.family is not None:
        return _family(args, scene, settings, nodes, guess, params, tol,
                       {**named, "family": args.family})
    energy = args.energy if args.energy is not None else defaults.energy
    if energy is None:
        raise InputError(f"--energy is needed: scene {scene.name!r} declares no default energy")
    return _orbit(args, scene, settings, nodes, guess or scene_guess(scene, energy, params),
                  params, tol, energy, {**named, "energy": energy})


def _interrupted(out, what: str) -> Stopped:


    return Stopped(f"interrupted ({INTERRUPTS.name or 'SIGINT'}) while {what}; nothing new "
                   f"was written: {holds(out)}")


def _orbit(args, scene, settings, nodes, guess, params, tol, energy, named) -> int:

    if guess is None:
        check_periodic(scene.system, energy=energy, nodes=nodes, **settings)
    check_grid_memory("--nodes", nodes, scene.system.n, 1)
    target, owned = default_or(args, f"{scene.name}-periodic", {**named, "stability": tol},
                               scene=scene, guess=guess if args.guess else None)
    with output_folder(target, owned=owned) as out:
        try:
            solution = solve_periodic(scene.system, energy=energy, nodes=nodes, guess=guess,
                                      **settings)
        except KeyboardInterrupt:
            raise _interrupted(out, "solving") from None
        with INTERRUPTS.saving():
            meta = write_periodic(out, scene, solution, params, plot=not args.no_plot,
                                  interruptible=INTERRUPTS.interruptible)
        print(f"{scene.name} periodic [{meta['scheme']}]: {meta['status']} - {meta['message']}"
              f"\n  {_period_line(solution, meta)}")
        _print_accuracy(solution)
        if not solution.success:
            print(f"  no stability: the orbit was not found; written to {out.path}/")
            return 1
        try:
            stability = periodic_stability(scene.system, solution, params=params,
                                           integrals=settings["integrals"], tol=tol)
        except KeyboardInterrupt:
            raise _interrupted(out, "computing the stability (the orbit was written)") from None
        with INTERRUPTS.saving():
            write_stability(out, stability)
    print(f"  stability: {stability.summary()}\n  written to {out.path}/ (stability.json)")
    return 0 if not INTERRUPTS.requested else 1


def _family(args, scene, settings, nodes, guess, params, tol, named) -> int:

    energies = family_energies(args.family, scene.system.n, nodes)
    guess = guess or scene_guess(scene, energies[0], params)
    for energy in (energies[0], energies[-1]) if guess is None else ():
        check_periodic(scene.system, energy=energy, nodes=nodes, **settings)
    target, owned = default_or(args, f"{scene.name}-family", {**named, "stability": tol},
                               scene=scene, guess=guess if args.guess else None)
    with output_folder(target, owned=owned) as out:
        try:
            family = solve_periodic_family(scene.system, energies, nodes=nodes, guess=guess,
                                           **settings)
        except KeyboardInterrupt:
            raise _interrupted(out, "solving the family") from None
        with INTERRUPTS.saving():
            write_family(out, scene, family, params, plot=not args.no_plot,
                         section=settings["section"], interruptible=INTERRUPTS.interruptible)
        try:
            stabilities = [periodic_stability(scene.system, orbit, params=params,
                                              integrals=settings["integrals"], tol=tol)
                           if orbit.success else None for _, orbit in family]
        except KeyboardInterrupt:
            raise _interrupted(out, "computing the stabilities (the family was written)") \
                from None
        with INTERRUPTS.saving():
            rows = write_family_stability(out, family, stabilities)
    for row in rows:
        print(f"E = {row['energy']:<12.6g} {row['status']:14s} T = {row['period']:.10g}  "
              f"{row.get('verdict', '-')}: indices {row.get('indices', '-')}")
    print(f"  written to {out.path}/ (family.csv, stability.csv, family.png, E=... folders)")
    return 0 if all(row["status"] == "success" for row in rows) and not INTERRUPTS.requested \
        else 1


def _follow(args, scene, settings, nodes, guess, params, tol, defaults, named) -> int:

    energy = args.energy if args.energy is not None else defaults.energy
    if energy is None:
        raise InputError(f"--energy is needed with --follow: scene {scene.name!r} declares no "
                         f"default energy")
    check_real("--follow", args.follow)
    switch = (Switch(orbits=args.switch, **switch_tol(args)) if args.switch is not None
              else None)
    continuation = Continuation(step=args.step, tol=tol, switch=switch,
                                max_orbits=check_integer("--max-orbits", args.max_orbits,
                                                         minimum=2))
    guess = guess or scene_guess(scene, energy, params)
    check_grid_memory("--nodes", nodes, scene.system.n,
                      continuation.max_orbits + 2 * (args.switch or 0))
    target, owned = default_or(args, f"{scene.name}-follow", {
        **named, "energy": energy, "step": args.step, "max_orbits": args.max_orbits,
        "stability": tol, **({"switch": args.switch} if switch else {}),
        **({"switch_tol": switch.tol} if switch and args.switch_tol is not None else {})},
        scene=scene, guess=guess if args.guess else None)
    with output_folder(target, owned=owned) as out:
        try:
            family = follow_periodic_family(scene.system, (energy, args.follow), nodes=nodes,
                                            guess=guess, continuation=continuation,
                                            **settings)
        except KeyboardInterrupt:
            raise _interrupted(out, "following the family") from None
        with INTERRUPTS.saving():
            _write_follow(out, scene, family, params, not args.no_plot)
    _print_members(family.members, "")
    _print_bifurcations(family.bifurcations, "")
    print(f"{family.message}; {len(family.members)} orbits in {family.seconds:.1f} s; written "
          f"to {out.path}/ (family.csv, bifurcations.csv, bifurcations.json, family.png"
          + "".join(f", branch-{j + 1}/" for j in range(len(family.branches))) + ")")
    if switch is None:
        return 0 if family.members and family.complete and not INTERRUPTS.requested else 1
    return _report_switch(family)


def _write_follow(out, scene, family, params, plot: bool) -> None:
    """The family's files, and each half of a new branch in ``branch-J/`` (the same files)."""
    def write_orbit(folder, scene, solution, params):
        write_periodic(folder, scene, solution, params, plot=False)
    write_followed_family(out, scene, family, params, plot=plot, write_orbit=write_orbit)
    for j, branch in enumerate(family.branches):
        with out.subfolder(f"branch-{j + 1}") as folder:
            write_followed_family(folder, scene, branch.family, params, plot=plot,
                                  write_orbit=write_orbit)


def _print_members(members, indent: str) -> None:
    for member in members:
        exact = member.stability.exact
        print(f"{indent}E = {member.energy:<14.10g} T = {member.orbit.orbit.period:<14.10g} "
              f"{member.stability.verdict:9s} indices "
              f"{', '.join(f'{k.real:.6g}' for k in member.stability.indices) or '-'}"
              + (f" (exact flow: {exact.verdict}, difference {member.stability.index_error:.1e})"
                 if exact is not None else ""))


def _print_bifurcations(bifurcations, indent: str) -> None:
    for j, found in enumerate(bifurcations):
        exact = found.extra.get("exact_energy")
        print(f"{indent}bifurcation {j + 1}: {found.kind} at E = {found.energy:.12g} (bracket "
              f"{found.bracket[0]:.12g} .. {found.bracket[1]:.12g})"
              + (f"; exact flow: E = {exact:.12g}, difference "
                 f"{found.extra['discrete_minus_exact']:.2e}" if exact is not None
                 else "; not confirmed on the exact flow"))


def _report_switch(family) -> int:
    """Each half of the new branch, its orbits and bifurcations; the exit code: 2 when the
    family had no branch point to switch at (``--switch`` asked for what is not there), 1 when
    a half stopped short (it says why), else 0."""
    if not family.branches:
        print(f"ddvp periodic: --switch: {family.switched}", file=sys.stderr)
        return 2
    print(family.switched)
    for j, branch in enumerate(family.branches):
        half = branch.family
        print(f"branch {j + 1} ({branch.label}): {half.message}; {len(half.members)} orbits in "
              f"{half.seconds:.1f} s; written to branch-{j + 1}/")
        _print_members(half.members, "  ")
        _print_bifurcations(half.bifurcations, "  ")
    whole = family.complete and all(b.family.complete for b in family.branches)
    return 0 if whole and not INTERRUPTS.requested else 1


# The flags only the search reads: given without --search they would be ignored unsaid.
SEARCH_ONLY = ("seeds", "max_returns", "reversing", "jitter", "workers")


def refuse_search_flags(args) -> None:
    """A search-only flag given without ``--search`` is refused by name (exit 2)."""
    given = [f"--{dest.replace('_', '-')} {getattr(args, dest)}" for dest in SEARCH_ONLY
             if getattr(args, dest, None) is not None]
    if given:
        raise InputError(f"{given[0]}: read with --search only (the search of a section for "
                         f"orbits); without --search it would be ignored")
