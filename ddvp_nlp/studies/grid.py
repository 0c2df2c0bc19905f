"""Grids of independent runs: one task, one result row; in this process, on local worker
processes, or on a Dask cluster, with the same rows whichever way they ran.

A `Task` names a function by ``"module:function"`` with its arguments, so it pickles small
and each worker imports and runs it by itself (building, or loading from the cache, whatever
compiled functions it needs; ``fast.compile_function`` writes each library atomically, so workers
sharing a cache folder are safe).

`run_tasks` runs tasks and yields ``(task, result, error)`` as they finish:

- ``workers=1`` and no scheduler: one after the other in this process (no Dask);
- ``scheduler=None`` otherwise: a ``dask.distributed.LocalCluster`` of ``workers`` processes
  (default: the number of cores), one thread each, started and stopped here, no set-up;
- ``scheduler="tcp://host:8786"`` (or ``$DDVP_SCHEDULER``): the same tasks on that cluster; its
  workers need ddvp_nlp installed.

A task that raises is retried once, then reported with the error. A task whose worker dies is
run again on another worker once (local clusters run with ``allowed-failures = 1``), then
reported as ``worker_died``.

`run_grid` adds the result file (`ddvp_nlp.io.row_file`): each row is appended to a
CSV as it arrives, so an interrupted grid keeps every finished row, and a second call with the
same tasks skips the keys already in the file (resume). At the end the file is rewritten in task
order, holding exactly the rows of this grid. A `RowSchema` types the rows read back.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import json
import math
import os
import socket
import uuid
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from ..io.row_file import read_csv
from ..solution import Status
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


# Memory of one local worker process (Python, numpy, CasADi and Dask loaded; measured about
# 150 MB): --workers 100000000000 had started a cluster until the machine ran out of memory.
WORKER_BYTES = 200e6


def check_workers(workers) -> int | None:
    """``None`` (as many as there are cores) or a positive integer whose processes fit in
    memory."""
    from ..validation import check_memory

    if workers is None:
        return None
    workers = check_integer("workers", workers)
    check_memory("workers", workers, workers * WORKER_BYTES, "the local worker processes")
    return workers


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


# Dask's own loggers, in this process and (through the environment) in the local workers it
# spawns: at an interrupt, the workers' heartbeats logged CommClosedError tracebacks.
DASK_LOGGERS = ("distributed", "tornado", "asyncio")


def _quiet_dask() -> None:
    """Only Dask's critical messages, here and in workers started from now on; ddvp reports a
    failed task or a lost worker itself (as the row's status)."""
    import logging

    for name in DASK_LOGGERS:
        logging.getLogger(name).setLevel(logging.CRITICAL)
    os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "critical")


def _watch_parent(parent: int) -> None:
    """On a local cluster's worker: end with ``parent`` if it is this worker's parent."""
    from ..solvers.march.ensemble import end_with_parent

    if os.getppid() == parent:
        end_with_parent(parent, death_signal=False)


def _connect(client_class, scheduler: str):
    """A client of the Dask scheduler at ``scheduler``; anything there that is not one (an
    HTTP server, a closed port) is an ``InputError`` naming the address, not a
    ``CommClosedError`` traceback."""
    try:
        return client_class(scheduler, timeout="10s")
    except Exception as exc:  # noqa: BLE001 - whatever Dask raises for a bad address
        raise InputError(f"no Dask scheduler answers at {scheduler!r}: {type(exc).__name__}: "
                         f"{exc}") from None


def _run_on_dask(tasks, *, workers, scheduler, retries):
    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    _quiet_dask()
    with held_signals():  # a cluster cut half-way through its start or its close cannot close
        client, cluster = _start_dask(workers, scheduler)
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
        with held_signals():
            client.cancel(list(futures))
        raise
    finally:
        with held_signals():
            client.close()
            if cluster is not None:
                cluster.close()


def _start_dask(workers, scheduler):
    """``(client, cluster)``: a local cluster of ``workers`` processes (``cluster`` to close),
    or a client of the cluster at ``scheduler`` (``cluster`` ``None``)."""
    import dask
    from distributed import Client, LocalCluster

    if scheduler is not None:
        return _connect(Client, scheduler), None
    # allowed-failures 1: a task whose worker dies runs once more, then is reported.
    # worker-saturation 1.0: a worker holds only the task it runs, so a dying worker takes
    # no queued task down with it, and the longest tasks (highest priority) start first.
    with dask.config.set({"distributed.scheduler.allowed-failures": 1,
                          "distributed.scheduler.worker-saturation": 1.0}), \
            warnings.catch_warnings():
        # no dashboard is served; Dask still warns when another process holds its port
        warnings.filterwarnings("ignore", message="Port .* is already in use")
        cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1,
                               threads_per_worker=1, processes=True, dashboard_address=None)
    client = Client(cluster)
    # the workers end with this process, even when it is killed (SIGKILL gives it no chance
    # to close the cluster)
    client.run(_watch_parent, os.getpid())
    return client, cluster


@contextlib.contextmanager
def held_signals():
    """Ctrl-C and SIGTERM held (blocked, not lost) in the main thread for the duration: the
    start and the close of a cluster are not cut half-way (Dask's exit hook then failed with
    a traceback); a signal that came meanwhile is handled right after."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread() or \
            not hasattr(signal, "pthread_sigmask"):
        yield
        return
    wanted = {signal.SIGINT, signal.SIGTERM}
    before = signal.pthread_sigmask(signal.SIG_BLOCK, wanted)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, before)


@dataclass(frozen=True)
class RowSchema:
    """A grid's table: its columns and which of them hold numbers or flags. `parse` is
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


class GridFileWarning(UserWarning):
    """A row of a grid file that is not reused (and why): shown even where the runs'
    numerical warnings are silenced."""


class GridInterrupted(KeyboardInterrupt):
    """A grid stopped by Ctrl-C or SIGTERM; the message says what was kept and where."""


def run_grid(tasks: Sequence[Task], path: str | os.PathLike, columns: Sequence[str], *,
             failure_row: Callable[[Task, str], dict], parse: Callable[[dict], dict],
             resume: bool = True, workers: int | None = None, scheduler: str | None = None,
             progress: bool = False, commit: bool = True,
             finite: Sequence[str] = ()) -> tuple[list[dict], int]:
    """Run the tasks that have no valid row yet and journal each row as it arrives; return all
    rows of this grid in task order and how many tasks ran.

    The result file ``path`` (``NAME.csv``) holds the last complete grid; rows of a grid under
    way go to the journal ``NAME.partial.csv`` beside it, appended and flushed one by one (an
    interrupt or a kill keeps every finished row there). With ``commit`` the rows are then
    written to ``NAME.csv`` (through the output layer, with a manifest) and the journal is
    removed; without, the caller commits them with the other files of its set
    (`commit_grid`).

    Each task returns a row (a dict over ``columns``, ``key`` included); a task that fails
    gives ``failure_row(task, error)`` instead. Every row carries the task's ``fingerprint``
    and a checksum of its own values. ``resume``: rows already in ``NAME.csv`` or the journal
    are reused after they are checked (`read_rows_back`: checksum, this grid's key and
    fingerprint, a known status, ``finite`` columns finite on a success); rows of another
    grid are refused, not overwritten (``InputError``); ``resume=False`` ignores them (they
    are replaced when this grid commits).
    """
    from ..io import atomic

    keys = [task.key for task in tasks]
    if len(set(keys)) != len(keys):
        raise InputError("the grid has two tasks with the same key")
    columns = _with_checks(columns)
    path = Path(path)
    journal = journal_path(path)
    with atomic.output_folder(path.parent) as folder:
        done = read_rows_back(path, tasks, columns, parse, finite) if resume else {}
        todo = [task for task in tasks if task.key not in done]
        # the journal starts with the rows kept, so a row is never read twice
        folder.replace(journal.name, atomic.text(row_lines(columns, done.values(),
                                                            header=True)))
        try:
            with folder.journal(journal.name) as handle:
                for task, result, error in run_tasks(todo, workers=workers,
                                                     scheduler=scheduler, progress=progress):
                    row = result if error is None else failure_row(task, error)
                    row = signed({**row, "key": task.key, "fingerprint": task.fingerprint()},
                                 columns)
                    handle.write(row_lines(columns, [row]))
                    handle.flush()  # a row on disk survives an interrupt or a dying process
                    done[task.key] = parse({k: str(v) for k, v in row.items()})
        except KeyboardInterrupt:
            raise GridInterrupted(
                f"interrupted; {len(done)} of {len(tasks)} rows are finished and kept in "
                f"{journal} (running the same grid again goes on from them); {path} still "
                "holds the last complete grid, if there was one") from None
        rows = [done[key] for key in keys]
        if commit:
            commit_grid(path, columns, rows)
    return rows, len(todo)


def journal_path(path) -> Path:
    """``NAME.partial.csv`` beside ``NAME.csv``: the rows of a grid under way."""
    path = Path(path)
    return path.with_name(path.stem + ".partial" + path.suffix)


def commit_grid(path, columns: Sequence[str], rows: list[dict], files: dict | None = None,
                meta: dict | None = None) -> dict:
    """Write ``NAME.csv`` (``rows`` in order), the other ``files`` of the set (name ->
    writer) and the manifest ``meta.json`` as one set through the output layer, then drop the
    journal. Returns the manifest."""
    from ..io import atomic

    path = Path(path)
    columns = _with_checks(columns)
    rows = [signed(row, columns) for row in rows]
    with atomic.output_folder(path.parent) as folder:
        written = folder.commit({path.name: atomic.text(row_lines(columns, rows, header=True)),
                                 **(files or {})},
                                {"rows": len(rows), **(meta or {})})
        folder.remove(journal_path(path).name)
    return written


RETRIED = ("task_failed", "worker_died", "not_run")  # statuses a resumed grid runs again
CHECKSUM = "row_sha256"
# Statuses a row may have: a solver's, or how its task ended.
STATUSES = frozenset([status.code for status in Status] + list(RETRIED))


def _with_checks(columns) -> list[str]:
    columns = [c for c in columns if c not in ("fingerprint", CHECKSUM)]
    return [*columns, "fingerprint", CHECKSUM]


def row_checksum(row: dict, columns: Sequence[str]) -> str:
    """16 hex digits of the SHA-256 of the row's values as the file holds them (strings), in
    column order: a row edited by hand, cut short or written by another tool does not match.
    (Not a signature: whoever recomputes it can forge a row.)"""
    text = json.dumps([_cell(row.get(c)) for c in columns if c != CHECKSUM])
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _cell(value) -> str:
    return "" if value is None else str(value)


def signed(row: dict, columns: Sequence[str]) -> dict:
    """``row`` with its checksum (over the values as they will be written)."""
    row = {c: _cell(row.get(c)) for c in columns if c != CHECKSUM}
    row[CHECKSUM] = row_checksum(row, columns)
    return row


def row_lines(columns: Sequence[str], rows, *, header: bool = False) -> str:
    """CSV text of ``rows`` (and the header)."""
    import csv
    import io

    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, columns, extrasaction="ignore", lineterminator="\n")
    if header:
        writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue()


def read_rows_back(path, tasks, columns, parse, finite=()) -> dict:
    """The rows of ``NAME.csv`` and of its journal that a resumed grid keeps, by key.

    A file that is not a grid file ddvp wrote (not UTF-8 text, another header, a field past
    the CSV limit, a link, a folder, bigger than the memory allows) is refused, naming it and
    the reason (``InputError``); so is a row of another grid (a key this grid does not have:
    other points, methods or cases): it is not overwritten. A row cut short by a kill, whose
    checksum does not match, computed with other settings (its task's fingerprint changed),
    with an unknown status, or a success with a number that is not finite, is dropped with a
    warning and its task runs again; so is a failed task's row (``RETRIED``)."""
    fingerprints = {task.key: task.fingerprint() for task in tasks}
    kept, foreign = {}, 0
    for source in (Path(path), journal_path(path)):
        for number, row in _file_rows(source, columns):
            reason = _row_problem(row, columns, fingerprints, finite)
            if reason == "foreign":
                foreign += 1
                continue
            if reason is None:
                try:
                    parsed = parse(row)
                except (KeyError, ValueError, TypeError) as exc:
                    reason = f"does not parse ({exc})"
            if reason is not None:
                warnings.warn(f"{source}: line {number} {reason}; its task runs again",
                              GridFileWarning, stacklevel=3)
                continue
            if row.get("status") not in RETRIED:
                kept[row["key"]] = parsed
    if foreign:
        raise InputError(f"{path} holds {foreign} rows of another grid (points, methods or "
                         "cases this grid does not have); they are not overwritten: start this "
                         "grid afresh to replace them (sweep --fresh, stress without --resume) "
                         "or give another --out")
    return kept


def _row_problem(row: dict, columns, fingerprints: dict, finite) -> str | None:
    """Why a row read back cannot be reused (``"foreign"``: another grid's), or ``None``."""
    if None in row or any(row.get(c) is None for c in columns):
        return "is incomplete (a run cut short?)"
    if row[CHECKSUM] != row_checksum(row, columns):
        return "does not match its checksum (edited, or written by another tool)"
    if row["key"] not in fingerprints:
        return "foreign"
    if fingerprints[row["key"]] != row["fingerprint"]:
        return "was computed with other settings or another scene file"
    if "status" not in row:  # a grid whose rows have no status (a plain table of results)
        return None
    if row["status"] not in STATUSES:
        return f"has an unknown status {row['status'][:40]!r}"
    if row["status"] == "success":
        for name in finite:
            try:
                value = float(row[name])
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                return f"claims success with {name} = {row[name][:40]!r}"
    return None


# Largest grid file read back: a row is a few hundred bytes; a grid has at most a million.
GRID_FILE_LIMIT = 1 << 30


def _file_rows(path: Path, columns) -> Iterator[tuple[int, dict]]:
    """``(line number, row)`` of a grid file (none if it does not exist); ``InputError`` for a
    file that is not one (module docstring of `read_rows_back`)."""
    import csv
    import io

    from ..validation import check_file_size, read_limited

    if not os.path.lexists(path):
        return
    if path.is_symlink():  # never followed; the grid's commit replaces the link itself
        warnings.warn(f"{path} is a symbolic link: not read (ddvp follows no link); its rows, "
                      "if any, run again", GridFileWarning, stacklevel=4)
        return
    data = read_limited(path, GRID_FILE_LIMIT, what="grid file")
    check_file_size(str(path), len(data))
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"grid file {str(path)!r} is not UTF-8 text (byte {exc.start}): not a "
                         "file ddvp wrote; start the grid afresh to replace it") from None
    if "\0" in text:
        raise InputError(f"grid file {str(path)!r} holds NUL bytes: not a file ddvp wrote; "
                         "start the grid afresh to replace it")
    reader = csv.DictReader(io.StringIO(text, newline=""))
    try:
        header = reader.fieldnames or []
        if text.strip() and list(header) != list(columns):
            raise InputError(f"grid file {str(path)!r} has other columns than this grid's "
                             f"({', '.join(header[:4])}...): not written for it; start the grid "
                             "afresh to replace it")
        yield from enumerate(reader, start=2)
    except csv.Error as exc:
        raise InputError(f"grid file {str(path)!r} is not a CSV ddvp wrote ({exc}); start the "
                         "grid afresh to replace it") from None


def describe_error(error: str) -> tuple[str, str]:
    """``(status, message)`` of an error from `run_tasks`."""
    status, _, message = error.partition(": ")
    return status, message.strip().splitlines()[-1] if message.strip() else status


__all__ = ["GridInterrupted", "RowSchema", "Task", "commit_grid", "describe_error", "execute",
           "run_grid", "run_tasks"]
