"""The exact flow ``z' = f(z, t) = (H_p, -H_q)``, integrated to an accuracy the checks can trust:
a reference trajectory at a run's own node times, and the flow map over each of its steps.

The integrator is the explicit Runge-Kutta method of order 8 of Dormand and Prince (the twelve
stages of DOP853; Hairer, Norsett and Wanner, *Solving Ordinary Differential Equations I*,
section II.10; the coefficients are taken from scipy, which ships them), written once as a
CasADi expression and compiled with the march's compiler (``compiler.py``; CasADi's virtual
machine where there is none). It shares nothing with the schemes it checks: no equation of
``discrete/``, no Newton, no step the scheme chose other than the node times themselves.

Its own error is controlled by step doubling. Every quantity is computed twice, with ``m`` and
with ``2m`` equal substeps per interval (the pair ``A``, ``B``); ``B`` is the result and
``|A - B|`` bounds its error: for an order-8 method ``B``'s error is about ``|A - B| / 255``
once the substeps resolve the motion, and along a trajectory ``|A - B|`` grows with the flow's
sensitivity exactly as ``B``'s error does (a chaotic orbit shows it in both). Where ``|A - B|``
passes the budget its caller sets, the caller repeats the computation with ``m`` doubled, up to
``MAX_SUBSTEPS``: a coarse run (few, long steps) costs more substeps, a fine one none.

A substep count ``m`` is a finer time grid (each interval cut into ``m`` equal pieces), not a
new compiled function: one compiled step serves every ``m``.
"""

from __future__ import annotations

from collections.abc import Iterator

import casadi as ca
import numpy as np

from ...cache import cached
from ...discrete.runge_kutta import rk4
from ...physics.hamiltonian import vector_field_function
from ...physics.higher_order import HigherOrderSystem, euler_lagrange_field
from ..compiler import (
    CompileUnavailable,
    FunctionBuffer,
    buffered,
    cache_folder,
    compile_function,
    warn_once,
)

BLOCK = 512  # intervals per call of a compiled block (the last block is padded)
MAX_SUBSTEPS = 256  # the finest substep count tried (a run of a few long steps)


def _tableau():
    """``(A, b, c)`` of the order-8 solution of DOP853 (its first twelve stages)."""
    dop = _dop853_coefficients()
    stages = dop.N_STAGES
    return dop.A[:stages, :stages], dop.B, dop.C[:stages]


def _dop853_coefficients():
    """scipy's module of DOP853's coefficients, loaded from its file on its own: importing it
    through ``scipy.integrate`` would load scipy.integrate's solvers with scipy.sparse and
    scipy.linalg behind them (113 modules, which a march does not otherwise load)."""
    import importlib.util
    import sys
    from pathlib import Path

    name = "ddvp_nlp_dop853_coefficients"
    if name not in sys.modules:
        spec = importlib.util.find_spec("scipy")
        path = Path(spec.origin).parent / "integrate" / "_ivp" / "dop853_coefficients.py"
        module = importlib.util.module_from_spec(importlib.util.spec_from_file_location(
            name, path))
        module.__spec__.loader.exec_module(module)
        sys.modules[name] = module
    return sys.modules[name]


def order8_step(flow, z, t, h):
    """One step of length ``h`` of DOP853's order-8 formula for ``z' = flow(z, t)``."""
    a, b, c = _tableau()
    stages = []
    for i in range(len(c)):
        state = z
        for j in range(i):
            if a[i, j] != 0:
                state = state + (h * float(a[i, j])) * stages[j]
        stages.append(flow(state, t + float(c[i]) * h))
    return z + h * sum(float(b[i]) * stages[i] for i in range(len(c)) if b[i] != 0)


def flow_field(system) -> tuple[ca.Function, int]:
    """The exact flow's vector field ``(z, t, theta) -> z'`` and the size of ``z``: Hamilton's
    equations ``(H_p, -H_q)`` for a system with ``H`` (or a first-order ``L``), the
    Euler-Lagrange equation in Ostrogradsky's variables for a higher-order ``L``."""
    if isinstance(system, HigherOrderSystem):
        return euler_lagrange_field(system), 2 * system.order * system.n
    return vector_field_function(system), 2 * system.n


def pair_function(system) -> ca.Function:
    """``(z_a, z_b, t, h, theta) -> (A, B)``: one order-8 step of length ``h`` from ``z_a`` and
    two of length ``h / 2`` from ``z_b``, both from time ``t``."""
    def build():
        field, n2 = flow_field(system)
        theta = ca.SX.sym("theta", system.theta.numel())
        z_a, z_b = ca.SX.sym("z_a", n2), ca.SX.sym("z_b", n2)
        t, h = ca.SX.sym("t"), ca.SX.sym("h")

        def flow(z, time):
            return field(z, time, theta)

        one = order8_step(flow, z_a, t, h)
        half = order8_step(flow, order8_step(flow, z_b, t, h / 2), t + h / 2, h / 2)
        return ca.Function("reference_pair", [z_a, z_b, t, h, theta], [one, half],
                           ["z_a", "z_b", "t", "h", "theta"], ["A", "B"], {"cse": True})
    return cached(system, "reference_pair", build)


def look_function(system) -> ca.Function:
    """``(z_a, z_b, t, h, theta) -> (z_b - RK4(z_a), f(z_a), H(z_a))``: a step's local error
    against one classical Runge-Kutta step of the exact flow, component by component (the cheap
    first look of a second-order march's steps; ``accuracy.py``), with the vector field and
    ``H`` at its first node (the RK4 step's first stage: computed once)."""
    def build():
        field, n2 = flow_field(system)
        theta = ca.SX.sym("theta", system.theta.numel())
        z_a, z_b = ca.SX.sym("z_a", n2), ca.SX.sym("z_b", n2)
        t, h = ca.SX.sym("t"), ca.SX.sym("h")
        step = rk4(lambda z, time: field(z, time, theta), z_a, t, h)
        H = system.H_function(z_a[:system.n], z_a[system.n:], t, theta)
        return ca.Function("reference_look", [z_a, z_b, t, h, theta],
                           [z_b - step, field(z_a, t, theta), H],
                           ["z_a", "z_b", "t", "h", "theta"], ["d", "f", "H"], {"cse": True})
    return cached(system, "reference_look", build)


def node_function(system) -> ca.Function:
    """``(z, t, theta) -> (f, H)``: the vector field and ``H`` at one node."""
    def build():
        n2 = 2 * system.n
        field = vector_field_function(system)
        theta = ca.SX.sym("theta", system.theta.numel())
        z, t = ca.SX.sym("z", n2), ca.SX.sym("t")
        H = system.H_function(z[:system.n], z[system.n:], t, theta)
        return ca.Function("reference_node", [z, t, theta], [field(z, t, theta), H],
                           ["z", "t", "theta"], ["f", "H"], {"cse": True})
    return cached(system, "reference_node", build)


class ReferenceFlow:
    """The exact flow of ``system`` with parameters ``theta``, by `pair_function` on
    blocks of ``BLOCK`` intervals: as a chain (`chain`, the reference trajectory from one
    state through given node times) and as a map (`maps`, the flow over each of many
    intervals from its own start)."""

    def __init__(self, system, theta, *, compiler=None, cache_dir=None):
        self.system = system
        self.theta = np.broadcast_to(np.asarray(theta, float),
                                     (BLOCK, system.theta.numel())).copy()
        self.compiler, self.cache_dir = compiler, cache_dir
        self._chain = self._map = self._nodes = None

    def _compiled(self, kind: str) -> FunctionBuffer:
        """The block function ``kind`` (``chain``, ``map`` or ``nodes``), compiled once per
        system and compiler, with its call buffers."""
        key = ("reference", kind, self.compiler, str(self.cache_dir))
        return cached(self.system, key, lambda: FunctionBuffer(self._build(kind)))

    def _build(self, kind: str) -> ca.Function:
        pair = pair_function(self.system)
        if kind == "chain":
            function = pair.mapaccum("reference_chain", BLOCK, 2)
        elif kind == "map":
            function = pair.map("reference_map", "serial", BLOCK, [], [])
        elif kind == "look":
            function = look_function(self.system).map("reference_looks", "serial", BLOCK,
                                                      [], [])
        else:
            function = node_function(self.system).map("reference_nodes", "serial", BLOCK, [],
                                                      [])
        failed = cached(self.system, ("reference compile", self.compiler, str(self.cache_dir)),
                        lambda: {"failed": False})
        if self.compiler is None or failed["failed"]:
            return function
        try:
            return compile_function(function, self.compiler, cache_folder(self.cache_dir),
                                    prefix="reference")
        except CompileUnavailable as reason:  # the virtual machine computes the same
            warn_once(reason)
            failed["failed"] = True  # one warning: the other block functions do not try
            return function

    def chain(self, t: np.ndarray, z0: np.ndarray, substeps: int = 1
              ) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
        """The flow from ``z0`` at ``t[0]`` through the times ``t`` (increasing), block by
        block: ``(first, A, B)`` with the states at the nodes ``first + 1 .. first + len(A)``
        (``A`` with ``substeps``, ``B`` with ``2 substeps`` substeps per interval). The caller
        may stop early."""
        if self._chain is None:
            self._chain = self._compiled("chain")
        m = int(substeps)
        tau = np.diff(t)
        # the finer grid: interval k cut into m pieces, its end at every m-th substep
        starts = (t[:-1, None] + tau[:, None] * (np.arange(m) / m)[None, :]).ravel()
        lengths = np.repeat(tau / m, m)
        state_a, state_b = np.array(z0, float), np.array(z0, float)
        per_block = BLOCK // m if m <= BLOCK else 0
        nodes_per_call = max(per_block, 1)
        for first in range(0, tau.size, nodes_per_call):
            last = min(first + nodes_per_call, tau.size)
            rows_a, rows_b = [], []
            for sub in range(first * m, last * m, BLOCK):
                stop = min(sub + BLOCK, last * m)
                count = stop - sub
                A, B = self._chain(state_a, state_b, _padded(starts[sub:stop]),
                                   _padded(lengths[sub:stop]), self.theta)
                state_a, state_b = A[count - 1].copy(), B[count - 1].copy()
                rows_a.append(A[:count])
                rows_b.append(B[:count])
            yield first, np.vstack(rows_a)[m - 1::m], np.vstack(rows_b)[m - 1::m]

    def maps(self, t_a: np.ndarray, z_a: np.ndarray, tau: np.ndarray, substeps: int = 1
             ) -> tuple[np.ndarray, np.ndarray]:
        """The flow over each interval ``[t_a[k], t_a[k] + tau[k]]`` from ``z_a[k]`` (rows):
        ``(A, B)``, with ``substeps`` and ``2 substeps`` substeps."""
        if self._map is None:
            self._map = self._compiled("map")
        A, B = np.array(z_a, float), np.array(z_a, float)
        h = np.asarray(tau, float) / substeps
        for first in range(0, h.size, BLOCK):
            last = min(first + BLOCK, h.size)
            count = last - first
            a, b = A[first:last], B[first:last]
            for j in range(substeps):
                start = t_a[first:last] + j * h[first:last]
                out_a, out_b = self._map(_padded(a), _padded(b), _padded(start),
                                         _padded(h[first:last]), self.theta)
                a, b = out_a[:count].copy(), out_b[:count].copy()
            A[first:last], B[first:last] = a, b
        return A, B

    def flow(self, z0: np.ndarray, t0: float, t1: float, substeps: int = 8
             ) -> tuple[np.ndarray, float]:
        """The flow from ``z0`` at ``t0`` to ``t1`` (one state): ``B`` with ``2 substeps``
        substeps, and ``|A - B|_inf``, the bound of its error."""
        single = buffered(pair_function(self.system), "reference_pair", owner=self.system)
        a, b = np.array(z0, float), np.array(z0, float)
        h = (t1 - t0) / substeps
        for j in range(substeps):
            out_a, out_b = single(a, b, t0 + j * h, h, self.theta[0])
            a, b = out_a[0].copy(), out_b[0].copy()
        return b, float(np.max(np.abs(a - b)))

    def first_look(self, t: np.ndarray, z: np.ndarray):
        """``z_{k+1} - RK4(z_k)`` over every step between the rows of ``t``, ``z`` (rows), and
        the vector field and ``H`` at every node (as `at_nodes`)."""
        look = self._compiled("look")
        d, f, H = np.empty((t.size - 1, z.shape[1])), np.empty_like(z), np.empty(t.size)
        tau = np.diff(t)
        for first in range(0, tau.size, BLOCK):
            last = min(first + BLOCK, tau.size)
            count = last - first
            out_d, out_f, out_H = look(_padded(z[first:last]), _padded(z[first + 1:last + 1]),
                                       _padded(t[first:last]), _padded(tau[first:last]),
                                       self.theta)
            d[first:last], f[first:last], H[first:last] = (out_d[:count], out_f[:count],
                                                           out_H[:count, 0])
        f[-1:], H[-1:] = self.at_nodes(t[-1:], z[-1:])
        return d, f, H

    def at_nodes(self, t: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The vector field ``f`` (rows) and ``H`` at the nodes ``(t_k, z_k)``."""
        if self._nodes is None:
            self._nodes = self._compiled("nodes")
        f, H = np.empty_like(z), np.empty(t.size)
        for first in range(0, t.size, BLOCK):
            last = min(first + BLOCK, t.size)
            count = last - first
            out_f, out_H = self._nodes(_padded(z[first:last]), _padded(t[first:last]),
                                       self.theta)
            f[first:last], H[first:last] = out_f[:count], out_H[:count, 0]
        return f, H


def _padded(values: np.ndarray) -> np.ndarray:
    """``values`` (rows) repeated from its last row up to ``BLOCK`` rows."""
    extra = BLOCK - values.shape[0]
    if extra == 0:
        return values
    return np.pad(values, [(0, extra)] + [(0, 0)] * (values.ndim - 1), mode="edge")
