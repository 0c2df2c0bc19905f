"""An accuracy check of a trajectory that does not trust the scheme's own equations.

A march can satisfy every one of its equations and still not follow the motion: the energy
equation holds on a wrong energy level just as well as on the right one. So every trajectory is
also measured against the exact flow ``z' = f(z, t) = (H_p, -H_q)``, with three estimates:

1. **Local error of every step.** ``delta_k = |z_{k+1} - Phi_k|_inf``, where ``Phi_k`` is one
   classical Runge-Kutta step (two half steps for methods of order 3 or 4) of the exact flow from
   ``(t_k, z_k)`` over the accepted ``tau_k``. For a second-order scheme the RK4 step's own error,
   ``O(tau^5)``, is far below the scheme's ``O(tau^3)``, so ``delta_k`` is the step's local error
   up to a relative ``O(tau^2)``. A step fails when
   ``delta_k > atol + rtol * max(|z_k|_inf, |z_{k+1}|_inf)``.
2. **Energy.** ``level_error``: the energy level the first step sets (for the energy rules, the
   first interval's energy ``E_0``, kept for the whole march, so an error here is never repaired)
   against ``H(z_0, t_0)``; ``energy_drift`` (autonomous ``H`` only): ``max_k |H(z_k) - H(z_0)|``.
   Both relative to ``max(1, |H(z_0, t_0)|)``; each fails above ``energy_tol``.
3. **Global error estimate.** ``G_k = sum_{j<k} delta_j``: the local errors added up, as they
   are for a symplectic scheme whose errors grow linearly. It is reported, and checked only
   against ``global_tol`` when one is given: over long horizons the phase error of any scheme
   grows past every trajectory tolerance while the orbit stays right (the paper's own example).

The check runs as a monitor of the step loop (``driver.py``), on the nodes each call of the
stepper accepted, so it stops a march at the first step that fails (or, with ``stop=False``,
records the first failure and lets the march go on). The estimates are a compiled CasADi function
mapped over blocks of nodes, like the march's chunks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..cache import cached
from ..discrete.runge_kutta import rk4
from ..physics.hamiltonian import vector_field_function
from ..solution import Status
from ..validation import check_real
from .compiler import cache_folder, compile_function

BLOCK = 1024  # nodes per call of the compiled estimate (the last block is padded)
ADVICE = ("try a smaller tau0, fixed steps (scheme 'fixed'), or the least-squares step; "
          "accept_inaccurate records the estimates and goes on")


@dataclass(frozen=True)
class Tolerance:
    """What the accuracy check accepts.

    Attributes:
        rtol, atol: the local error test ``delta_k <= atol + rtol * |z|``.
        energy_tol: bound on ``level_error`` and ``energy_drift`` (relative to ``max(1, |H0|)``).
        global_tol: optional bound on the global estimate relative to ``max(1, max |z|)``.
        stop: end the march at the first failure (status ``inaccurate``); ``False`` records it
            and goes on.
    """

    rtol: float = 1e-2
    atol: float = 1e-2
    energy_tol: float = 0.1
    global_tol: float | None = None
    stop: bool = True

    def __post_init__(self):
        for name in ("rtol", "atol", "energy_tol"):
            object.__setattr__(self, name, check_real(name, getattr(self, name), positive=True))
        object.__setattr__(self, "global_tol",
                           check_real("global_tol", self.global_tol, positive=True,
                                      allow_none=True))


def local_error_function(system, substeps: int = 1) -> ca.Function:
    """``(z_a, z_b, t_a, tau, theta) -> (delta, scale, H_b)``: the local error estimate of the
    step from ``z_a`` to ``z_b``, ``max(|z_a|, |z_b|)`` and ``H`` at the new node."""
    def build():
        n2 = 2 * system.n
        field = vector_field_function(system)
        z_a, z_b = ca.SX.sym("z_a", n2), ca.SX.sym("z_b", n2)
        t_a, tau = ca.SX.sym("t_a"), ca.SX.sym("tau")
        theta = ca.SX.sym("theta", system.theta.numel())

        def flow(z, t):
            return field(z, t, theta)

        z, h = z_a, tau / substeps
        for i in range(substeps):
            z = rk4(flow, z, t_a + i * h, h)
        delta = ca.norm_inf(z_b - z)
        scale = ca.fmax(ca.norm_inf(z_a), ca.norm_inf(z_b))
        H_b = system.H_function(z_b[:system.n], z_b[system.n:], t_a + tau, theta)
        return ca.Function("local_error", [z_a, z_b, t_a, tau, theta], [delta, scale, H_b],
                           ["z_a", "z_b", "t_a", "tau", "theta"], ["delta", "scale", "H_b"])
    return cached(system, ("local_error", substeps), build)


class LocalErrors:
    """The local error estimate over many steps at once: a compiled map over ``BLOCK`` nodes
    (CasADi's virtual machine where no compiler is given)."""

    def __init__(self, system, substeps: int = 1, *, compiler=None, cache_dir=None):
        self.system = system
        single = local_error_function(system, substeps)
        function = single.map(BLOCK)
        if compiler is not None:
            key = ("local_error_block", substeps, compiler, str(cache_dir))
            function = cached(system, key, lambda: compile_function(
                function, compiler, cache_folder(cache_dir)))
        self.block = function

    def __call__(self, t: np.ndarray, z: np.ndarray, theta: np.ndarray):
        """``delta``, ``scale`` and ``H`` of the new node for the steps between the rows of
        ``t`` (M+1,) and ``z`` (M+1, 2n): three arrays of shape (M,)."""
        steps = t.size - 1
        out = np.empty((3, max(steps, 0)))
        theta_block = np.tile(np.asarray(theta, float)[:, None], (1, BLOCK))
        for start in range(0, steps, BLOCK):
            stop = min(start + BLOCK, steps)
            count = stop - start
            z_a, z_b = _padded(z[start:stop]), _padded(z[start + 1:stop + 1])
            t_a = _padded(t[start:stop])
            tau = _padded(np.diff(t[start:stop + 1]))
            delta, scale, H_b = self.block(z_a.T, z_b.T, t_a[None, :], tau[None, :],
                                           theta_block)
            out[:, start:stop] = np.vstack([np.asarray(v).ravel()[:count]
                                            for v in (delta, scale, H_b)])
        return out[0], out[1], out[2]


def _padded(values: np.ndarray) -> np.ndarray:
    """``values`` (rows) repeated from its last row up to ``BLOCK`` rows."""
    extra = BLOCK - values.shape[0]
    return np.pad(values, [(0, extra)] + [(0, 0)] * (values.ndim - 1), mode="edge")


class AccuracyMonitor:
    """The accuracy check as a monitor of the step loop (``driver.py``, rule 5).

    ``level`` is ``None`` for schemes without an energy level (fixed steps), else a function of
    the first two nodes ``(t, z)`` giving the level the first step sets."""

    def __init__(self, system, theta, tolerance: Tolerance, *, H0: float, level=None,
                 substeps: int = 1, compiler=None, cache_dir=None):
        self.system = system
        self.theta = np.asarray(theta, float)
        self.tolerance = tolerance
        self.H0 = H0
        self.energy_scale = max(1.0, abs(H0))
        self.level_of = level
        self.autonomous = not system.time_dependent
        self.errors = LocalErrors(system, substeps, compiler=compiler, cache_dir=cache_dir)
        self.delta: list[np.ndarray] = []
        self.level = None
        self.level_error = math.nan
        self.energy_drift = 0.0 if self.autonomous else math.nan
        self.size = 0.0
        self.failure = None  # the first failed test: {"step", "t", "test", "value", "limit"}

    # -- the monitor -------------------------------------------------------------------------
    def watch(self, nodes, first: int, advance):
        start = max(first - 1, 0)  # the new steps run from node start to nodes.count - 1
        t, z = nodes.t[start:nodes.count], nodes.z[start:nodes.count]
        if t.size < 2:
            return None
        delta, scale, H = self.errors(t, z, self.theta)
        self.delta.append(delta)
        self.size = max(self.size, float(np.max(scale)))
        failure = self._first_failure(start, t, z, delta, scale, H)
        if failure is None or self.failure is not None:
            return None
        self.failure = failure
        if not self.tolerance.stop:
            return None
        keep = failure["step"] + 1 - first + 1  # the nodes up to the end of the failing step
        return Status.INACCURATE, self.describe(failure), max(keep, 0)

    def _first_failure(self, start, t, z, delta, scale, H):
        """The first step among these that fails a test, as a dict, or None."""
        tol = self.tolerance
        candidates = []
        local = delta > tol.atol + tol.rtol * scale
        if np.any(local):
            i = int(np.argmax(local))
            candidates.append((i, "local error", delta[i], tol.atol + tol.rtol * scale[i]))
        if start == 0 and self.level_of is not None:
            self.level = float(self.level_of(t[:2], z[:2]))
            self.level_error = abs(self.level - self.H0) / self.energy_scale
            if self.level_error > tol.energy_tol:
                candidates.append((0, "energy level of the first step", self.level_error,
                                   tol.energy_tol))
        if self.autonomous:
            drift = np.abs(H - self.H0) / self.energy_scale
            self.energy_drift = max(self.energy_drift, float(np.max(drift)))
            over = drift > tol.energy_tol
            if np.any(over):
                i = int(np.argmax(over))
                candidates.append((i, "nodal energy drift", drift[i], tol.energy_tol))
        if tol.global_tol is not None:
            total = self.global_estimate
            if total / max(1.0, self.size) > tol.global_tol:
                running = (total - float(np.sum(delta))) + np.cumsum(delta)
                i = int(np.argmax(running / max(1.0, self.size) > tol.global_tol))
                candidates.append((i, "global error estimate", running[i] / max(1.0, self.size),
                                   tol.global_tol))
        if not candidates:
            return None
        i, test, value, limit = min(candidates, key=lambda c: c[0])
        return {"step": start + i, "t": float(t[i]), "test": test, "value": float(value),
                "limit": float(limit)}

    # -- what it found -----------------------------------------------------------------------
    @property
    def global_estimate(self) -> float:
        return float(sum(float(np.sum(d)) for d in self.delta))

    def local_errors(self, steps: int) -> np.ndarray:
        """``delta_k`` of the first ``steps`` steps."""
        values = np.concatenate(self.delta) if self.delta else np.zeros(0)
        return values[:steps]

    @staticmethod
    def describe(failure) -> str:
        return (f"the {failure['test']} of step {failure['step']} (from t = "
                f"{failure['t']:.10g}) is {failure['value']:.3e} > {failure['limit']:.3e}; "
                + ADVICE)

    def report(self, steps: int) -> dict:
        """The estimates of a run of ``steps`` steps, for ``Solution.stats["accuracy"]``."""
        delta = self.local_errors(steps)
        tol = self.tolerance
        return {"verdict": "inaccurate" if self.failure else "accurate",
                "first_failure": self.failure,
                "level": self.level, "level_error": self.level_error,
                "energy_drift": self.energy_drift,
                "local_error_max": float(delta.max()) if delta.size else 0.0,
                "global_error_estimate": float(delta.sum()),
                "global_error_relative": float(delta.sum()) / max(1.0, self.size),
                "rtol": tol.rtol, "atol": tol.atol, "energy_tol": tol.energy_tol,
                "global_tol": tol.global_tol}
