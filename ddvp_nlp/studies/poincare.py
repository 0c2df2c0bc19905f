"""Poincare sections at a fixed energy: many orbits marched as one ensemble, their crossings of a
section located by the scheme's dense output.

Starts: on the section ``z[i] = value`` (``"q1=0"``: ``q_1 = 0``), the other coordinates
``q_j`` and momenta ``p_j`` (j != i) seeded uniform in ``box``, and the section's conjugate
momentum ``p_i >= 0`` (``direction`` ``"+"``; ``<= 0`` for ``"-"``) from ``H = E``, kept where
``H = E`` has such a root (the allowed region). ``H`` must be quadratic in ``p_i`` (a kinetic
energy, as every built-in scene): ``H(p_i) = a p_i^2 + b p_i + c`` is read off three values.

Crossings: where the section coordinate passes ``value`` between nodes ``k`` and ``k + 1`` in
the direction, the point is located on the cubic Hermite interpolant of the interval (the nodes
and the exact vector field ``f`` at both, third order, above the scheme's second), its root by
bisection to round-off: each crossing lies on the section to 1e-12 and on the energy surface to
the scheme's own nodal accuracy.

Where the orbits run: ``march_ensemble`` on ``workers`` local processes (two by default), or,
with a Dask ``scheduler`` (argument or ``$DDVP_SCHEDULER``), in blocks of orbits as tasks of
``grid.run_tasks``, like grid rows: each worker loads the scene by its name or file (``scene``)
and its compiled chunk from its own compile cache, and marches its block as a serial ensemble;
the blocks are merged back in orbit order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..physics import vector_field_function
from ..runner.tasks import Task, resolve_scheduler, run_tasks
from ..scenes import load_scene
from ..solvers import (
    Collect,
    Compilation,
    Event,
    evaluate_blocks,
    locate,
    march_ensemble,
    parse_section,
)
from ..validation import check_real

# Orbits per task on a cluster: enough that a task's start-up (loading the scene and its
# compiled chunk) is small against its marching.
CLUSTER_BLOCK = 10
# The crossings' vector field and the nodal energies: compiled where there is a compiler.
COMPILATION = Compilation()


@dataclass
class Section:
    """The crossings of all orbits: ``points`` ``(K, 2n)`` (``z = (q, p)``), ``times`` and
    ``orbit`` (index of its orbit) ``(K,)``; per orbit its start, status, nodal energy
    error ``max_k |H(z_k) - E|`` and the accuracy check's verdict with its ``t_drift``
    (``verdicts``: ``(verdict, t_drift)`` pairs; crossings after an orbit's ``t_drift`` are
    where its trajectory error had passed the tolerance). ``boundary``: for two degrees of
    freedom, ``(x, y, D)``, the discriminant ``D`` of ``H = E`` in the section's momentum on a
    grid of the free plane: ``D = 0`` bounds where the energy surface meets the section
    (`energy_boundary`)."""

    energy: float
    section: str
    direction: str
    points: np.ndarray
    times: np.ndarray
    orbit: np.ndarray
    starts: np.ndarray
    statuses: list
    energy_errors: np.ndarray
    steps: np.ndarray
    verdicts: tuple | list = ()
    boundary: tuple | None = None


def section_starts(system, theta, energy: float, section: str, count: int, *,
                   direction: str = "+", box=(-1.0, 1.0), seed: int = 0) -> np.ndarray:
    """``count`` starts ``z = (q, p)`` (rows) on the section at ``H = E`` (module docstring)."""
    n = system.n
    energy = check_real("energy", energy)
    index, value, _ = parse_section(section, n)
    if index > n:
        raise InputError(f"the section must fix a coordinate q1..q{n}, got {section!r}")
    i = index - 1
    rng = np.random.default_rng(seed)
    found = []
    for _ in range(1000):
        z = rng.uniform(box[0], box[1], size=(4 * count, 2 * n))
        z[:, i], z[:, n + i] = value, 0.0
        H = [_energy(system, z, theta, n, i, s) for s in (0.0, 1.0, -1.0)]
        c, b, a = H[0], (H[1] - H[2]) / 2, (H[1] + H[2]) / 2 - H[0]
        disc = b * b - 4 * a * (c - energy)
        with np.errstate(invalid="ignore", divide="ignore"):
            root = (-b + (1 if direction == "+" else -1) * np.sqrt(disc)) / (2 * a)
        good = np.isfinite(root) & (a > 0) & ((root >= 0) if direction == "+" else (root <= 0))
        z[:, n + i] = root
        found.extend(z[good])
        if len(found) >= count:
            starts = np.array(found[:count])
            check = system.energy(starts[:, :n], starts[:, n:], np.zeros(count), theta)
            if not np.allclose(check, energy, rtol=1e-9, atol=1e-12):
                raise InputError(f"H is not quadratic in p{i + 1}: the starts miss H = E")
            return starts
    raise InputError(f"found {len(found)} of {count} starts with H = {energy} on {section} in "
                     f"the box {box}: the energy surface does not meet the section there")


def _energy(system, z, theta, n, i, momentum):
    z = z.copy()
    z[:, n + i] = momentum
    return system.energy(z[:, :n], z[:, n:], np.zeros(z.shape[0]), theta)


def poincare_section(system, energy: float, *, section: str = "q1=0", orbits: int = 50,
                     direction: str = "+", tau0: float, t_end: float = 2000.0, params=None,
                     seed: int = 0, box=(-1.0, 1.0), scene: str | None = None,
                     scheduler: str | None = None, **march_options) -> Section:
    """March ``orbits`` starts on the section at ``energy`` as one ensemble and collect their
    crossings (module docstring). ``march_options`` go to ``march_ensemble`` (``workers``
    too); ``scheduler``: a Dask cluster's address, whose workers load ``scene`` (the name or
    file ``system`` came from)."""
    if direction not in ("+", "-"):
        raise InputError(f"direction must be '+' or '-', got {direction!r}")
    theta = system.parameter_vector(params)
    n = system.n
    starts = section_starts(system, theta, energy, section, orbits, direction=direction,
                            box=box, seed=seed)
    index, value, _ = parse_section(section, n)
    # the crossings are found where each orbit was marched: only they come back
    outputs = ensemble(system, starts[:, :n], starts[:, n:], scene=scene, scheduler=scheduler,
                       t_span=(0.0, t_end), tau0=tau0, params=params,
                       collect=Collect(output=SectionOutput(index - 1, value, direction,
                                                            energy)),
                       **march_options)
    return Section(energy, section, direction,
                   np.vstack([o["points"] for o in outputs]),
                   np.concatenate([o["times"] for o in outputs]),
                   np.concatenate([np.full(o["times"].size, k) for k, o in enumerate(outputs)]),
                   starts, [o["status"] for o in outputs],
                   np.array([o["energy_error"] for o in outputs]),
                   np.array([o["steps"] for o in outputs]),
                   [(o["verdict"], o["t_drift"]) for o in outputs],
                   energy_boundary(system, theta, energy, index - 1, value, starts))


# Points per side of the grid the energy boundary is contoured on.
BOUNDARY_GRID = 160


def energy_boundary(system, theta, energy: float, i: int, value: float, starts):
    """``(x, y, D)`` (`Section`) for two degrees of freedom, else ``None``: ``H`` read off as
    ``a p_i^2 + b p_i + c`` at each point of a grid of the free plane ``(q_j, p_j)`` (as the
    starts are), ``D = b^2 - 4a(c - E)``, where ``a > 0``; the grid spans the starts' range
    and as far again on each side."""
    n = system.n
    if n != 2:
        return None
    j = 1 - i
    ranges = []
    for column in (j, n + j):
        low, high = float(starts[:, column].min()), float(starts[:, column].max())
        half = max(high - low, 1e-3 * max(abs(low), abs(high), 1.0))
        ranges.append(np.linspace(low - half, high + half, BOUNDARY_GRID))
    x, y = np.meshgrid(*ranges)
    z = np.zeros((x.size, 2 * n))
    z[:, i], z[:, j], z[:, n + j] = value, x.ravel(), y.ravel()
    H = [_energy(system, z, theta, n, i, s) for s in (0.0, 1.0, -1.0)]
    c, b, a = H[0], (H[1] - H[2]) / 2, (H[1] + H[2]) / 2 - H[0]
    with np.errstate(invalid="ignore"):
        D = np.where(a > 0, b * b - 4 * a * (c - energy), np.nan)
    return ranges[0], ranges[1], D.reshape(x.shape)


class SectionOutput:
    """An ensemble's per-orbit output (``Collect.output``): the orbit's crossings of the
    section ``z[column] = value`` in ``direction``, its status, nodal energy error
    ``max_k |H(z_k) - E|``, step count and the accuracy check's verdict with its ``t_drift``;
    computed on the worker that marched the orbit."""

    def __init__(self, column: int, value: float, direction: str, energy: float):
        self.column, self.value, self.direction, self.energy = column, value, direction, energy

    def __call__(self, solution, i: int) -> dict:
        z = np.hstack([solution.q, solution.p])
        times, points = crossings(solution.system, solution.vector_field.theta, solution.t, z,
                                  self.column, self.value, self.direction)
        H = evaluate_blocks(solution.system, ("poincare_energy",), solution.system.H_function,
                            [solution.q, solution.p, solution.t[:, None]],
                            solution.vector_field.theta, COMPILATION)[0]
        return {"times": times, "points": points, "status": solution.status.code,
                "energy_error": float(np.max(np.abs(H - self.energy))),
                "steps": solution.steps,
                "verdict": solution.verdict.name if solution.verdict is not None else "",
                "t_drift": solution.verdict.t_drift if solution.verdict is not None else None}


def ensemble(system, q0s, p0s, *, scene: str | None = None, scheduler: str | None = None,
             **options) -> list:
    """``march_ensemble(system, q0s, p0s, **options)``, here (local workers) or, with a
    ``scheduler``, on that Dask cluster in blocks of ``CLUSTER_BLOCK`` orbits (module
    docstring). A block that fails on the cluster raises, naming its orbits and the error.
    ``progress`` (in ``options``): the blocks done on the cluster, on stderr."""
    scheduler = resolve_scheduler(scheduler)
    progress = options.pop("progress", False)
    if scheduler is None:
        return march_ensemble(system, q0s, p0s, **options)
    if scene is None:
        raise InputError("a cluster run needs scene=, the scene's name or file, which each "
                         "worker loads (a system cannot be sent to another machine)")
    options.pop("workers", None)
    tasks = [Task(f"orbits-{start}", "ddvp_nlp.studies.poincare:march_block",
                  (scene, q0s[start:start + CLUSTER_BLOCK].tolist(),
                   p0s[start:start + CLUSTER_BLOCK].tolist()), options)
             for start in range(0, len(q0s), CLUSTER_BLOCK)]
    blocks = {}
    for task, result, error in run_tasks(tasks, scheduler=scheduler, progress=progress):
        if error is not None:
            raise RuntimeError(f"orbits from {task.key.split('-')[1]} on the cluster: {error}")
        blocks[task.key] = result
    return [solution for task in tasks for solution in blocks[task.key]]


def march_block(scene: str, q0s, p0s, **options) -> list:
    """One cluster task: the scene loaded by name or file, its orbits marched in this worker
    (a serial ensemble)."""
    return march_ensemble(load_scene(scene).system, np.asarray(q0s), np.asarray(p0s),
                          workers=1, **options)


def crossings(system, theta, t, z, column: int, value: float, direction: str):
    """Times ``(K,)`` and states ``(K, 2n)`` where ``z[:, column]`` passes ``value`` in the
    direction: the section as an event ``g = z[column] - value`` of the march's dense output
    (``solvers/dense.py``: located to round-off on each interval's cubic Hermite
    interpolant). The vector field is evaluated at the two nodes of the crossing intervals
    only, by a compiled map kept per system (on every node of every orbit through a map built
    per orbit, locating the crossings of ``ddvp poincare`` took longer than marching the
    orbits: 8.6 s against 5.7 s; measured)."""
    event = section_event(column, value, direction)
    g = z[:, column] - value
    where = np.flatnonzero(event.crossed(g[:-1], g[1:]))
    if where.size == 0:
        return np.zeros(0), np.zeros((0, z.shape[1]))
    ends = np.concatenate([where, where + 1])
    slopes = np.zeros_like(z)  # only the crossing intervals' ends are read
    slopes[ends] = evaluate_blocks(system, ("poincare_field",), vector_field_function(system),
                                   [z[ends], t[ends, None]], theta, COMPILATION)[0]
    return locate(event, t, z, slopes, where)


def section_event(column: int, value: float, direction: str) -> Event:
    """The section ``z[column] = value`` crossed in ``direction`` (``"+"``, ``"-"``) as an
    event (vectorized)."""
    def g(t, q, p):
        return np.hstack([q, p])[:, column] - value
    return Event(g, 1 if direction == "+" else -1, 0, True)
