"""Many independent tasks: in this process, on local worker processes, or on a Dask cluster,
with the same results whichever way they ran.

A `Task` names a function by ``"module:function"`` with its arguments, so it pickles small
and each worker imports and runs it by itself (building, or loading from the cache, whatever
compiled functions it needs; ``solvers/compiler.py`` writes each library atomically, so workers
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

The journal of their rows (``journal.py``) is built on `run_tasks`.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import json
import os
import socket
import uuid
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

from ..errors import InputError
from ..validation import check_integer

SCHEDULER_VARIABLE = "DDVP_SCHEDULER"


@dataclass(frozen=True)
class Task:
    """``function(*args, **kwargs)``, where ``function`` is ``"module:name"``; ``key`` is unique
    within a table and stable across runs (resume matches on it); ``priority``: larger first."""

    key: str
    function: str
    args: tuple = ()
    kwargs: dict = field(default_factory=dict)
    priority: float = 0.0

    def fingerprint(self) -> str:
        """A hash of everything the task's row depends on: the function and every argument
        (for a stress or sweep run: scene and the scene file's digest, settings, method, knob,
        bounds). A resumed table reuses a row only under the same fingerprint."""
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
    """Where the runs of a table go.

    Attributes:
        count: local worker processes (``1``, the default: one after the other in this
            process, so that run times compare like with like; ``None``: as many as there are
            cores).
        scheduler: the address of a Dask scheduler (``tcp://host:8786``) whose workers run the
            tasks instead; default ``$DDVP_SCHEDULER``, else local. Whether anyone answers
            there is checked when the table is planned.
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
    from ..progress import progress as report

    workers = check_workers(workers)
    scheduler = resolve_scheduler(scheduler)
    bar = report(len(tasks), unit="task", label="runs", enabled=progress)
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
        except Exception as exc:  # a task's failure is a row, not the end of the table
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
    from ..solvers import end_with_parent

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
    client = cluster = None
    futures = {}
    try:
        # a cluster cut half-way through its start or its close cannot close (its event loop
        # and its workers' threads then ran on into the interpreter's exit): both are held
        with held_signals():
            client, cluster = _start_dask(workers, scheduler)
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
        if client is not None:
            with held_signals():
                client.cancel(list(futures))
        raise
    finally:
        with held_signals():
            if client is not None:
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
    try:
        client = Client(cluster)
        # the workers end with this process, even when it is killed (SIGKILL gives it no
        # chance to close the cluster)
        client.run(_watch_parent, os.getpid())
    except BaseException:
        cluster.close()
        raise
    return client, cluster


@contextlib.contextmanager
def held_signals():
    """Ctrl-C, SIGTERM and SIGHUP held (noted, not acted on) for the duration, then acted on:
    the start and the close of a cluster are not cut half-way (Dask's exit hook then failed
    with a traceback, and a close cut short left its event loop and its workers' threads
    running into the interpreter's exit). Blocking the signals in the main thread is not
    enough: another thread (Dask's event loop) takes the signal, and the main thread then
    runs its Python handler wherever it is; so the handlers are also replaced, for the
    duration, by one that notes the signal. A signal that came meanwhile is raised again
    right after, once for each kind, to the handler that was in place (a command's handler
    raises ``KeyboardInterrupt`` there; an ignored signal stays ignored)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread() or \
            not hasattr(signal, "pthread_sigmask"):
        yield
        return
    wanted = [getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP")
              if hasattr(signal, name)]
    noted = []
    before = signal.pthread_sigmask(signal.SIG_BLOCK, wanted)
    previous = {}
    try:
        for sig in wanted:
            if signal.getsignal(sig) is not None:  # None: a handler set outside Python
                previous[sig] = signal.signal(sig, lambda signum, frame: noted.append(signum))
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        signal.pthread_sigmask(signal.SIG_SETMASK, before)
        for sig in dict.fromkeys(noted):
            signal.raise_signal(sig)


def describe_error(error: str) -> tuple[str, str]:
    """``(status, message)`` of an error from `run_tasks`."""
    status, _, message = error.partition(": ")
    return status, message.strip().splitlines()[-1] if message.strip() else status


__all__ = ["Task", "Workers", "describe_error", "execute", "resolve_scheduler", "run_tasks"]
