"""The test functions of bifurcations along a family, and a located bifurcation confirmed by the
exact flow.

Test functions (``arclength.py`` locates their sign changes between members):

- ``fold``: ``dE/ds``, the energy component of the family's unit tangent;
- ``branch point``: ``det(R - I) = prod_j (2 - k_j)`` (a nontrivial pair passes +1);
- ``period doubling``: ``det(R + I) = prod_j (2 + k_j)`` (a pair passes -1),

with ``R`` the reduced monodromy and ``k_j`` the stability indices (``floquet.py``).

Confirmation by the exact flow (`confirm`): the same test function on the exact flow's
orbits (``exact.close_exact`` from the discrete orbit at the located energy ``E_N``, then at
each energy from the last exact orbit), its sign change bracketed around ``E_N`` (half-width
``1e-6`` of the energy the orbit trades in a radian of its period, quadrupled until the signs
differ) and located by Brent's method: the
exact flow's bifurcation energy ``E_exact``, and ``E_N - E_exact`` the discrete error. A fold
has exact orbits on one side only (two there, none beyond), so no sign change can be bracketed
in ``E``; the exact family is followed in its period instead (``close_exact(...,
fixed_period=True)``, regular through the fold), and the fold is the zero of ``dE/dT``, bracketed
around the discrete orbit's period and located by Brent's method.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from ..exact.closure import close_exact
from ..grid.motion_size import energy_traded
from .floquet import Stability, exact_stability

KINDS = ("fold", "branch point", "period doubling")
# The first half-width of the exact bracket (relative to the energy the orbit trades in a radian
# of its period, `grid.motion_size.energy_traded`, or to the period for a fold: ``max(1, |E|)``
# moved with a constant added to H and with the units) and its expansions.
FIRST_HALF_WIDTH = 1e-6
EXPANSIONS = 12


def tests(stability: Stability, slope: float) -> dict:
    """The three test functions (module docstring) of an orbit with the tangent slope
    ``dE/ds``."""
    k = stability.indices
    return {"fold": float(slope), "branch point": float(np.prod(2 - k).real),
            "period doubling": float(np.prod(2 + k).real)}


@dataclass
class Confirmation:
    """The exact flow's bifurcation near a located one: its energy, the final bracket, the
    exact test function's values at the bracket's ends, the exact orbits' largest closure and
    the discrete energy's difference from it."""

    energy: float
    bracket: tuple
    values: tuple
    closure: float
    difference: float
    evaluations: int

    def as_dict(self) -> dict:
        return {"exact_energy": self.energy, "exact_bracket": list(self.bracket),
                "exact_tests": list(self.values), "exact_closure": self.closure,
                "discrete_minus_exact": self.difference, "exact_orbits": self.evaluations}


def confirm(system, theta, orbit, kind: str, *, section_index: int, section_value: float,
            integrals=(), tol: float = 1e-6) -> Confirmation | None:
    """The exact flow's bifurcation of ``kind`` near the located discrete ``orbit`` (a
    `Solution` at the located energy), or ``None`` if the exact test function does not
    change sign within the widest bracket."""
    integrals = tuple(integrals)
    energy = float(orbit.orbit.energy)
    start = (np.concatenate([orbit.q[0], orbit.p[0]]), float(orbit.orbit.period))
    shift = np.concatenate([2 * np.pi * np.asarray(orbit.orbit.winding, float),
                            np.zeros(system.n)])
    seen = {"count": 0, "closure": 0.0}

    def closed(level, begin=start, period=None):
        exact = close_exact(system, theta, begin[0], begin[1] if period is None else period,
                            energy=level, section_index=section_index,
                            section_value=section_value, integrals=integrals, shift=shift,
                            fixed_period=period is not None)
        seen["count"] += 1
        seen["closure"] = max(seen["closure"], exact.closure)
        if not exact.converged:
            raise _NotClosed(level)
        return exact

    def test(level):
        exact = closed(level)
        stability = exact_stability(system, theta, exact.z0, exact.monodromy,
                                    integrals=integrals, tol=tol)
        return tests(stability, 1.0)[kind]

    if kind == "fold":
        return _fold(closed, orbit, energy, seen)

    try:
        scale = energy_traded(orbit.t, np.hstack([orbit.q, orbit.p]),
                              float(orbit.orbit.period) / (2 * np.pi))
        found = _root_near(test, energy, FIRST_HALF_WIDTH * scale, 1e-13 * scale)
    except _NotClosed:
        return None
    if found is None:
        return None
    root, half, values = found
    return Confirmation(energy=root, bracket=(energy - half, energy + half), values=values,
                        closure=seen["closure"], difference=energy - root,
                        evaluations=seen["count"])


def _root_near(f, center: float, half: float, xtol: float):
    """``(root, half, (f(center - half), f(center + half)))``: the bracket around ``center``
    widened four times at a time (``EXPANSIONS`` tries) until ``f`` changes sign across it,
    then its root by Brent's method; ``None`` if it never does."""
    for _ in range(EXPANSIONS):
        low, high = f(center - half), f(center + half)
        if low * high < 0:
            root = brentq(f, center - half, center + half, xtol=xtol, rtol=1e-15, maxiter=100)
            return float(root), half, (low, high)
        half *= 4
    return None


def _fold(closed, orbit, energy: float, seen: dict) -> Confirmation | None:
    """The exact fold: the zero of ``dE/dT`` along the exact family parametrised by its period
    (module docstring), bracketed around the discrete orbit's period and located by Brent's
    method; each exact orbit starts from the last one found."""
    period = float(orbit.orbit.period)
    state = {"start": (np.concatenate([orbit.q[0], orbit.p[0]]), period), "energy": energy}

    def slope(level_period):
        exact = closed(state["energy"], state["start"], level_period)
        state["start"], state["energy"] = (exact.z0, exact.period), exact.energy
        return 1.0 / exact.period_derivative

    try:
        found = _root_near(slope, period, FIRST_HALF_WIDTH * period, 1e-13 * period)
        if found is None:
            return None
        slope(found[0])  # the exact fold's orbit, its energy in state
    except _NotClosed:
        return None
    _, half, values = found
    return Confirmation(energy=state["energy"], bracket=(period - half, period + half),
                        values=values, closure=seen["closure"],
                        difference=energy - state["energy"], evaluations=seen["count"])


class _NotClosed(Exception):
    """The exact flow's shooting did not close at an energy of the bracket."""
