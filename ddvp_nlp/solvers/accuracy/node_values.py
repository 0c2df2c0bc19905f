"""What the accuracy check evaluates at every node or step of a trajectory, compiled and mapped
over blocks of nodes (CasADi's virtual machine where there is no compiler): the vector field
and ``H`` at the nodes (the energy scale and drift), and the first look at every step
(``z_{k+1} - RK4(z_k)``, one classical Runge-Kutta step of the exact flow: a cheap filter of the
steps that plainly pass the local test)."""

from __future__ import annotations

import threading

import casadi as ca
import numpy as np

from ...blocks import copied, evaluate_in_blocks, through_buffer
from ...cache import cached
from ...discrete.runge_kutta import rk4
from ..compiler import FunctionBuffer, RentedBuffer, buffered
from ..exact.flow import flow_field

BLOCK = 512  # nodes per call of a compiled block (the last block padded: blocks.py)
FEW = 16  # fewer rows than this are evaluated one at a time, not in a padded block
# Rows per call of a compiled block map called from CasADi (a map of WIDE // BLOCK calls of the
# compiled block): each call from Python took about 35 us besides its work (setting the
# arrays of seven inputs and outputs), a fifth of the compiled look at a block of 512.
WIDE = 8 * BLOCK
# Steps whose looks are kept for the check of the finished march (`Kept`): the early verdict's
# (``marching/monitors.py``, ``EARLY_STEPS``).
KEPT_STEPS = 4096


def look_function(system) -> ca.Function:
    """``(z_a, z_b, t, h, theta) -> (z_b - RK4(z_a), f(z_a), H(z_a))`` (``H`` without its
    constant terms, `physics.hamiltonian.varying_part`: the energy tests take differences of
    it): a step's local error against one classical Runge-Kutta step of the exact flow,
    component by component (the cheap first look of a second-order march's steps), with the
    vector field and ``H`` at its first node (the RK4 step's first stage: computed once)."""
    def build():
        field, n2 = flow_field(system)
        theta = ca.SX.sym("theta", system.theta.numel())
        z_a, z_b = ca.SX.sym("z_a", n2), ca.SX.sym("z_b", n2)
        t, h = ca.SX.sym("t"), ca.SX.sym("h")
        step = rk4(lambda z, time: field(z, time, theta), z_a, t, h)
        H = system.H_varying_function(z_a[:system.n], z_a[system.n:], t, theta)
        return ca.Function("accuracy_look", [z_a, z_b, t, h, theta],
                           [z_b - step, field(z_a, t, theta), H],
                           ["z_a", "z_b", "t", "h", "theta"], ["d", "f", "H"], {"cse": True})
    return cached(system, "accuracy_look", build)


def node_function(system) -> ca.Function:
    """``(z, t, theta) -> (f, H)``: the vector field and ``H`` (without its constant terms) at
    one node."""
    def build():
        field, n2 = flow_field(system)
        theta = ca.SX.sym("theta", system.theta.numel())
        z, t = ca.SX.sym("z", n2), ca.SX.sym("t")
        H = system.H_varying_function(z[:system.n], z[system.n:], t, theta)
        return ca.Function("accuracy_node", [z, t, theta], [field(z, t, theta), H],
                           ["z", "t", "theta"], ["f", "H"], {"cse": True})
    return cached(system, "accuracy_node", build)


def _direct(system, function: ca.Function, calls: int = 1):
    """This thread's ``Function.buffer()`` of the compiled block ``function`` (``calls`` > 1:
    of a map calling it that many times in a row, from CasADi rather than from Python), for
    `blocks.through_buffer` (its own, not a `FunctionBuffer`'s: that one's arrays stay
    bound)."""
    local = cached(system, ("accuracy", "direct", function.name(), calls), threading.local)
    if getattr(local, "function", None) is not function:
        wide = function if calls == 1 else function.map(f"{function.name()}_{calls}",
                                                        "serial", calls, [], [])
        local.function, local.buffer = function, wide.buffer()
    return local.buffer


class NodeValues:
    """`first_look` and `at_nodes` of ``system`` with parameters ``theta``, compiled once per
    system and compiler (kept with the system)."""

    def __init__(self, system, theta, *, compiler=None, cache_dir=None):
        self.system = system
        self.theta = np.broadcast_to(np.asarray(theta, float),
                                     (BLOCK, system.theta.numel())).copy()
        self.compiler, self.cache_dir = compiler, cache_dir
        self.looks = 0  # nodes `first_look` evaluated (the tests count them)
        self._wide = None  # theta in WIDE rows, made on first use

    def _compiled(self, kind: str) -> FunctionBuffer:
        def build():
            single = look_function(self.system) if kind == "look" else \
                node_function(self.system)
            mapped = single.map(f"accuracy_{kind}s", "serial", BLOCK, [], [])
            return RentedBuffer(mapped, self.compiler, self.cache_dir, prefix="exact")
        return cached(self.system, ("accuracy", kind, self.compiler, str(self.cache_dir)),
                      build)

    def _theta(self, rows: int) -> np.ndarray:
        """``theta`` in each of ``rows`` rows (C-ordered: a compiled call reads it in place)."""
        if self.theta.shape[0] == rows:
            return self.theta
        if self._wide is None or self._wide.shape[0] != rows:
            self._wide = np.broadcast_to(self.theta[0], (rows, self.theta.shape[1])).copy()
        return self._wide

    def _single(self, kind: str) -> FunctionBuffer:
        """The unmapped function of ``kind``, for a few rows (a block of `BLOCK` rows for
        three nodes cost 0.15-0.2 ms on the virtual machine; a row alone, a few us)."""
        single = look_function(self.system) if kind == "look" else node_function(self.system)
        return buffered(single, "accuracy", kind, owner=self.system)

    def _evaluate(self, kind: str, inputs, outputs, count: int) -> None:
        """``outputs`` of the function of ``kind`` (its block map, or row by row for fewer
        than `FEW` rows) on ``count`` rows of ``inputs``; ``theta`` is the last input."""
        if count < FEW:
            single = self._single(kind)
            single.inputs[-1][:] = self.theta[:1]
            evaluate_in_blocks(copied(lambda *row: single(*row, None)), inputs, outputs,
                               count=count, width=1)
            return
        function = self._compiled(kind)
        if function.compiled:  # the nodes' own memory handed to the library, block by block
            wide = count // WIDE * WIDE  # in calls of WIDE rows, the rest in blocks
            for first, stop, width in ((0, wide, WIDE), (wide, count, BLOCK)):
                if stop > first:
                    buffer, trigger = _direct(self.system, function.function, width // BLOCK)
                    buffer.set_arg(len(inputs), memoryview(self._theta(width)))
                    evaluate_in_blocks(through_buffer(buffer, trigger),
                                       [values[first:stop] for values in inputs],
                                       [values[first:stop] for values in outputs],
                                       count=stop - first, width=width)
            return
        function.inputs[-1][:] = self.theta  # kept for every block
        evaluate_in_blocks(copied(lambda *block: function(*block, None)), inputs, outputs,
                           count=count, width=BLOCK)

    def first_look(self, t: np.ndarray, z: np.ndarray, *, last: bool = True):
        """``z_{k+1} - RK4(z_k)`` over every step between the rows of ``t``, ``z`` (rows), and
        the vector field and ``H`` at every node (as `at_nodes`; ``last=False``: not at the
        last node, whose row is left NaN, for a caller that reads the steps alone). The rows a
        look of this thread kept (`Kept`: the early verdict's first steps of the same march)
        are not evaluated again where the nodes are the same bits."""
        d, f, H = np.empty((t.size - 1, z.shape[1])), np.empty_like(z), np.empty(t.size)
        kept = Kept.of(self)
        reused = kept.prefix(self.theta[0], t, z)
        m = 0 if reused is None else reused[0].shape[0]  # steps read back
        if m:
            d[:m], f[:m], H[:m] = reused[0], reused[1][:m], reused[2][:m]
        self._look(t[m:], z[m:], d[m:], f[m:], H[m:], last)  # node m again, as the first
        if not m:
            kept.keep(self.theta[0], t, z, d, f, H)
        return d, f, H

    def _look(self, t, z, d, f, H, last: bool = True) -> None:
        """`first_look` evaluated into ``d``, ``f``, ``H``: the steps in blocks, the last node
        (a step of length 0 onto itself; its ``d`` is not kept) in the rows of the last block,
        which is padded anyway (it had been evaluated alone on the virtual machine, 50-100 us
        a call); ``last=False``: not the last node."""
        self.looks += t.size
        steps = t.size - 1
        h = np.diff(t)
        if not last:
            f[-1], H[-1] = np.nan, np.nan
            if steps:
                self._evaluate("look", [z[:-1], z[1:], t[:-1], h], [d, f[:-1], H[:-1]], steps)
            return
        head = steps - steps % BLOCK  # whole blocks; the rest and the last node together
        if head:
            self._evaluate("look", [z[:head], z[1:head + 1], t[:head], h[:head]],
                           [d[:head], f[:head], H[:head]], head)
        z_b = np.concatenate([z[head + 1:], z[-1:]])
        self._evaluate("look", [z[head:], z_b, t[head:], np.append(h[head:], 0.0)],
                       [d[head:], f[head:], H[head:]], t.size - head)

    def at_nodes(self, t: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The vector field ``f`` (rows) and ``H`` at the nodes ``(t_k, z_k)``."""
        f, H = np.empty_like(z), np.empty(t.size)
        self._evaluate("node", [z, t], [f, H], t.size)
        return f, H


class Kept:
    """The looks of the first nodes of a march (`NodeValues.first_look`), kept per system,
    compiler and thread: the early verdict looks at the first `KEPT_STEPS` steps window by
    window while the march runs, and the check of the finished march at every step from the
    first; the second reads the first's rows where its nodes, their times and ``theta`` are
    the same bits (the look is a function of these alone), so the first steps are looked at
    once. Any other nodes are evaluated: a kept row is never taken for a node it was not
    computed from."""

    def __init__(self):
        # (theta, t, z, d, f, H) of consecutive nodes from a first one: views of the first
        # `count` rows of buffers of KEPT_STEPS + 1 rows, filled window by window (a window
        # appended in place, not the kept rows copied again for each)
        self.rows = None
        self._buffers = None
        self.count = 0

    @staticmethod
    def of(values: NodeValues) -> Kept:
        local = cached(values.system, ("accuracy", "kept", values.compiler,
                                       str(values.cache_dir)), threading.local)
        if not hasattr(local, "kept"):
            local.kept = Kept()
        return local.kept

    def prefix(self, theta, t, z):
        """The kept ``(d, f, H)`` of the first nodes of ``t``, ``z`` (all the kept ones, as
        many as given or fewer: the last kept node's ``f`` and ``H`` are evaluated again), or
        ``None``."""
        if self.rows is None:
            return None
        kept_theta, kept_t, kept_z, d, f, H = self.rows
        m = kept_t.size
        if m > t.size or not np.array_equal(kept_theta, theta) or \
                not np.array_equal(kept_t, t[:m]) or not np.array_equal(kept_z, z[:m]):
            return None
        return d, f, H

    def keep(self, theta, t, z, d, f, H) -> None:
        """The look at ``t``, ``z`` kept: after the kept rows where it starts at their last
        node (the next window of the same march), else in their place; at most
        `KEPT_STEPS` steps."""
        rows, count = self.rows, self.count
        if rows is not None and count + t.size - 1 <= KEPT_STEPS + 1 and \
                self._buffers[2].shape[1] == z.shape[1] and \
                np.array_equal(rows[0], theta) and rows[1][-1] == t[0] and \
                np.array_equal(rows[2][-1], z[0]):
            first = count - 1  # the shared node: its f and H evaluated again, as given
        elif t.size <= KEPT_STEPS + 1:
            first = 0
            if self._buffers is None or self._buffers[2].shape[1] != z.shape[1]:
                size = KEPT_STEPS + 1
                self._buffers = (np.empty(size), np.empty((size, z.shape[1])),
                                 np.empty((size - 1, z.shape[1])),
                                 np.empty((size, z.shape[1])), np.empty(size))
            theta = np.array(theta)
        else:
            return
        end = first + t.size
        bt, bz, bd, bf, bH = self._buffers
        skip = 1 if first else 0  # the shared node's t and z stay the kept ones
        bt[first + skip:end], bz[first + skip:end] = t[skip:], z[skip:]
        bd[first:end - 1], bf[first:end], bH[first:end] = d, f, H
        self.count = end
        self.rows = (theta if first == 0 else rows[0], bt[:end], bz[:end], bd[:end - 1],
                     bf[:end], bH[:end])
