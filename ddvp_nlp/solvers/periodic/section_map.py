"""The return map of a section at a prescribed energy, by the exact flow, for two degrees of
freedom: where the section meets the energy surface, the returns of a point, and the derivative
of the map (the tools of ``search.py``).

The section ``q_s = v`` at energy ``E``: a point is ``u = (q_o, p_o)`` (the other position and its
momentum); the section's momentum ``p_s`` is the root of ``H(z) = E`` on the branch where the
flow crosses the section upwards, ``q_s' = dH/dp_s > 0`` (or downwards, ``direction = -1``).
``H`` is read as a quadratic ``a p_s^2 + b p_s + c`` in ``p_s`` (checked on the section, refused
otherwise), so the accessible region, where ``b^2 - 4 a (c - E) >= 0``, is computed, not guessed.

A return is a crossing of ``q_s = v`` along the exact flow (``exact/flow.py``, DOP853 at the
exact flow's tolerance): a sign change of ``q_s - v`` between two accepted steps, located on the
run's dense output by Brent's method. The derivative of the ``k``-th return ``z_k = phi_{t_k}(z)``
at a moving crossing time is ``(I - f(z_k) e_s^T / f_s(z_k)) Y dz/du`` (``Y`` the flow's Jacobian
by its variational equations, ``dz/du`` the section's parametrisation: ``dp_s/du = -H_u / H_p_s``).
"""

from __future__ import annotations

import math
import multiprocessing
import os
import signal
from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.optimize import brentq

from ...errors import InputError
from ...physics.hamiltonian import vector_field_function
from ..exact.flow import exact_flow
from ..exact.tolerance import EXACT_TOLERANCE
from .orbit import parse_section

RTOL = EXACT_TOLERANCE.flow_rtol
# a run of a seed stops after this many attempted steps (a near-collision is then said, not waited
# for); a shooting evaluation is allowed ten times more
SEED_ATTEMPTS = 40_000


@dataclass(frozen=True)
class SearchSection:
    """The section ``q_s = v`` of a two-degree-of-freedom system: ``index`` (``s``, 0-based),
    ``other`` (``o``), ``value``, ``label`` (``"q2=0"``)."""

    index: int
    other: int
    value: float
    label: str

    @property
    def free(self) -> list[int]:
        """Indices in ``z`` of ``u = (q_o, p_o)``."""
        return [self.other, 2 + self.other]


def parse_search_section(section, system) -> SearchSection:
    """``"q2=0"`` (or ``("q2", 0.0)``) checked against ``system``: a position coordinate of a
    system of two degrees of freedom."""
    if getattr(system, "n", None) != 2:
        raise InputError(f"system: the search of a section works on two degrees of freedom, "
                         f"{getattr(system, 'name', 'the system')!r} has n = "
                         f"{getattr(system, 'n', None)!r}")
    index, value, label = parse_section(section, system.n)
    if index > system.n:
        raise InputError(f"section must fix a position coordinate (q1 or q2) for a search of "
                         f"returns, got {section!r}")
    return SearchSection(index=index - 1, other=2 - index, value=value, label=label)


class SectionAtEnergy:
    """The section at energy ``E``: its points ``z(u)``, their accessibility and the
    derivatives of the parametrisation (module docstring)."""

    def __init__(self, system, theta, section: SearchSection, energy: float):
        self.system, self.theta, self.section, self.energy = system, theta, section, energy
        z = ca.SX.sym("z", 4)
        H = ca.substitute(system.H, ca.vertcat(system.q, system.p), z)
        self._gradient = ca.Function("dH", [z, system.theta], [ca.gradient(H, z)])
        self.field = vector_field_function(system)

    def _H(self, z: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            return self.system.energy(z[:, :2], z[:, 2:], np.zeros(len(z)), self.theta)

    def _on_section(self, u: np.ndarray, momentum: float) -> np.ndarray:
        u = np.atleast_2d(np.asarray(u, float))
        z = np.zeros((len(u), 4))
        z[:, self.section.index] = self.section.value
        z[:, self.section.free] = u
        z[:, 2 + self.section.index] = momentum
        return z

    def _probe(self, u) -> np.ndarray:
        """A momentum step per row on the scale of ``H`` there (``sqrt |H(p_s = 0)|``), so
        that the differences below do not cancel where ``H`` is large."""
        zero = np.abs(self._H(self._on_section(u, 0.0)))
        typical = np.median(zero[np.isfinite(zero) & (zero > 0)]) if np.any(zero > 0) else 1.0
        return np.sqrt(np.where(np.isfinite(zero), zero, 0.0) + typical)

    def _at(self, u, momenta) -> np.ndarray:
        z = self._on_section(u, 0.0)
        z[:, 2 + self.section.index] = momenta
        return self._H(z)

    def quadratic(self, u) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(a, b, c)`` of ``H = a p_s^2 + b p_s + c`` at each row of ``u``."""
        u = np.atleast_2d(np.asarray(u, float))
        step = self._probe(u)
        minus, zero, plus = (self._at(u, m * step) for m in (-1.0, 0.0, 1.0))
        with np.errstate(all="ignore"):  # a singular point of H: NaN, not accessible
            return ((plus + minus) / 2 - zero) / step ** 2, (plus - minus) / (2 * step), zero

    def check_quadratic(self, u) -> None:
        """Refuse an ``H`` that is not quadratic in the section's momentum (on rows ``u``)."""
        u = np.atleast_2d(np.asarray(u, float))
        a, b, c = self.quadratic(u)
        step = self._probe(u)
        for m in (2.0, -3.0):
            momenta = m * step
            H = self._at(u, momenta)
            fit = a * momenta ** 2 + b * momenta + c
            ok = np.isfinite(H) & np.isfinite(fit)
            scale = np.abs(a * momenta ** 2) + np.abs(b * momenta) + np.abs(c)
            if np.any(np.abs(H - fit)[ok] > 1e-8 * scale[ok]) or np.any(a[ok] <= 0):
                raise InputError(
                    f"section {self.section.label}: H is not a convex quadratic in p"
                    f"{self.section.index + 1}, so its root at the energy is not computed "
                    "here; the search needs a kinetic energy quadratic in the momenta")

    def points(self, u, direction: int = 1) -> np.ndarray:
        """``z(u)`` at ``H = E`` crossing the section in ``direction``; rows of NaN where the
        energy allows no motion."""
        a, b, c = self.quadratic(u)
        with np.errstate(all="ignore"):
            root = (-b + direction * np.sqrt(b * b - 4 * a * (c - self.energy))) / (2 * a)
        z = self._on_section(u, 0.0)
        z[:, 2 + self.section.index] = root
        z[~np.isfinite(root)] = np.nan
        return z

    def tangent(self, z: np.ndarray) -> np.ndarray:
        """``dz/du`` (4 x 2) at a point of the section at the energy."""
        g = np.asarray(self._gradient(z, self.theta), float).ravel()
        s, free = 2 + self.section.index, self.section.free
        T = np.zeros((4, 2))
        for j, i in enumerate(free):
            T[i, j] = 1.0
            T[s, j] = -g[i] / g[s]
        return T

    def velocity(self, z: np.ndarray) -> np.ndarray:
        return np.asarray(self.field(z, 0.0, self.theta), float).ravel()


@dataclass(frozen=True)
class Escape:
    """Where a run's motion has left: a position further than ``radius`` from ``centre`` (``q``,
    one value per position; ``search._scales``: the window's middle on the section, four times
    the window's half-width), in any of its components."""

    centre: tuple
    radius: float

    def beyond(self, q: np.ndarray) -> np.ndarray:
        """Whether each row of ``q`` has left."""
        return np.max(np.abs(q - np.asarray(self.centre, float)), axis=1) > self.radius


@dataclass
class Returns:
    """The crossings of the section along a run: times ``t`` (k,), states ``z`` (k, 4) and
    directions (k,) (``+1`` upwards); ``reason`` why the run ended early (``""``: it reached
    its horizon)."""

    t: np.ndarray
    z: np.ndarray
    direction: np.ndarray
    reason: str = ""
    reached: float = 0.0


def returns(geometry: SectionAtEnergy, z0, horizon: float, atol, *,
            attempts: int = SEED_ATTEMPTS, escape: Escape | None = None, run=None) -> Returns:
    """Every crossing of the section by the exact flow from ``z0`` over ``(0, horizon]``
    (module docstring; a negative ``horizon``: backwards in time, the crossings in the order
    met); ``escape``: where the motion has left (an `Escape`; ``None``: nowhere)."""
    section = geometry.section
    flow = exact_flow(geometry.system)
    with np.errstate(all="ignore"):
        run = run or flow.run(z0, 0.0, horizon, geometry.theta, rtol=RTOL, atol=atol,
                              max_attempts=attempts)
    t, w = run.nodes()
    z = w[:, :4]
    reason = ""
    with np.errstate(invalid="ignore"):
        far = np.flatnonzero(~np.all(np.isfinite(z), axis=1) |
                             (escape.beyond(z[:, :2]) if escape else False))
    if far.size:
        t, z = t[:far[0]], z[:far[0]]
        reason = (f"escaped (|q - q_c| > {escape.radius if escape else np.inf:.3g}, q_c the "
                  f"window's centre, at t = {run.t_old[min(far[0], run.steps - 1)]:.4g})")
    elif not run.success:
        reason = (f"the flow stopped at t = {run.t_reached:.4g} ({run.status}; a collision or a "
                  "near one)")
    c = z[:, section.index] - section.value
    where = np.flatnonzero((c[:-1] * c[1:] < 0) | ((c[1:] == 0) & (np.arange(1, c.size) > 1)))
    times, states = [], []
    for k in where:
        def offset(time):
            return float(run.z([time])[0, section.index]) - section.value
        a, b = sorted((t[k], t[k + 1]))  # a backward run's times decrease
        time = t[k + 1] if c[k + 1] == 0 else brentq(
            offset, a, b, xtol=1e-15 * max(abs(a), abs(b), 1e-300), rtol=1e-15)
        times.append(time)
        states.append(run.z([time])[0])
    states = np.reshape(states, (-1, 4))
    ups = np.sign([geometry.velocity(s)[section.index] for s in states]) if len(states) else \
        np.zeros(0)
    return Returns(np.asarray(times), states, ups, reason, float(t[-1]) if t.size else 0.0)


def return_derivative(geometry: SectionAtEnergy, z0, t_return: float, atol):
    """``(z_k, D)``: the state at a crossing ``t_return`` from ``z0`` (a point of the section)
    and ``D = d u_k / d u`` (2 x 2) of the map (module docstring)."""
    tangent_flow = exact_flow(geometry.system, tangent=2, dense=False)
    with np.errstate(all="ignore"):
        run = tangent_flow.run(z0, 0.0, t_return, geometry.theta, rtol=RTOL, atol=atol,
                               Y0=geometry.tangent(z0), max_attempts=10 * SEED_ATTEMPTS)
    if not run.success or not np.all(np.isfinite(run.w_end)):
        return None, None
    z, Y = run.z_end, run.Y_end
    f = geometry.velocity(z)
    s = geometry.section.index
    moved = Y - np.outer(f, Y[s]) / f[s]
    return z, moved[geometry.section.free]


# Blocks of seeds per worker: the seeds' runs differ in length (one escapes at once, another
# makes its returns) and a shot takes from milliseconds to a second (Hill at E = -2.14: 30
# shots from the whole map's minima, 9 s), so each worker takes many small blocks, the next as
# soon as it is free (30 shots: one a block; 400 seeds' runs: 13 a block).
SEED_BLOCKS_PER_WORKER = 16


class SeedPool:
    """Where the seeds' work runs (``search.py``): in this process (``workers=1``), or on
    ``workers`` processes forked from this one when the pool is entered, which inherit the
    section's geometry and its exact flows (built here first: nothing is compiled in a
    worker). ``map(function, items)`` is ``[function(geometry, *item) for item in items]``,
    the items sent in blocks of consecutive ones and the results merged back in order: the
    same calls with the same arguments either way, so the same results. ``function`` must be
    a module-level function (it is sent by name) and its results picklable."""

    def __init__(self, geometry: SectionAtEnergy, workers: int = 1):
        self.geometry, self.workers, self.pool = geometry, workers, None

    def __enter__(self):
        if self.workers > 1 and "fork" in multiprocessing.get_all_start_methods() \
                and not multiprocessing.current_process().daemon:
            exact_flow(self.geometry.system)
            exact_flow(self.geometry.system, tangent=2, dense=False)
            context = multiprocessing.get_context("fork")
            self.pool = context.Pool(self.workers, initializer=_install_seeds,
                                     initargs=(self.geometry, os.getpid()))
        return self

    def __exit__(self, kind, value, traceback):
        if self.pool is None:
            return
        if kind is None:
            self.pool.close()
        else:  # Ctrl-C, SIGTERM, a failed block: no worker outlives the search
            self.pool.terminate()
        self.pool.join()
        self.pool = None

    def map(self, function, items) -> list:
        items = list(items)
        if self.pool is None or len(items) < 2:
            return [function(self.geometry, *item) for item in items]
        size = max(1, math.ceil(len(items) / (self.workers * SEED_BLOCKS_PER_WORKER)))
        blocks = [(function, items[i:i + size]) for i in range(0, len(items), size)]
        return [result for part in self.pool.imap(_run_seeds, blocks) for result in part]


_GEOMETRY: SectionAtEnergy | None = None


def _install_seeds(geometry: SectionAtEnergy, parent: int) -> None:
    """A worker's initializer: the geometry inherited through ``fork`` (nothing pickled), the
    parent's Ctrl-C handling undone and the worker tied to its parent's life (as the
    ensemble's workers, ``marching/ensemble.py``)."""
    from ..marching.ensemble import end_with_parent

    global _GEOMETRY
    _GEOMETRY = geometry
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    end_with_parent(parent)


def _run_seeds(block) -> list:
    function, items = block
    return [function(_GEOMETRY, *item) for item in items]
