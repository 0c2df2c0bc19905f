"""What the accuracy check evaluates at every node or step of a trajectory, compiled and mapped
over blocks of nodes (CasADi's virtual machine where there is no compiler): the vector field
and ``H`` at the nodes (the energy scale and drift), and the first look at every step
(``z_{k+1} - RK4(z_k)``, one classical Runge-Kutta step of the exact flow: a cheap filter of the
steps that plainly pass the local test)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ...blocks import copied, evaluate_in_blocks
from ...cache import cached
from ...discrete.runge_kutta import rk4
from ..compiler import FunctionBuffer, RentedBuffer
from ..exact.flow import flow_field

BLOCK = 512  # nodes per call of a compiled block (the last block padded: blocks.py)


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


class NodeValues:
    """`first_look` and `at_nodes` of ``system`` with parameters ``theta``, compiled once per
    system and compiler (kept with the system)."""

    def __init__(self, system, theta, *, compiler=None, cache_dir=None):
        self.system = system
        self.theta = np.broadcast_to(np.asarray(theta, float),
                                     (BLOCK, system.theta.numel())).copy()
        self.compiler, self.cache_dir = compiler, cache_dir

    def _compiled(self, kind: str) -> FunctionBuffer:
        def build():
            single = look_function(self.system) if kind == "look" else \
                node_function(self.system)
            mapped = single.map(f"accuracy_{kind}s", "serial", BLOCK, [], [])
            return RentedBuffer(mapped, self.compiler, self.cache_dir, prefix="exact")
        return cached(self.system, ("accuracy", kind, self.compiler, str(self.cache_dir)),
                      build)

    def first_look(self, t: np.ndarray, z: np.ndarray):
        """``z_{k+1} - RK4(z_k)`` over every step between the rows of ``t``, ``z`` (rows), and
        the vector field and ``H`` at every node (as `at_nodes`)."""
        look = self._compiled("look")
        d, f, H = np.empty((t.size - 1, z.shape[1])), np.empty_like(z), np.empty(t.size)
        look.inputs[4][:] = self.theta  # kept for every block
        evaluate_in_blocks(copied(lambda *block: look(*block, None)),
                           [z[:-1], z[1:], t[:-1], np.diff(t)], [d, f[:-1], H[:-1]],
                           count=t.size - 1, width=BLOCK)
        f[-1:], H[-1:] = self.at_nodes(t[-1:], z[-1:])
        return d, f, H

    def at_nodes(self, t: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The vector field ``f`` (rows) and ``H`` at the nodes ``(t_k, z_k)``."""
        nodes = self._compiled("node")
        f, H = np.empty_like(z), np.empty(t.size)
        nodes.inputs[2][:] = self.theta
        evaluate_in_blocks(copied(lambda *block: nodes(*block, None)), [z, t], [f, H],
                           count=t.size, width=BLOCK)
        return f, H
