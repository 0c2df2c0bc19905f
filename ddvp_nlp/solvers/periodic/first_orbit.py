"""Starts of the periodic problem: a point on the section at the prescribed energy, a march from
it to its return to the section, and the resampling of any start onto ``N`` intervals.

The point: the section fixes one coordinate of ``z = (q, p)``; the others are those of a start
direction ``d`` (default all ones) scaled by ``s > 0``, ``z(s) = (s d with z[section] =
value)``, and ``s`` is the first root of ``H(z(s)) = E`` on ``(0, S_MAX]`` (a scan for the first
sign change, then Brent's method). Where the ray does not meet ``E``, the ray's point whose ``H``
is nearest ``E`` has its momenta scaled (``H(q, mu p)``, the kinetic energy's parabola in ``mu``):
whether the section meets the energy is a property of the whole section, not of one ray (Hill's
problem at ``E = -1.663`` on ``q2 = 0`` was refused along the ray, whose ``H`` tops out at
-1.89). Where neither meets ``E``, the same from ``H``'s least value (the ray's origin then is
no longer the coordinates': a well centred at ``q = -5`` was refused from theirs, "the section
does not meet the energy"). Only where none meets ``E`` is it an input error (which says so also
when ``H`` is not finite anywhere on the ray, and names the ray's origin).

The march: ``solvers/marching`` from that point with a small first step (it sets the discrete
energy level, within ``O(tau0^2)`` of ``E``) until the section coordinate crosses its value again
in the direction it left it (on an angle coordinate, its value plus any whole turns). Where the
energy rule's march stops before the return (its energy step breaks down on the pendulum's
rotations near q = 1.95 whatever tau0), the fixed-step midpoint rule is marched instead: the
start only has to be near the orbit. The crossing time, interpolated linearly between the two
nodes, is the period of the guess. The guess is the march resampled on ``N + 1`` times with
the energy rules' predicted site density (``predicted_grid``: ``tau ~ |w|^(-1/3)``, the step
spike of a rotation included; ``resample`` spaces them equally), the last node equal to the
first (plus the whole turns of angle coordinates); the solver moves the node times to where the
energy equations put them.
"""

from __future__ import annotations

import warnings

import casadi as ca
import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import brentq

from ...errors import InputError
from ...physics.hamiltonian import (
    flow_time_scale,
    site_density_weight_function,
    vector_field_function,
)
from ...solution import Solution
from ..marching.initial_value import march

# The scales of the start direction scanned for the energy, 0 and |z| from S_MIN |d| to S_MAX |d|
# in geometric steps (SCAN_POINTS, 0.5 % apart): the first crossing of the energy is found in
# the units the system is written in, whatever they are. A linear scan to 20 |d| missed every
# crossing of a pendulum in lengths of 1e8 (and "the energy is outside the range" was said).
S_MIN, S_MAX = 1e-12, 1e12
SCAN_POINTS = 12001
# March: first step as a fraction of the start's time scale (``flow_time_scale``: the inverse
# of the linearised flow's fastest rate, which follows the units of time whatever the units of
# the coordinates and wherever their origin; |z| / |f(z)| with floors had put the first step
# 1e5 times the swing's period in lengths of 1e-8, and 1e-4 of it in time units of 1e-4), and
# the number of such steps in the first horizon (multiplied by 4 up to MAX_HORIZONS times).
MARCH_FRACTION = 2e-3
# A return in fewer steps than COARSEST_RETURN is marched again with STEPS_PER_RETURN steps to
# the period it found (the start's time scale can be far from the orbit's: at a turning point
# on an inflection of the potential the linearised flow has no rate of its own). The pendulum's
# swing at E = 0.5 returns in 2400 steps of the first march.
COARSEST_RETURN = 500
STEPS_PER_RETURN = 2000
FIRST_HORIZON = 4000
MAX_HORIZONS = 4


def section_point(system, theta, energy: float, index: int, value: float, direction,
                  label: str, origin=None) -> np.ndarray:
    """``z = (q, p)`` on the section ``z[index - 1] = value`` at ``H(z) = energy`` (module
    docstring); ``index`` counts ``t`` as 0, as the layouts do. The ray starts at ``origin``
    (default the coordinates' origin; where that ray does not meet ``E``, from ``H``'s least
    value, found once)."""
    direction = np.asarray(direction, float)
    base = np.zeros(direction.size) if origin is None else np.asarray(origin, float)
    s = _scales()
    points = base[None, :] + s[:, None] * direction[None, :]
    points[:, index - 1] = value
    n = system.n
    H = system.energy(points[:, :n], points[:, n:], np.zeros(s.size), theta) - energy
    change = np.flatnonzero(np.sign(H[:-1]) * np.sign(H[1:]) <= 0)
    change = change[np.isfinite(H[change]) & np.isfinite(H[change + 1])]
    if change.size == 0 or (change[0] == 0 and H[0] == 0 and change.size == 1):
        finite = H[np.isfinite(H)] + energy
        if finite.size == 0:  # a singular potential along the whole ray: no range to name
            raise InputError(
                f"energy {energy!r}: H is not finite anywhere on the start's ray of the "
                f"section {label} (|z| from {S_MIN:g} |d| to {S_MAX:g} |d|, {SCAN_POINTS} points), "
                "so no start "
                "on it has that energy; give a start (--guess) or another section")
        least = least_energy(system, theta, points[np.argmin(np.where(np.isfinite(H), H,
                                                                        np.inf))])
        if least is not None and energy < least[0]:
            raise NoMotion(
                f"no motion exists at energy {energy!r}: H is at least {least[0]:.6g} (its "
                f"minimum, at q = {np.round(least[1][:n], 6).tolist()}, p = "
                f"{np.round(least[1][n:], 6).tolist()}); give an energy above it")
        off_ray = _momentum_scaled_point(system, theta, energy, points, H, n)
        if off_ray is not None:  # the section meets E off the ray: the ray was no range
            return off_ray
        if least is not None and origin is None:
            # the ray from H's minimum: where the coordinates' origin is must not decide (a
            # well centred at q = -5 was refused from the origin's ray)
            return section_point(system, theta, energy, index, value, direction, label,
                                 origin=least[1])
        raise InputError(
            f"energy {energy!r} is outside the range where the section {label} meets the "
            f"energy surface along the start's ray (from {_origin_words(origin)} along "
            f"{np.round(direction, 6).tolist()}, H runs from {np.min(finite):.6g} to "
            f"{np.max(finite):.6g}); give a start near the orbit (start=(q, p) in Python, "
            "--guess on the command line) or another section")
    k = int(change[0])

    def excess(scale):
        z = base + scale * direction
        z[index - 1] = value
        return float(system.energy(z[None, :n], z[None, n:], [0.0], theta)[0]) - energy

    # xtol relative to the bracket: an absolute 1e-15 left a root at s ~ 1e-8 to 1e-7 of itself
    root = s[k] if H[k] == 0 else brentq(excess, s[k], s[k + 1], xtol=1e-15 * s[k + 1],
                                         rtol=1e-15)
    z = base + root * direction
    z[index - 1] = value
    return z


def _origin_words(origin) -> str:
    if origin is None:
        return "the coordinates' origin"
    return f"H's least value at z = {np.round(np.asarray(origin, float), 6).tolist()}"


def _scales() -> np.ndarray:
    """0, then ``S_MIN .. S_MAX`` in geometric steps: the scales a scan along a ray tries."""
    return np.concatenate([[0.0], np.geomspace(S_MIN, S_MAX, SCAN_POINTS - 1)])


def _momentum_scaled_point(system, theta, energy, points, H, n):
    """A point of the section at ``energy`` off the start's ray: the ray's point whose ``H`` is
    nearest ``E`` with its momenta scaled by ``mu >= 0`` (``H(q, mu p)`` is the kinetic energy's
    parabola in ``mu``, so the section meets ``E`` at this ``q`` when some ``mu`` crosses it;
    whether the section meets ``E`` is a property of the whole section, not of one ray), or
    ``None``."""
    finite = np.flatnonzero(np.isfinite(H))
    if finite.size == 0:
        return None
    base = points[finite[np.argmin(np.abs(H[finite]))]].copy()
    mu = _scales()
    scaled = np.repeat(base[None, :], mu.size, axis=0)
    scaled[:, n:] *= mu[:, None]
    with np.errstate(all="ignore"):
        excess = system.energy(scaled[:, :n], scaled[:, n:], np.zeros(mu.size), theta) - energy
    change = np.flatnonzero((np.sign(excess[:-1]) * np.sign(excess[1:]) < 0)
                            & np.isfinite(excess[:-1]) & np.isfinite(excess[1:]))
    if change.size == 0:
        return None
    k = int(change[-1])  # the larger momentum: the crossing that moves through the section

    def at(m):
        z = base.copy()
        z[n:] *= m
        return float(system.energy(z[None, :n], z[None, n:], [0.0], theta)[0]) - energy
    root = brentq(at, mu[k], mu[k + 1], xtol=1e-15 * mu[k + 1], rtol=1e-15)
    z = base.copy()
    z[n:] *= root
    return z


class NoMotion(InputError):
    """An energy below the least value of ``H``: no section and no start can help."""


def least_energy(system, theta, z0: np.ndarray):
    """``(H_min, z)``: a minimum of ``H(z, 0)`` searched from ``z0`` and from the origin (BFGS
    on CasADi's gradient), or ``None`` where ``H`` is not bounded below there (the search runs
    off, as on Kepler's) or the search fails."""
    from scipy.optimize import minimize

    n = system.n
    z = ca.SX.sym("z", 2 * n)
    H = system.H_function(z[:n], z[n:], 0, theta)
    value = ca.Function("H", [z], [H, ca.gradient(H, z)])
    found = []
    for start in (np.asarray(z0, float), np.zeros(2 * n)):
        def objective(x):
            h, g = value(x)
            return float(h), np.asarray(g, float).ravel()
        try:
            with np.errstate(all="ignore"):
                result = minimize(objective, start, jac=True, method="BFGS",
                                  options={"maxiter": 200, "gtol": 1e-10})
        except (ValueError, RuntimeError, ArithmeticError):
            continue
        if np.isfinite(result.fun) and np.linalg.norm(result.jac) < 1e-6 and \
                np.max(np.abs(result.x)) < 1e6:
            found.append((float(result.fun), result.x))
    return min(found, key=lambda item: item[0]) if found else None


def march_to_return(system, theta, z0: np.ndarray, index: int, value: float, scheme,
                    angle: bool = False):
    """``(t, z)`` of a march from ``z0`` up to its first return to the section, the last row
    the interpolated crossing, or ``None`` if it does not return within the horizons (with
    ``scheme``, then with fixed steps: module docstring). On an
    ``angle`` coordinate the section is met at ``value + 2 pi k`` for any ``k`` (a rotation
    returns one turn on)."""
    f = np.asarray(vector_field_function(system)(z0, 0.0, theta)).ravel()
    heading = np.sign(f[index - 1])
    if heading == 0:
        return None  # the flow is tangent to the section here: no crossing to look for
    scale = flow_time_scale(system, z0, 0.0, theta)
    if not 0 < scale < np.inf:
        return None
    tau0 = MARCH_FRACTION * scale
    for rule in dict.fromkeys((scheme, "fixed")):
        with warnings.catch_warnings():  # a breakdown of the start's march is handled here
            warnings.simplefilter("ignore", RuntimeWarning)
            traced = _march_until_return(system, theta, z0, index, value, rule, angle,
                                         heading, tau0)
            if traced is not None and traced[0].size - 2 < COARSEST_RETURN:
                # the time scale at the start was not the orbit's: march again on the period
                again = _march_until_return(system, theta, z0, index, value, rule, angle,
                                            heading, traced[0][-1] / STEPS_PER_RETURN)
                traced = again if again is not None else traced
        if traced is not None:
            return traced
    return None


def _march_until_return(system, theta, z0, index, value, scheme, angle, heading, tau0):
    """The march of `march_to_return` with one rule, horizon after horizon."""
    n = system.n
    horizon = FIRST_HORIZON * tau0
    for _ in range(MAX_HORIZONS):
        run = march(system, z0[:n], z0[n:], (0.0, horizon), tau0=tau0, scheme=scheme,
                    params=dict(zip(system.params, theta, strict=True)), accuracy=None)
        t, z = run.t, np.hstack([run.q, run.p])
        c = z[:, index - 1] - value
        if angle:  # the offset reduced to (-pi, pi]: its jumps at pi are not crossings of 0
            c = np.pi - np.mod(np.pi - c, 2 * np.pi)
        c = heading * c
        back = np.flatnonzero((c[:-1] < 0) & (c[1:] >= 0))
        if back.size:
            k = int(back[0]) + 1
            share = -c[k - 1] / (c[k] - c[k - 1])
            crossing = z[k - 1] + share * (z[k] - z[k - 1])
            return (np.append(t[:k], t[k - 1] + share * (t[k] - t[k - 1])),
                    np.vstack([z[:k], crossing]))
        if not run.success:
            return None
        horizon *= 4
    return None


def closing_shift(first: np.ndarray, last: np.ndarray, angles=()) -> np.ndarray:
    """``z_N - z_0`` of the closed orbit near a start from ``first`` to ``last``: ``2 pi`` times
    the whole turns of each angle coordinate (indices into ``z``), 0 elsewhere."""
    shift = np.zeros(np.size(first))
    for i in angles:
        shift[i] = 2 * np.pi * np.round((last[i] - first[i]) / (2 * np.pi))
    return shift


def resample(t, z, intervals: int, angles=()) -> tuple[np.ndarray, np.ndarray]:
    """``N + 1`` nodes on equally spaced times from ``t[0]`` to ``t[-1]`` (``t`` shifted to start
    at 0), cubic between the given nodes, the last node set equal to the first (plus the whole
    turns of the ``angles``, `closing_shift`)."""
    t = np.asarray(t, float) - float(t[0])
    z = np.asarray(z, float)
    grid = np.linspace(0.0, t[-1], intervals + 1)
    zs = CubicSpline(t, z, axis=0)(grid) if t.size >= 4 else np.column_stack(
        [np.interp(grid, t, z[:, j]) for j in range(z.shape[1])])
    zs[-1] = zs[0] + closing_shift(zs[0], zs[-1], angles)
    return grid, zs


def guess_nodes(guess, n: int, intervals: int, angles=()):
    """``(t, z)`` of ``N + 1`` nodes from a user's start: a `Solution` or a mapping with
    ``t``, ``q``, ``p`` (one period, last node at or near the first). Taken as it is when it has
    ``N + 1`` rows (a previous solve on the same grid), else resampled."""
    if isinstance(guess, Solution):
        guess = {"t": guess.t, "q": guess.q, "p": guess.p}
    try:
        t = np.asarray(guess["t"], float).ravel()
        z = np.hstack([np.asarray(guess["q"], float).reshape(t.size, n),
                       np.asarray(guess["p"], float).reshape(t.size, n)])
    except (KeyError, TypeError, ValueError, IndexError):
        raise InputError(f"guess must be a Solution or a mapping with t (M,), q and p (M, {n}) "
                         f"arrays, got {type(guess).__name__}") from None
    if t.size < 3 or not np.all(np.isfinite(z)) or not np.all(np.diff(t) > 0):
        raise InputError(f"guess must have at least 3 nodes with finite values and increasing "
                         f"times, got {t.size} nodes")
    if t.size == intervals + 1:
        z = z.copy()
        z[-1] = z[0] + closing_shift(z[0], z[-1], angles)
        return t - t[0], z
    return resample(t, z, intervals, angles)


# The predicted steps' ratio to the typical one where w = f' H_zz f vanishes: the density
# |w|^(1/3) is floored at this fraction of its median (the discrete rotation's step spike at the
# level curve's inflection is 3-5x the typical step at N = 100..800 on the pendulum at E = 2.5;
# measured).
SPIKE = 4.0


def predicted_grid(system, theta, t, z, intervals: int, angles=()):
    """``N + 1`` nodes on the march ``(t, z)`` at the energy rules' site density: ``tau ~
    |w|^(-1/3)``, ``w = f' H_zz f`` (``H(z_mid) = H(z) - tau^2 w / 8``: the interval energy's
    error term that the energy equation balances), floored so that no predicted step exceeds
    ``SPIKE`` typical ones. Where ``w`` changes sign (a pendulum's rotation, at the inflection
    of its level curve) the discrete orbit's steps have a spike; with uniform times Newton
    stalled at every N (module docstring of ``orbit.py``). The nodes split the integral of the
    density over the march into equal parts, cubic between the march's nodes; the last node is
    the first plus the whole turns of the ``angles``."""
    t = np.asarray(t, float) - float(t[0])
    z = np.asarray(z, float)
    n = system.n
    middle = (z[:-1] + z[1:]) / 2
    w = np.asarray(site_density_weight_function(system).map(middle.shape[0])(
        middle[:, :n].T, middle[:, n:].T, ((t[:-1] + t[1:]) / 2)[None, :], theta)).ravel()
    density = np.abs(w) ** (1 / 3)
    floor = np.median(density) / SPIKE if np.any(density > 0) else 1.0
    density = np.maximum(density, floor)
    mass = np.concatenate([[0.0], np.cumsum(density * np.diff(t))])
    grid = np.interp(np.linspace(0.0, mass[-1], intervals + 1), mass, t)
    grid[0], grid[-1] = 0.0, t[-1]
    zs = CubicSpline(t, z, axis=0)(grid) if t.size >= 4 else np.column_stack(
        [np.interp(grid, t, z[:, j]) for j in range(z.shape[1])])
    zs[-1] = zs[0] + closing_shift(zs[0], zs[-1], angles)
    return grid, zs
