"""Many initial states marched as one ensemble, split across worker processes.

``march_ensemble`` runs ``M`` marches of the same system, scheme and options. Each orbit is
marched by `march` itself, so its nodes, step lengths,
acceptance, monitors (solvability, accuracy check), status and message are exactly those of a
march from the same start; an orbit that fails ends alone. What the ensemble adds:

- every input (options and all ``M`` starts) is checked before anything is built or run;
- the compiled functions the marches share (the chunk, the recheck) are built once, in this
  process, by a three-step march of the first start, before any worker starts; the workers are
  forked from this process and inherit them loaded (nothing is compiled in a worker);
- the orbits are split into blocks, run on ``workers`` local processes (two by default), and
  merged back in orbit order.

Why not one compiled call per round mapped over the orbits: that was the first version. It
cost the same as a loop of ``march`` calls (34.2 against 35.8 orbits per CPU second,
docs/benchmarks/bench_ensemble.md): a chunk is 1024 steps of compiled arithmetic, so the call
itself is a small part of a round, and the per-orbit checks and monitors are the same either
way; a map over ``M`` orbits also computed the chunks of finished orbits and needed a compile
per ``M``. Marching orbit after orbit shares the march's own compiled chunk (one compile per
scene and scheme) and throws nothing away.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import signal
import threading
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ...discrete.scheme import Scheme
from ...errors import InputError
from ...solution import Solution
from ...validation import check_integer, check_memory, check_span, check_times
from ..compiler import build_count, find_compiler
from ..dense import attach
from ..options import (
    DEFAULT_TOLERANCE,
    Compilation,
    Output,
    StepControl,
    Tolerance,
    answers_removed_keywords,
    coerce,
)
from .derivatives import DerivativeOptions, derivative_request
from .initial_value import check_problem, march

# Blocks per worker: orbits differ in length (a failing orbit is short), so each worker takes
# several blocks, the next as soon as it is free. A block holds at most BLOCK_ORBITS orbits: its
# results cross a pipe as one message, and messages of 13 orbits (83 MB at 1e5 steps an orbit)
# cost this process twice the system time of messages of 2 (1.6 against 0.8 s for 100
# Henon-Heiles orbits of 96617 steps, two runs each: fresh pages for every large message).
BLOCKS_PER_WORKER = 4
# Memory of one forked worker (it shares the parent's pages until it writes them): a bound on
# how many may start, not a measurement of each.
WORKER_BYTES = 200e6
BLOCK_ORBITS = 2


@dataclass(frozen=True)
class Collect:
    """What an ensemble returns instead of whole solutions (SciML's ``output_func`` and
    ``reduction``), computed on the workers so that only it crosses between processes.

    Attributes:
        output: ``output(solution, i) -> value`` for orbit ``i``, run where the orbit was
            marched (``solution.at``, ``energy()`` and the events work there); ``None`` keeps
            the solution.
        reduction: ``reduction(values: list) -> value``, run on each block of orbits on its
            worker and then on the list of the blocks' results, in orbit order: it must give
            the same for a list and for a list of its reduced pieces (a concatenation, a max,
            a count; a floating-point sum is the same up to round-off only). ``None``: the
            list of outputs.
    """

    output: Callable | None = None
    reduction: Callable | None = None

    def __post_init__(self):
        for name in ("output", "reduction"):
            value = getattr(self, name)
            if value is not None and not callable(value):
                raise InputError(f"Collect.{name} must be a function, got {value!r}")

    def block(self, solutions: list, first: int) -> list:
        """A block's outputs (orbits ``first``, ``first + 1``, ...), reduced if asked."""
        values = solutions if self.output is None else [
            self.output(solution, first + k) for k, solution in enumerate(solutions)]
        return values if self.reduction is None else [self.reduction(values)]

    def merge(self, blocks: list):
        """The blocks' results in orbit order: the list, or its reduction."""
        values = [value for block in blocks for value in block]
        return values if self.reduction is None else self.reduction(values)


@answers_removed_keywords
def march_ensemble(system, q0s, p0s, t_span=None, *, tau0: float, scheme="vddvp", params=None,
                   steps: StepControl | None = None,
                   accuracy: Tolerance | None = DEFAULT_TOLERANCE,
                   compilation: Compilation | None = None, workers: int = 2,
                   collect: Collect | None = None, t_eval=None, derivatives=None):
    """March each ``(q0s[i], p0s[i])`` (arrays of shape ``(M, n)``) as `march` would;
    the arguments after them are `march`'s (with ``compilation.fast``, the default, the
    workers share the compiled chunk built here).

    ``workers``: local processes marching the orbits (forked from this one; ``1``: all in
    this process). Returns one `Solution` per orbit, in order, each with its own status
    and `march`'s own timing of that orbit; with workers, ``stats["worker_compiles"]``
    counts the C compiles the orbit's worker ran (none: it inherits the loaded functions).

    ``collect``: a `Collect` whose ``output`` (per orbit) and ``reduction`` run on the
    workers; the ensemble then returns only what they give (100 Henon-Heiles orbits to t = 5000
    returned 725 MB of pickled solutions; their Poincare crossings 3.1 MB, measured by
    ``scripts/benchmarks/bench_ensemble_bytes.py``).

    ``t_eval``, ``derivatives`` (names or `DerivativeOptions`): each orbit's states at ``t_eval``
    (``Solution.z_eval``) and their derivatives, as `march` gives them with
    ``output=Output(t_eval=t_eval)`` and the same ``derivatives`` (``derivatives.py``)."""
    names, mode = derivative_request(derivatives)
    scheme = Scheme.coerce(scheme)
    q0s, p0s = np.atleast_2d(_numbers("q0s", q0s)), np.atleast_2d(_numbers("p0s", p0s))
    if q0s.ndim == 2 and q0s.shape == p0s.shape and (q0s.shape[0] == 0 or q0s.size == 0):
        raise InputError(f"q0s and p0s hold no orbit (shape {q0s.shape}): give at least one "
                         "start, (M, n) arrays with M >= 1")
    if q0s.shape != p0s.shape or q0s.shape[0] == 0 or q0s.ndim != 2:
        raise InputError(f"q0s and p0s must be (M, n) arrays of the same shape, got "
                         f"{q0s.shape} and {p0s.shape}")
    workers = check_integer("workers", workers)
    check_memory("workers", workers, workers * WORKER_BYTES, "the worker processes")
    steps = coerce(steps, StepControl, "steps")  # time_limit, energy_guard: per orbit
    if accuracy is not None:
        coerce(accuracy, Tolerance, "accuracy")
    compilation = coerce(compilation, Compilation, "compilation")
    collect = coerce(collect, Collect, "collect")
    t0, t_end = check_span(t_span)
    output = _output(t_eval, names, (t0, t_end))
    theta = _check_all(system, scheme, q0s, p0s, (t0, t_end), tau0, steps, params)
    compilation = replace(compilation, compiler=find_compiler(compilation.compiler))
    options = dict(tau0=tau0, scheme=scheme, params=params, steps=steps, accuracy=accuracy,
                   compilation=compilation)
    with warnings.catch_warnings():  # the first orbit's warnings come from its own march
        warnings.simplefilter("ignore")
        # build (or load from the on-disk cache) what every march shares, here, once
        march(system, q0s[0], p0s[0], (t0, t0 + min(3 * tau0, t_end - t0)), **options)
    if output is not None:
        options.update(output=output, derivatives=DerivativeOptions(names, mode) if names
                       else None)
    job = _Job(system, q0s, p0s, (t0, t_end), options, collect)
    blocks = _blocks(q0s.shape[0], workers)
    if workers == 1 or len(blocks) == 1 or not _can_fork():
        return collect.merge([job.run(block, count_compiles=False) for block in blocks])
    context = multiprocessing.get_context("fork")
    pool = context.Pool(min(workers, len(blocks)), initializer=_install,
                        initargs=(job, os.getpid()))
    try:
        parts = list(pool.imap(_run_block, blocks))
        pool.close()
    except BaseException:  # Ctrl-C, SIGTERM, a failed block: no worker outlives this call
        pool.terminate()
        raise
    finally:
        pool.join()
    for part in parts:  # the live system stays behind in the worker
        for value in part:
            if isinstance(value, Solution):
                _attach(value, system, theta, t_end)
    return collect.merge(parts)


def _attach(solution, system, theta, t_end) -> None:
    """`attach`, on the constrained field for a constrained system."""
    if getattr(system, "n_constraints", 0):
        from .constrained_march import attach_constrained

        attach_constrained(solution, system, theta, t_end)
    else:
        attach(solution, system, theta, t_end)


def _output(t_eval, names, t_span) -> Output | None:
    """The orbits' `Output` for ``t_eval`` (``None`` without), checked before anything runs;
    ``derivatives`` need ``t_eval``, refused by name otherwise."""
    if t_eval is None:
        if names:
            raise InputError("derivatives are of the states at fixed times: give t_eval")
        return None
    if t_span[1] < t_span[0] and names:
        raise InputError("derivatives are not supported with a backward t_span (t_end < t0)")
    return Output(t_eval=check_times(t_eval, t_span))


def _numbers(name: str, value) -> np.ndarray:
    """An array of real numbers (whether each start is finite, `_check_all` says, orbit
    by orbit)."""
    try:
        return np.asarray(value, float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an (M, n) array of real numbers, got {value!r}") \
            from None


def _check_all(system, scheme, q0s, p0s, t_span, tau0, steps, params) -> np.ndarray:
    """Every start, checked as `march` checks it, before any march; returns
    ``theta``."""
    if getattr(system, "n_constraints", 0):  # each start projected as its march projects it
        from .constrained_march import check_ensemble_starts

        return check_ensemble_starts(system, q0s, p0s, t_span, tau0, params)
    theta = None
    for i, (q0, p0) in enumerate(zip(q0s, p0s, strict=True)):
        try:
            theta = check_problem(system, scheme, q0, p0, None, t_span, tau0, steps,
                                  params).theta
        except InputError as exc:
            raise InputError(f"orbit {i}: {exc}") from None
    return theta


def _blocks(count: int, workers: int) -> list[range]:
    """Consecutive blocks of orbits, at least ``BLOCKS_PER_WORKER`` per worker (fewer if too
    few orbits), of at most ``BLOCK_ORBITS`` orbits."""
    size = max(1, min(BLOCK_ORBITS, math.ceil(count / (workers * BLOCKS_PER_WORKER))))
    return [range(start, min(start + size, count)) for start in range(0, count, size)]


def _can_fork() -> bool:
    """Workers are forked: not where ``fork`` is missing, nor from a daemon process (a pool
    worker, which may not have children)."""
    return ("fork" in multiprocessing.get_all_start_methods()
            and not multiprocessing.current_process().daemon)


class _Job:
    """The marches of one ensemble: the system, the starts and `march`'s options."""

    def __init__(self, system, q0s, p0s, t_span, options, collect):
        self.system, self.q0s, self.p0s, self.options = system, q0s, p0s, options
        self.t_span = t_span
        self.collect = collect

    def run(self, indices, *, count_compiles: bool) -> list:
        """The block's orbits marched, then what ``collect`` asks of them."""
        return self.collect.block(self.march(indices, count_compiles=count_compiles),
                                  indices[0])

    def march(self, indices, *, count_compiles: bool) -> list[Solution]:
        before = build_count()
        solutions = [march(self.system, self.q0s[i], self.p0s[i], self.t_span, **self.options)
                     for i in indices]
        if count_compiles:
            for solution in solutions:
                solution.stats["worker_compiles"] = build_count() - before
        return solutions


_JOB: _Job | None = None


def _install(job: _Job, parent: int) -> None:
    """A worker's initializer: the job, inherited through ``fork`` (nothing is pickled); the
    parent's Ctrl-C handling undone (the parent stops the workers: a terminal's Ctrl-C reaches
    the whole process group) and the worker tied to its parent's life."""
    global _JOB
    _JOB = job
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    end_with_parent(parent)


# How often a worker looks whether its parent is still there.
PARENT_POLL_S = 0.2


def end_with_parent(parent: int, *, death_signal: bool = True) -> None:
    """End this process (``os._exit``) once ``parent`` is gone: a SIGKILL of the parent gives it
    no chance to stop its workers, and they had marched on (two left after a killed
    ``ddvp poincare``). With ``death_signal`` (a process forked by the parent's main thread)
    Linux also gets ``PR_SET_PDEATHSIG``; the poll covers the rest."""
    if death_signal:
        _death_signal()
    if os.getppid() != parent:
        os._exit(1)

    def watch():
        while os.getppid() == parent:
            time.sleep(PARENT_POLL_S)
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="ddvp-parent-watch").start()


def _death_signal() -> None:
    """``prctl(PR_SET_PDEATHSIG, SIGKILL)`` where the C library has it."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError, TypeError):
        pass


def _run_block(indices: range) -> list[Solution]:
    return _JOB.run(indices, count_compiles=True)
