"""Chaos maps over a section: MEGNO and the largest Lyapunov exponent of every cell of a grid of
starts at a fixed energy, each cell a march with its tangent vector (``solvers/chaos/``).

Cells (a two-degree-of-freedom scene): the section ``q_i = value`` (``"q1=0"``), the grid's
two axes the other coordinate and its momentum (``"q2=A:B:N,p2=C:D:M"``: ``N`` values of
``q_2`` from ``A`` to ``B``, ``M`` of ``p_2``), and the section's conjugate momentum
``p_i = +sqrt(...)`` from ``H = E`` (the larger root of ``H(p_i) = E``, ``H`` quadratic in
``p_i``, as in ``poincare.py``). A cell where ``H = E`` has no such root lies outside the
energy surface: it is marked ``not_run`` and its indicators are NaN. Cells are numbered with
the first axis fastest (cell ``j * N + i`` at ``(q2_i, p2_j)``).

How they run: blocks of ``BLOCK`` cells are tasks (``runner/tasks.py``: in this process,
on local worker processes, or on a Dask cluster); each returns only its cells' indicators,
which are journalled as they arrive (``runner/journal.py``: ``cells.csv``), so a killed map
run again with the same settings goes on from its finished blocks. ``shard=(k, N)`` runs the
blocks ``b`` with ``b % N == k - 1`` into a folder of their own (``shard-k-of-N``), its own
journal and part file: the pattern of a SLURM job array, one array task per shard, with no
scheduler and no shared lock; `merge_shards` joins the parts once all are done.
"""

from __future__ import annotations

import functools
import json
import math
import re
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..runner.journal import run_journalled
from ..runner.tasks import Task
from ..scenes import load_scene
from ..solvers import chaos_indicators, parse_section
from ..validation import check_integer, check_memory, check_real

BLOCK = 25  # cells per task: a task's start-up (the scene, its compiled chunk) is small
COLUMNS = ("key", "status", "first", "count", "cells", "cpu_s")
KEYS = ("megno", "lyapunov", "fli", "megno_half", "lyapunov_half", "t", "steps")
MAX_CELLS = 10_000_000


@dataclass
class ChaosGrid:
    """The grid of a chaos map: the section (``index``: 0-based coordinate, ``value``), the two
    axes (names such as ``"q2"``, ``"p2"``; their values) and every cell's start."""

    section: str
    index: int
    value: float
    names: tuple
    axes: tuple
    text: str
    starts: np.ndarray = field(default=None)
    runnable: np.ndarray = field(default=None)

    @property
    def shape(self) -> tuple[int, int]:
        """``(M, N)``: rows are the second axis, columns the first."""
        return self.axes[1].size, self.axes[0].size


def parse_grid(text: str, section: str, n: int) -> ChaosGrid:
    """``"q2=A:B:N,p2=C:D:M"`` for the section ``section`` of an ``n = 2`` system: the other
    coordinate and its momentum, each ``FROM:TO:COUNT`` (``COUNT >= 2``, ``FROM < TO``); an
    ``InputError`` naming ``grid`` or ``section`` and the value otherwise."""
    if n != 2:
        raise InputError(f"a chaos map needs a scene of two degrees of freedom, got n = {n}")
    try:
        index, value, _ = parse_section(section, n)
    except InputError as exc:
        raise InputError(f"section {section!r}: {exc}") from None
    if index > n:
        raise InputError(f"section must fix a coordinate q1 or q2, got {section!r}")
    other = 2 - index  # 0-based index of the free coordinate
    wanted = (f"q{other + 1}", f"p{other + 1}")
    parts = [part.strip() for part in str(text).split(",")]
    found = {}
    for part in parts:
        match = re.fullmatch(r"([qp]\d+)=([^:]+):([^:]+):([^:]+)", part)
        if not match:
            raise InputError(f"grid must be '{wanted[0]}=A:B:N,{wanted[1]}=C:D:M', got "
                             f"{text!r}")
        name = match.group(1)
        if name not in wanted or name in found:
            raise InputError(f"grid must give {wanted[0]} and {wanted[1]} once each (the "
                             f"section {section} fixes q{index}), got {text!r}")
        found[name] = _axis(name, *match.group(2, 3, 4))
    if set(found) != set(wanted):
        raise InputError(f"grid must give {wanted[0]} and {wanted[1]}, got {text!r}")
    cells = found[wanted[0]].size * found[wanted[1]].size
    check_memory("grid", cells, cells * 400.0, "the map's cells")
    return ChaosGrid(section, index - 1, value, wanted, (found[wanted[0]], found[wanted[1]]),
                     text)


def _axis(name: str, first: str, last: str, count: str) -> np.ndarray:
    try:
        a, b, k = float(first), float(last), int(count)
    except ValueError:
        raise InputError(f"grid {name}={first}:{last}:{count}: FROM and TO must be numbers "
                         "and COUNT an integer") from None
    check_real(f"grid {name} FROM", a)
    check_real(f"grid {name} TO", b)
    check_integer(f"grid {name} COUNT", k, minimum=2, maximum=MAX_CELLS)
    if not a < b:
        raise InputError(f"grid {name}: FROM must be < TO, got {first}:{last}")
    return np.linspace(a, b, k)


def place_cells(system, theta, energy: float, grid: ChaosGrid) -> ChaosGrid:
    """Every cell's start ``z = (q, p)`` on the section at ``H = E`` and whether it has one
    (module docstring); NaN starts where not."""
    energy = check_real("energy", energy)
    n, i = 2, grid.index
    a, b = np.meshgrid(grid.axes[0], grid.axes[1])  # rows: second axis
    z, (c, slope, curve) = _on_section(system, theta, grid, a, b)
    with np.errstate(invalid="ignore", divide="ignore"):
        root = (-slope + np.sqrt(slope * slope - 4 * curve * (c - energy))) / (2 * curve)
    runnable = np.isfinite(root) & (curve > 0) & (root >= 0)
    z[:, n + i] = np.where(runnable, root, np.nan)
    if runnable.any():
        check = system.energy(z[runnable, :n], z[runnable, n:], np.zeros(runnable.sum()), theta)
        if not np.allclose(check, energy, rtol=1e-9, atol=1e-12):
            raise InputError(f"H is not quadratic in p{i + 1}: the starts miss H = E")
    grid.starts, grid.runnable = z, runnable
    return grid


def _on_section(system, theta, grid: ChaosGrid, a: np.ndarray, b: np.ndarray):
    """The states on the section at the axes' values ``a``, ``b`` (the section's momentum 0)
    and ``H`` there as the quadratic ``c + slope p + curve p^2`` in the section's momentum
    ``p`` (from ``H`` at ``p`` = 0, 1 and -1)."""
    n, i, j = 2, grid.index, 1 - grid.index
    z = np.zeros((a.size, 2 * n))
    z[:, i], z[:, j], z[:, n + j] = grid.value, a.ravel(), b.ravel()
    H = []
    for momentum in (0.0, 1.0, -1.0):
        z[:, n + i] = momentum
        H.append(system.energy(z[:, :n], z[:, n:], np.zeros(z.shape[0]), theta))
    z[:, n + i] = 0.0
    return z, (H[0], (H[1] - H[2]) / 2, (H[1] + H[2]) / 2 - H[0])


@functools.lru_cache(maxsize=4)
def scene_system(scene: str):
    """The system of ``scene`` (name or file), loaded once per process: a worker's tasks share
    it and so its compiled chunk."""
    return load_scene(scene).system


def chaos_block(scene: str, starts: list, *, t_end: float, tau0: float, params=None) -> dict:
    """One task: the indicators of ``starts`` (rows ``z``), each a march to ``t_end`` with its
    tangent, also at ``t_end / 2``; only the numbers come back."""
    system = scene_system(scene)
    n = system.n
    started = time.process_time()
    cells = []
    for z in np.asarray(starts, float):
        r = chaos_indicators(system, z[:n], z[n:], (0.0, t_end), tau0=tau0, params=params,
                             snapshots=(t_end / 2,))
        cells.append([r.status.code, r.megno, r.lyapunov, r.fli, r.snapshots["megno"][0],
                      r.snapshots["lyapunov"][0], r.t, r.steps])
    return {"status": "success", "cells": json.dumps(cells),
            "cpu_s": f"{time.process_time() - started:.4f}"}


@dataclass
class ChaosMap:
    """The indicators of every cell (``cells``: ``M * N``, the first axis fastest): ``megno``,
    ``lyapunov``, ``fli``, the same at ``t_end / 2`` (``megno_half``, ``lyapunov_half``), the
    last node's time ``t`` and ``steps`` (NaN, 0 where not run), ``status`` per cell
    (``not_run`` outside the energy surface, else the march's), the CPU seconds of the blocks
    run now, and how many blocks ran now (the rest came from the journal)."""

    grid: ChaosGrid
    energy: float
    t_end: float
    tau0: float
    values: dict
    status: np.ndarray
    cpu_s: float
    blocks_run: int
    blocks: int
    shard: tuple | None = None


def map_tasks(grid: ChaosGrid, scene: str, *, t_end: float, tau0: float, params) -> list:
    """The blocks of runnable cells as tasks, in cell order."""
    cells = np.flatnonzero(grid.runnable)
    options = {"t_end": float(t_end), "tau0": float(tau0), "params": params or None}
    return [Task(f"cells-{int(cells[s])}", "ddvp_nlp.studies.chaos_map:chaos_block",
                 (scene, grid.starts[cells[s:s + BLOCK]].tolist()), options)
            for s in range(0, cells.size, BLOCK)]


def parse_shard(text: str | None) -> tuple[int, int] | None:
    """``"K/N"`` (``1 <= K <= N``) as ``(K, N)``."""
    if text is None:
        return None
    match = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", str(text))
    if not match or not 1 <= int(match.group(1)) <= int(match.group(2)):
        raise InputError(f"shard must be K/N with 1 <= K <= N, got {text!r}")
    return int(match.group(1)), int(match.group(2))


def shard_folder(k: int, count: int) -> str:
    return f"shard-{k}-of-{count}"


def run_map(system, scene: str, energy: float, grid: ChaosGrid, out, *, t_end: float,
            tau0: float, params=None, workers: int | None = 1, scheduler=None, shard=None,
            resume: bool = True, progress: bool = False) -> tuple[ChaosMap, object, list]:
    """The map's tasks (all, or those of ``shard`` ``(k, N)``) run and journalled in ``out``
    (``cells.csv``); returns the `ChaosMap` of the cells run (a shard's others have status
    ``other_shard``), the journal's path and its rows, for `commit_journal` with the map's
    files."""
    if not t_end > 0:
        raise InputError(f"t_end must be > 0 (the cells start at t = 0), got {t_end!r}")
    tasks = map_tasks(grid, scene, t_end=t_end, tau0=tau0, params=params)
    if shard is not None:
        tasks = tasks[shard[0] - 1::shard[1]]
    if tasks:  # the compiled chunk built (or loaded) here, once, before any worker needs it
        first = np.asarray(tasks[0].args[1][0])
        chaos_indicators(system, first[:2], first[2:], (0.0, min(10 * tau0, t_end)),
                         tau0=tau0, params=params)
    path = out / "cells.csv"
    rows, ran = run_journalled(tasks, path, COLUMNS, failure_row=_failure_row, parse=dict,
                               resume=resume, workers=workers, scheduler=scheduler,
                               progress=progress, commit=False)
    cells = grid.starts.shape[0]
    values = {key: np.full(cells, math.nan) for key in KEYS}
    status = np.where(grid.runnable, "other_shard" if shard else "task_failed", "not_run")
    status = status.astype(object)
    cpu = 0.0
    for task, row in zip(tasks, rows, strict=True):
        indices = _task_cells(grid, task)
        if row["status"] != "success":
            status[indices] = row["status"]
            continue
        cpu += float(row["cpu_s"] or 0.0)
        for index, cell in zip(indices, json.loads(row["cells"]), strict=True):
            status[index] = cell[0]
            for key, number in zip(KEYS, cell[1:], strict=True):
                values[key][index] = number
    result = ChaosMap(grid, float(energy), float(t_end), float(tau0), values,
                      status.astype(str), cpu, ran, len(tasks), shard)
    return result, path, rows


def _task_cells(grid: ChaosGrid, task: Task) -> np.ndarray:
    first = int(task.key.split("-")[1])
    cells = np.flatnonzero(grid.runnable)
    start = int(np.searchsorted(cells, first))
    return cells[start:start + len(task.args[1])]


def _failure_row(task: Task, error: str) -> dict:
    return {"status": error.partition(":")[0], "cells": "[]", "cpu_s": ""}


def map_arrays(result: ChaosMap, system, theta) -> dict:
    """The arrays of ``chaos.npz`` (``io/chaos_files.py``), the energy boundary included: the
    least ``H`` over the section's momentum on a fine grid of the axes (``H`` is quadratic in
    it: its least value is at the vertex)."""
    grid = result.grid
    fine = [np.linspace(axis[0], axis[-1], 300) for axis in grid.axes]
    a, b = np.meshgrid(*fine)
    n = 2
    _, (c, slope, curve) = _on_section(system, theta, grid, a, b)
    with np.errstate(invalid="ignore", divide="ignore"):
        least = np.where(curve > 0, c - slope ** 2 / (4 * curve), np.nan)
    return {"q0": grid.starts[:, :n], "p0": grid.starts[:, n:], **result.values,
            "status": result.status, "axis_names": np.array(grid.names),
            "axis_0": grid.axes[0], "axis_1": grid.axes[1], "shape": np.array(grid.shape),
            "energy": result.energy, "t_end": result.t_end, "tau0": result.tau0,
            "section": grid.section, "grid": grid.text,
            "boundary_0": fine[0], "boundary_1": fine[1],
            "boundary_H": least.reshape(b.shape)}


def merge_shards(folder) -> tuple[dict, dict]:
    """The part files of every ``shard-K-of-N`` folder in ``folder`` joined: ``(arrays,
    parts)``. Each part is read through its manifest (checksums); the parts must be ``N`` of
    one job (the same ``N`` and settings, the scene's file the same by its hash), each part
    whole (every array, of the map's size), every cell from exactly one of them and every
    cell a part calls a success with finite figures; else an ``InputError`` names the shard
    and what is wrong. A folder named like a shard that is none (``shard-1-of-3.bak``) is
    refused by name rather than guessed at."""
    from pathlib import Path

    from ..io.atomic import read_set
    from ..io.chaos_files import read_arrays

    folder = Path(folder)
    where = f"folder {str(folder)!r}"
    count = _shard_count(folder, where)
    parts, merged, settings, owner = {}, None, None, None
    for k in range(1, count + 1):
        name = shard_folder(k, count)
        if not (folder / name).is_dir():
            raise InputError(f"{where}: {name} is missing (that shard has "
                             "not finished, or ran elsewhere)")
        meta, files = read_set(folder / name, required=("part.npz",))
        arrays = _whole_part(read_arrays(files["part.npz"]), name, where,
                             None if merged is None else merged["status"].size)
        if settings is None:
            settings, merged = meta.get("settings"), dict(arrays)
            merged["status"] = arrays["status"].astype(object)
            owner = np.full(arrays["status"].size, "", dtype=object)
        elif meta.get("settings") != settings:
            raise InputError(f"{where}: {name} was run with other settings "
                             f"than shard 1 ({meta.get('settings')} against {settings})")
        if not np.array_equal(arrays["status"] == "not_run", merged["status"] == "not_run"):
            raise InputError(f"{where}: {name} and shard 1 differ on which cells are off the "
                             "energy surface (parts of different jobs?)")
        ran = ~np.isin(arrays["status"], ("other_shard", "not_run"))
        twice = ran & (owner != "")
        if twice.any():
            raise InputError(f"{where}: {name} and {owner[twice][0]} both hold "
                             f"{int(twice.sum())} cells (parts of different jobs?)")
        owner[ran] = name
        for key in (*KEYS, "status"):
            merged[key][ran] = arrays[key][ran]
        parts[name] = meta
    left = int(np.sum(merged["status"] == "other_shard"))
    if left:
        raise InputError(f"{where}: {left} cells are in no shard's part")
    merged["status"] = merged["status"].astype(str)
    return merged, parts


SHARD_NAME = re.compile(r"shard-([1-9][0-9]*)-of-([1-9][0-9]*)")


def _shard_count(folder, where: str) -> int:
    """``N`` of the ``shard-K-of-N`` folders in ``folder``: one ``N``, every ``K`` in
    ``1..N``; a folder whose name starts ``shard-`` but is not one of them is refused."""
    found = sorted(p.name for p in folder.glob("shard-*") if p.is_dir())
    if not found:
        raise InputError(f"{where}: no shard-K-of-N folder in it (run the "
                         "shards with `shard` K/N `out` there first)")
    stray = [name for name in found if not SHARD_NAME.fullmatch(name)]
    if stray:
        raise InputError(f"{where}: {stray[0]!r} is not a shard folder (shard-K-of-N, as "
                         "`shard` K/N writes them); move it out before merging")
    pairs = [tuple(map(int, SHARD_NAME.fullmatch(name).groups())) for name in found]
    counts = {n for _, n in pairs}
    if len(counts) != 1:
        raise InputError(f"{where}: shards of different splits "
                         f"({sorted(counts)}); keep one job's shards only")
    count = counts.pop()
    beyond = [f"shard-{k}-of-{n}" for k, n in pairs if k > n]
    if beyond:
        raise InputError(f"{where}: {beyond[0]} is past the split's {count} shards")
    return count


def _whole_part(arrays: dict, name: str, where: str, cells: int | None) -> dict:
    """A shard's arrays if whole: every figure and the status present, of one length (the
    first part's), and finite wherever the part calls the cell a success."""
    missing = [key for key in (*KEYS, "status") if key not in arrays]
    if missing:
        raise InputError(f"{where}: {name}'s part has no {missing[0]!r} array (damaged)")
    size = cells if cells is not None else np.size(arrays["status"])
    wrong = [key for key in (*KEYS, "status") if np.shape(arrays[key]) != (size,)]
    if wrong:
        raise InputError(f"{where}: {name}'s {wrong[0]!r} has shape "
                         f"{np.shape(arrays[wrong[0]])}, not ({size},) as the map's cells")
    success = arrays["status"] == "success"
    for key in KEYS:
        values = np.asarray(arrays[key], dtype=float)
        bad = success & ~np.isfinite(values)
        if bad.any():
            raise InputError(f"{where}: {name} calls {int(bad.sum())} cells a success with "
                             f"{key} = {values[bad][0]} (damaged)")
    return arrays


def chaos_map(system, energy: float, grid: str, out, *, scene: str, tau0: float,
              section: str = "q1=0", t_end: float = 1000.0, params=None, workers: int = 2,
              scheduler: str | None = None, shard=None, resume: bool = True,
              progress: bool = False) -> tuple[ChaosMap, object, list]:
    """The chaos map of ``system`` (loaded from ``scene``, which workers load again) at
    ``energy`` over ``grid`` on ``section`` (module docstring), each cell marched to
    ``t_end`` with first step ``tau0``, its blocks run on ``workers`` local processes (or at
    ``scheduler``) and journalled in ``out``: `run_map`'s result, journal and rows. Every
    input is checked before any cell runs."""
    theta = system.parameter_vector(params)
    cells = place_cells(system, theta, energy, parse_grid(grid, section, system.n))
    t_end = check_real("t_end", t_end)
    return run_map(system, scene, energy, cells, out, t_end=t_end, tau0=tau0, params=params,
                   workers=workers, scheduler=scheduler, shard=parse_shard(shard),
                   resume=resume, progress=progress)
