"""Grids of independent runs: one task, one result row; in this process, on local worker
processes, or on a Dask cluster, with the same rows whichever way they ran.

A :class:`Task` names a function by ``"module:function"`` with its arguments, so it pickles small
and each worker imports and runs it by itself (building, or loading from the cache, whatever
compiled functions it needs; ``fast.compile_function`` writes each library atomically, so workers
sharing a cache folder are safe).

:func:`run_tasks` runs tasks and yields ``(task, result, error)`` as they finish:

- ``workers=1`` and no scheduler: one after the other in this process (no Dask);
- ``scheduler=None`` otherwise: a ``dask.distributed.LocalCluster`` of ``workers`` processes
  (default: the number of cores), one thread each, started and stopped here, no set-up;
- ``scheduler="tcp://host:8786"`` (or ``$DDVP_SCHEDULER``): the same tasks on that cluster; its
  workers need ddvp_nlp installed.

A task that raises is retried once, then reported with the error. A task whose worker dies is
run again on another worker once (local clusters run with ``allowed-failures = 1``), then
reported as ``worker_died``.

:func:`run_grid` adds the result file: each row is appended to a CSV as it arrives, so an
interrupted grid keeps every finished row, and a second call with the same tasks skips the keys
already in the file (resume). At the end the file is rewritten in task order, holding exactly
the rows of this grid.
"""

from __future__ import annotations

import csv
import importlib
import os
import uuid
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError

SCHEDULER_VARIABLE = "DDVP_SCHEDULER"


@dataclass(frozen=True)
class Task:
    """``function(*args, **kwargs)``, where ``function`` is ``"module:name"``; ``key`` is unique
    within a grid and stable across runs (resume matches on it); ``priority``: larger first."""

    key: str
    function: str
    args: tuple = ()
    kwargs: dict = field(default_factory=dict)
    priority: float = 0.0


def execute(task: Task):
    """Run one task (in whatever process it landed)."""
    module, _, name = task.function.partition(":")
    return getattr(importlib.import_module(module), name)(*task.args, **task.kwargs)


def resolve_scheduler(scheduler: str | None) -> str | None:
    """The scheduler address: the argument, else ``$DDVP_SCHEDULER``, else ``None`` (local)."""
    if scheduler is None:
        scheduler = os.environ.get(SCHEDULER_VARIABLE) or None
    if scheduler is not None and (not isinstance(scheduler, str) or "://" not in scheduler):
        raise InputError(f"scheduler must be an address like tcp://host:8786, got {scheduler!r}")
    return scheduler


def check_workers(workers) -> int | None:
    if workers is None:
        return None
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(f"workers must be a positive integer, got {workers!r}")
    return workers


def run_tasks(tasks: Sequence[Task], *, workers: int | None = None,
              scheduler: str | None = None, retries: int = 1,
              progress: bool = False) -> Iterator[tuple[Task, object, str | None]]:
    """Run ``tasks``; yield ``(task, result, None)`` or ``(task, None, error)`` as each ends.

    ``error`` is ``"task_failed: <exception>"`` or ``"worker_died: <message>"``.
    """
    from tqdm import tqdm

    workers = check_workers(workers)
    scheduler = resolve_scheduler(scheduler)
    bar = tqdm(total=len(tasks), disable=not progress, unit="task", leave=False)
    try:
        if scheduler is None and workers == 1:
            for task in sorted(tasks, key=lambda t: -t.priority):
                yield _run_here(task, retries)
                bar.update()
            return
        for outcome in _run_on_dask(tasks, workers=workers, scheduler=scheduler,
                                    retries=retries):
            yield outcome
            bar.update()
    finally:
        bar.close()


def _run_here(task, retries):
    for attempt in range(retries + 1):
        try:
            return task, execute(task), None
        except Exception as exc:  # a task's failure is a row, not the end of the grid
            if attempt == retries:
                return task, None, f"task_failed: {type(exc).__name__}: {exc}"
    raise AssertionError("unreachable")


def _run_on_dask(tasks, *, workers, scheduler, retries):
    import dask
    from distributed import Client, LocalCluster, as_completed
    from distributed.scheduler import KilledWorker

    cluster = None
    if scheduler is None:
        # allowed-failures 1: a task whose worker dies runs once more, then is reported.
        # worker-saturation 1.0: a worker holds only the task it runs, so a dying worker takes
        # no queued task down with it, and the longest tasks (highest priority) start first.
        with dask.config.set({"distributed.scheduler.allowed-failures": 1,
                              "distributed.scheduler.worker-saturation": 1.0}):
            cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1,
                                   threads_per_worker=1, processes=True,
                                   dashboard_address=None)
        client = Client(cluster)
    else:
        client = Client(scheduler)
    futures = {}
    try:
        run = uuid.uuid4().hex[:8]
        futures = {client.submit(execute, task, key=f"ddvp-{run}-{i}", pure=False,
                                 retries=retries, priority=task.priority): task
                   for i, task in enumerate(tasks)}
        for future in as_completed(futures):
            task = futures[future]
            try:
                yield task, future.result(), None
            except KilledWorker as exc:
                yield task, None, f"worker_died: {exc}"
            except Exception as exc:
                yield task, None, f"task_failed: {type(exc).__name__}: {exc}"
            future.release()
    except BaseException:  # Ctrl-C included: stop the rest, keep what was yielded
        client.cancel(list(futures))
        raise
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def read_csv(path: Path) -> list[dict]:
    if not path.exists():
        return []
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def run_grid(tasks: Sequence[Task], path: str | os.PathLike, columns: Sequence[str], *,
             failure_row: Callable[[Task, str], dict], parse: Callable[[dict], dict],
             resume: bool = True, workers: int | None = None, scheduler: str | None = None,
             progress: bool = False) -> tuple[list[dict], int]:
    """Run the tasks whose key is not yet in the CSV at ``path`` and append each row as it
    arrives; return all rows of this grid in task order and how many tasks ran.

    Each task returns a row (a dict over ``columns``, ``key`` included); a task that fails gives
    ``failure_row(task, error)`` instead. ``parse`` turns a row read back from the file into
    typed values. ``resume=False`` starts the file afresh.
    """
    path = Path(path)
    keys = [task.key for task in tasks]
    if len(set(keys)) != len(keys):
        raise InputError("the grid has two tasks with the same key")
    done = {row["key"]: parse(row) for row in read_csv(path)} if resume else {}
    todo = [task for task in tasks if task.key not in done]
    fresh = not done
    with open(path, "w" if fresh else "a", newline="") as handle:
        writer = csv.DictWriter(handle, columns, extrasaction="ignore")
        if fresh:
            writer.writeheader()
            handle.flush()
        for task, result, error in run_tasks(todo, workers=workers, scheduler=scheduler,
                                             progress=progress):
            row = result if error is None else failure_row(task, error)
            row = {**row, "key": task.key}
            writer.writerow(row)
            handle.flush()
            done[task.key] = parse({k: str(v) for k, v in row.items()})
    rows = [done[key] for key in keys]
    _rewrite(path, columns, rows)
    return rows, len(todo)


def _rewrite(path: Path, columns, rows: Iterable[dict]):
    """The grid's rows, in task order, replacing the file atomically."""
    scratch = path.with_suffix(path.suffix + ".tmp")
    with open(scratch, "w", newline="") as handle:
        writer = csv.DictWriter(handle, columns, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow(row)
    os.replace(scratch, path)


def describe_error(error: str) -> tuple[str, str]:
    """``(status, message)`` of an error from :func:`run_tasks`."""
    status, _, message = error.partition(": ")
    return status, message.strip().splitlines()[-1] if message.strip() else status


__all__ = ["Task", "describe_error", "execute", "run_grid", "run_tasks"]
