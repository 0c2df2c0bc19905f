"""``ddvp periodic --stability`` and ``--follow``, and the note of ``ddvp bvp --energy``: the
stability of an orbit (or of each orbit of a family), a family followed by pseudo-arclength
continuation with its bifurcations, written to the run folder and summed up on stdout."""

from __future__ import annotations

from ..errors import InputError
from ..scenes import PeriodicSettings
from ..validation import check_integer, check_real


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


def transfer_note(stats: dict) -> str:
    """One line on a transfer at a prescribed energy and its check by shooting."""
    exact = stats.get("exact") or {}
    text = f"transfer time {stats['transfer_time']:.12g} at energy {stats['energy']:.10g}"
    if exact.get("converged"):
        text += (f"; the exact flow's shooting: {exact['transfer_time']:.12g} (difference "
                 f"{exact['time_difference']:.2e}), path difference {exact['path_difference']:.2e}")
    elif exact:
        text += "; the exact flow's shooting did not converge from this transfer"
    return text


def run_periodic_stability(args, scene, settings: dict, nodes: int, guess, params: dict) -> int:
    """``--stability`` on one orbit or a ``--family``, or ``--follow``."""
    defaults = getattr(scene, "periodic", None) or PeriodicSettings()
    tol = check_real("--stability-tol", args.stability_tol, positive=True)
    if args.follow is not None:
        if args.family is not None:
            raise InputError("--follow and --family are two ways through a family: give one")
        return _follow(args, scene, settings, nodes, guess, params, tol, defaults)
    if args.family is not None:
        return _family(args, scene, settings, nodes, guess, params, tol)
    energy = args.energy if args.energy is not None else defaults.energy
    if energy is None:
        raise InputError(f"--energy is needed: scene {scene.name!r} declares no default energy")
    return _orbit(args, scene, settings, nodes, guess or scene_guess(scene, energy, params),
                  params, tol, energy)


def _orbit(args, scene, settings, nodes, guess, params, tol, energy) -> int:
    from ..io.periodic_runs import write_periodic
    from ..io.runs import prepare_folder
    from ..io.stability_runs import write_stability
    from ..solvers.periodic import periodic_stability, solve_periodic
    from ..solvers.periodic.solve import check_periodic

    if guess is None:
        check_periodic(scene.system, energy=energy, nodes=nodes, **settings)
    out = prepare_folder(args.out or f"runs/{scene.name}-periodic")
    solution = solve_periodic(scene.system, energy=energy, nodes=nodes, guess=guess, **settings)
    meta = write_periodic(out, scene, solution, params, plot=not args.no_plot)
    print(f"{scene.name} periodic [{meta['scheme']}]: {meta['status']} - {meta['message']}\n"
          f"  period {meta['period']:.12g} at E = {meta['energy']:.10g}, N = {meta['nodes']}")
    if not solution.success:
        print(f"  no stability: the orbit was not found; written to {out}/")
        return 1
    stability = periodic_stability(scene.system, solution, params=params,
                                   integrals=settings["integrals"], tol=tol)
    write_stability(out, stability)
    print(f"  stability: {stability.summary()}\n  written to {out}/ (stability.json)")
    return 0


def _family(args, scene, settings, nodes, guess, params, tol) -> int:
    from ..io.periodic_runs import write_family
    from ..io.runs import prepare_folder
    from ..io.stability_runs import write_family_stability
    from ..solvers.periodic import periodic_stability, solve_periodic_family
    from ..solvers.periodic.solve import check_periodic

    energies = family_energies(args.family)
    guess = guess or scene_guess(scene, energies[0], params)
    for energy in (energies[0], energies[-1]) if guess is None else ():
        check_periodic(scene.system, energy=energy, nodes=nodes, **settings)
    out = prepare_folder(args.out or f"runs/{scene.name}-family")
    family = solve_periodic_family(scene.system, energies, nodes=nodes, guess=guess, **settings)
    write_family(out, scene, family, params, plot=not args.no_plot)
    stabilities = [periodic_stability(scene.system, orbit, params=params,
                                      integrals=settings["integrals"], tol=tol)
                   if orbit.success else None for _, orbit in family]
    rows = write_family_stability(out, family, stabilities)
    for row in rows:
        print(f"E = {row['energy']:<12.6g} {row['status']:14s} T = {row['period']:.10g}  "
              f"{row.get('verdict', '-')}: indices {row.get('indices', '-')}")
    print(f"  written to {out}/ (family.csv, stability.csv, family.png, E=... folders)")
    return 0 if all(row["status"] == "success" for row in rows) else 1


def _follow(args, scene, settings, nodes, guess, params, tol, defaults) -> int:
    from ..io.periodic_runs import write_periodic
    from ..io.runs import prepare_folder
    from ..io.stability_runs import write_followed_family
    from ..solvers.periodic import Continuation, follow_periodic_family

    energy = args.energy if args.energy is not None else defaults.energy
    if energy is None:
        raise InputError(f"--energy is needed with --follow: scene {scene.name!r} declares no "
                         f"default energy")
    check_real("--follow", args.follow)
    continuation = Continuation(step=args.step, tol=tol,
                                max_orbits=check_integer("--max-orbits", args.max_orbits,
                                                         minimum=2))
    guess = guess or scene_guess(scene, energy, params)
    family = follow_periodic_family(scene.system, (energy, args.follow), nodes=nodes,
                                    guess=guess, continuation=continuation, **settings)
    out = prepare_folder(args.out or f"runs/{scene.name}-follow")

    def write_orbit(folder, scene, solution, params):
        write_periodic(folder, scene, solution, params, plot=False)
    write_followed_family(out, scene, family, params, plot=not args.no_plot,
                          write_orbit=write_orbit)
    for member in family.members:
        exact = member.stability.exact
        print(f"E = {member.energy:<14.10g} T = {member.orbit.stats['period']:<14.10g} "
              f"{member.stability.verdict:9s} indices "
              f"{', '.join(f'{k.real:.6g}' for k in member.stability.indices) or '-'}"
              + (f" (exact flow: {exact.verdict}, difference {member.stability.index_error:.1e})"
                 if exact is not None else ""))
    for j, found in enumerate(family.bifurcations):
        exact = found.extra.get("exact_energy")
        print(f"bifurcation {j + 1}: {found.kind} at E = {found.energy:.12g} (bracket "
              f"{found.bracket[0]:.12g} .. {found.bracket[1]:.12g})"
              + (f"; exact flow: E = {exact:.12g}, difference "
                 f"{found.extra['discrete_minus_exact']:.2e}" if exact is not None
                 else "; not confirmed on the exact flow"))
    print(f"{family.message}; {len(family.members)} orbits in {family.seconds:.1f} s; written "
          f"to {out}/ (family.csv, bifurcations.csv, bifurcations.json, family.png)")
    return 0 if family.members and family.complete else 1


def family_energies(text: str):
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
