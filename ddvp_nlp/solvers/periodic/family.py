"""A family of periodic orbits in the energy: natural-parameter continuation.

The first orbit is solved from the default start (or a given guess); each next one at the next
energy of the list, started from the last orbit found (same grid, so the node times are taken
as they are). When a solve fails, the step in ``E`` is halved towards the target, up to
``max_halvings`` times; an energy still not reached is recorded as the failed solve and the
continuation goes on to the next energy from the last orbit found.
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from ...validation import check_finite_array, check_integer
from .orbit import check_periodic, solve_periodic

# What a family passes on to every solve_periodic.
FORWARDED = {"section", "scheme", "params", "start", "integrals", "angles", "options"}


def solve_periodic_family(system, energies, *, nodes: int, max_halvings: int = 4,
                          guess=None, **options) -> list:
    """``[(E, Solution), ...]`` for every energy of ``energies`` (module docstring); the
    intermediate energies the halvings took are not listed. ``options`` go to
    `solve_periodic`: ``section``, ``scheme``, ``params``, ``start``, ``integrals``,
    ``angles`` and its ``options`` (a ``GridOptions``)."""
    unknown = sorted(set(options) - FORWARDED)
    if unknown:
        raise InputError(f"solve_periodic_family takes no {unknown[0]!r} (it passes "
                         f"{', '.join(sorted(FORWARDED))} to solve_periodic)")
    energies = [float(e) for e in np.atleast_1d(check_finite_array("energies", energies))]
    if not energies:
        raise InputError("energies must be finite numbers, got none")
    max_halvings = check_integer("max_halvings", max_halvings, minimum=0)
    # Both ends of the range before any solve (energy outside the section's range, ...).
    for energy in {energies[0], energies[-1]}:
        check_periodic(system, energy=energy, nodes=nodes, **options)
    found = []
    last = None
    for target in energies:
        if last is None:
            solution = solve_periodic(system, energy=target, nodes=nodes, guess=guess, **options)
        else:
            solution = _reach(system, last, target, nodes, max_halvings, options)
        found.append((target, solution))
        if solution.success:
            last = (target, solution)
    return found


def _reach(system, last, target: float, nodes: int, max_halvings: int, options):
    """The orbit at ``target`` from ``last = (E, Solution)``, halving the step on failure."""
    energy, solution = last
    step = target - energy
    halvings = 0
    while True:
        trial = solve_periodic(system, energy=energy + step, nodes=nodes, guess=solution,
                               **options)
        if trial.success:
            energy, solution = energy + step, trial
            if energy == target:
                return trial
            step = target - energy
        elif halvings < max_halvings:
            halvings += 1
            step /= 2
        else:
            return trial
