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

:func:`run_grid` adds the result file (:mod:`ddvp_nlp.io.row_file`): each row is appended to a
CSV as it arrives, so an interrupted grid keeps every finished row, and a second call with the
same tasks skips the keys already in the file (resume). At the end the file is rewritten in task
order, holding exactly the rows of this grid. A :class:`RowSchema` types the rows read back.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import os
import socket
import uuid
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field

from ..errors import InputError
from ..io.row_file import appending, read_csv, rewrite_csv
from ..validation import check_integer

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

    def fingerprint(self) -> str:
        """A hash of everything the task's row depends on: the function and every argument
        (for a stress or sweep run: scene and the scene file's digest, settings, method, knob,
        bounds). A resumed grid reuses a row only under the same fingerprint."""
        text = json.dumps([self.function, list(self.args), self.kwargs], sort_keys=True,
                          default=repr)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


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
    if scheduler is not None:
        _reachable(scheduler)
    return scheduler


def _reachable(scheduler: str, timeout: float = 3.0) -> None:
    """Refuse, quickly and with a message, a scheduler nobody answers at (Dask would wait 30 s
    and end in a traceback)."""
    host, _, port = scheduler.split("://", 1)[1].rpartition(":")
    try:
        with socket.create_connection((host.strip("[]") or "localhost", int(port)),
                                      timeout=timeout):
            pass
    except ValueError:
        raise InputError(f"scheduler {scheduler!r} has no port (like tcp://host:8786)") from None
    except OSError as exc:
        raise InputError(f"no Dask scheduler answers at {scheduler!r} within {timeout:g} s: "
                         f"{exc.strerror or exc}") from None


def check_workers(workers) -> int | None:
    """``None`` (as many as there are cores) or a positive integer."""
    return None if workers is None else check_integer("workers", workers)


@dataclass(frozen=True)
class Workers:
    """Where the runs of a grid go.

    Attributes:
        count: local worker processes (``1``, the default: one after the other in this
            process, so that run times compare like with like; ``None``: as many as there are
            cores).
        scheduler: the address of a Dask scheduler (``tcp://host:8786``) whose workers run the
            tasks instead; default ``$DDVP_SCHEDULER``, else local. Whether anyone answers
            there is checked when the grid is planned.
    """

    count: int | None = 1
    scheduler: str | None = None

    def __post_init__(self):
        object.__setattr__(self, "count", check_workers(self.count))
        if self.scheduler is not None and (not isinstance(self.scheduler, str)
                                           or "://" not in self.scheduler):
            raise InputError(f"scheduler must be an address like tcp://host:8786, got "
                             f"{self.scheduler!r}")


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


@dataclass(frozen=True)
class RowSchema:
    """A grid's table: its columns and which of them hold numbers or flags. :meth:`parse` is
    the one place a row read back from the result file gets its types again."""

    columns: tuple[str, ...]
    floats: tuple[str, ...] = ()
    integers: tuple[str, ...] = ()
    flags: tuple[str, ...] = ()

    def parse(self, row: dict) -> dict:
        """``row`` with numbers as numbers and flags as ``True``/``False`` (``""`` if unset)."""
        row = dict(row)
        for key in self.floats:
            row[key] = float(row[key])
        for key in self.integers:
            row[key] = int(row[key])
        for key in self.flags:
            row[key] = {"True": True, "False": False}.get(row[key], "")
        return row

    def read(self, path) -> list[dict]:
        """The typed rows of a result file written with this schema."""
        return [self.parse(row) for row in read_csv(path, missing_ok=False)]


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
    keys = [task.key for task in tasks]
    if len(set(keys)) != len(keys):
        raise InputError("the grid has two tasks with the same key")
    columns = [*columns, *(["fingerprint"] if "fingerprint" not in columns else [])]
    done = _reusable(path, tasks, columns, parse) if resume else {}
    todo = [task for task in tasks if task.key not in done]
    # the rows kept are rewritten first, so a retried row is never read twice
    rewrite_csv(path, columns, done.values())
    with appending(path, columns, fresh=not done) as append:
        for task, result, error in run_tasks(todo, workers=workers, scheduler=scheduler,
                                             progress=progress):
            row = result if error is None else failure_row(task, error)
            row = {**row, "key": task.key, "fingerprint": task.fingerprint()}
            append(row)
            done[task.key] = parse({k: str(v) for k, v in row.items()})
    rows = [done[key] for key in keys]
    rewrite_csv(path, columns, rows)
    return rows, len(todo)


RETRIED = ("task_failed", "worker_died", "not_run")  # statuses a resumed grid runs again


def _reusable(path, tasks, columns, parse) -> dict:
    """The rows of the result file that a resumed grid keeps: same key, same fingerprint, a
    status that is not a failure of the task itself (``RETRIED``). A row cut short by a crash,
    or that does not parse, is skipped with a warning and its task runs again."""
    fingerprints = {task.key: task.fingerprint() for task in tasks}
    kept = {}
    for number, row in enumerate(read_csv(path), start=2):
        if None in row.values() or None in row or any(row.get(c) is None for c in columns):
            warnings.warn(f"{path}: line {number} is incomplete (a run cut short?); its task "
                          "runs again", RuntimeWarning, stacklevel=3)
            continue
        try:
            parsed = parse(row)
        except (KeyError, ValueError) as exc:
            warnings.warn(f"{path}: line {number} does not parse ({exc}); its task runs again",
                          RuntimeWarning, stacklevel=3)
            continue
        key = row.get("key")
        if fingerprints.get(key) == row.get("fingerprint") and row.get("status") not in RETRIED:
            kept[key] = parsed
    return kept


def describe_error(error: str) -> tuple[str, str]:
    """``(status, message)`` of an error from :func:`run_tasks`."""
    status, _, message = error.partition(": ")
    return status, message.strip().splitlines()[-1] if message.strip() else status


__all__ = ["RowSchema", "Task", "describe_error", "execute", "run_grid", "run_tasks"]
