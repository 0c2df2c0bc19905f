"""Chaos indicators of one orbit on the march's tangent map: MEGNO, the fast Lyapunov indicator
and the largest Lyapunov exponent (and, on request, the full spectrum, ``spectrum.py``).

One synchronous tangent vector (``tangent.py``) is carried by the compiled chunk and
renormalised every step; ``ell_k = ln(|w_{k+1}| / |w_k|)`` is its growth over step ``k``
(``|w_0| = 1``). The norm is ``|W w|``, ``W`` a symplectic scaling of each pair ``(q_i,
p_i)`` read off the flow at the start (``physics.hamiltonian.symplectic_weights``), so that no
indicator depends on the units of a coordinate or of time (with the plain norm a Henon-Heiles
orbit's FLI in time units of ``1e5`` was ``ln 1e5`` above its FLI in units of 1). Times are
counted from ``t_0``. The indicators at node ``N``:

- MEGNO (Cincotta and Simo 2000). Continuously ``Y(t) = (2/t) int_0^t s d ln|delta(s)|`` and
  its mean ``<Y>(t) = (1/t) int_0^t Y(s) ds``. On the nodes, with the midpoint of each step as
  its weight and the trapezoidal mean (``Y_0 = 0``)::

      Y_N   = (2/t_N) sum_{k<N} (t_k + t_{k+1})/2 ell_k,
      <Y>_N = (1/t_N) sum_{k=1}^{N} tau_{k-1} (Y_{k-1} + Y_k)/2.

  Both sums are exact when ``ln|delta|`` is linear in ``s`` over a step, so the weights add an
  error of second order in the steps; the weight ``t_{k+1}`` would add
  ``(1/t_N) sum tau_k ell_k ~ tau ln|delta_N| / t_N``, of first order (measured,
  docs/chaos/README.md). Limits: ``<Y> -> 2`` on a quasi-periodic orbit (an invariant torus),
  ``0`` on a stable isochronous periodic orbit, ``~ lambda t / 2`` on a chaotic one.
- The fast Lyapunov indicator ``FLI_N = max_{k <= N} ln|w_k|``.
- The largest exponent ``lambda_N = ln|w_N| / t_N``, per unit time (not per step: the node
  map is a reparametrised flow whose exponents per unit ``t`` are the flow's).

Streaming: the chunk returns ``ell``; `MegnoSums` keeps the four running sums (``S``,
the mean's integral, ``ln|w|``, its maximum), so nothing per node is kept.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ...discrete.scheme import Scheme
from ...solution import Status
from ..options import Compilation, StepControl
from .spectrum import lyapunov_spectrum
from .tangent_march import TangentMarch, start_tangent


@dataclass
class MegnoSums:
    """The running sums of one renormalised vector (module docstring), from ``t_0``."""

    t: float = 0.0  # the last node's time, from t_0
    S: float = 0.0  # sum of (t_k + t_{k+1})/2 ell_k
    Y: float = 0.0  # Y at the last node
    mean_integral: float = 0.0  # sum of tau (Y_prev + Y)/2
    log_norm: float = 0.0  # ln|w| at the last node
    fli: float = 0.0  # max of ln|w| so far
    steps: int = 0

    def add(self, t: np.ndarray, ell: np.ndarray) -> dict:
        """Take the nodes at times ``t`` (from ``t_0``) reached by steps of growth ``ell``;
        returns the indicators at each of them (arrays)."""
        before = np.concatenate([[self.t], t[:-1]])
        S = self.S + np.cumsum(0.5 * (before + t) * ell)
        Y = 2.0 * S / t
        Y_before = np.concatenate([[self.Y], Y[:-1]])
        integral = self.mean_integral + np.cumsum((t - before) * 0.5 * (Y_before + Y))
        log_norm = self.log_norm + np.cumsum(ell)
        fli = np.maximum(self.fli, np.maximum.accumulate(log_norm))
        self.t, self.S, self.Y = float(t[-1]), float(S[-1]), float(Y[-1])
        self.mean_integral, self.log_norm = float(integral[-1]), float(log_norm[-1])
        self.fli = float(fli[-1])
        self.steps += t.size
        return {"t": t, "megno": integral / t, "megno_instant": Y, "fli": fli,
                "lyapunov": log_norm / t}

    def values(self) -> dict:
        """The indicators at the last node."""
        t = self.t if self.t > 0 else math.nan
        return {"t": self.t, "megno": self.mean_integral / t, "megno_instant": self.Y,
                "fli": self.fli, "lyapunov": self.log_norm / t}


@dataclass
class ChaosIndicators:
    """The indicators of one orbit at its last node (module docstring).

    Attributes:
        megno: ``<Y>`` at ``t``; ``megno_instant``: ``Y``; ``fli``: the fast Lyapunov
            indicator; ``lyapunov``: the largest exponent ``ln|w| / (t - t_0)``.
        t: the last node's time (the first node at or past ``t_end``), absolute.
        steps: steps marched; ``status``, ``message``: how the march ended (a failure keeps
            the indicators of the last accepted node).
        snapshots: the same indicators at the first node at or past each time asked for
            (``{"t": ..., "megno": ..., ...}`` arrays in the order asked; NaN where not
            reached).
        spectrum: the `Spectrum` when asked for, else ``None``.
        seconds: CPU seconds of the march with its tangent (step 0, chunks, sums).
    """

    megno: float
    megno_instant: float
    fli: float
    lyapunov: float
    t: float
    steps: int
    status: Status
    message: str
    snapshots: dict = field(default_factory=dict)
    spectrum: object = None
    seconds: float = 0.0


def chaos_indicators(system, q0, p0, t_span, *, tau0: float, scheme: str | Scheme = "vddvp",
                     params=None, steps: StepControl | None = None,
                     compilation: Compilation | None = None, tangent0=None,
                     snapshots: Sequence[float] = (), spectrum: bool = False
                     ) -> ChaosIndicators:
    """MEGNO, FLI and the largest exponent of the march from ``z_0 = (q0, p0)`` (module
    docstring), its tangent carried in the compiled chunk: the nodes are `march`'s bit for
    bit.

    Args:
        system, q0, p0, t_span, tau0, scheme, params, steps, compilation: as for `march`
            (an energy rule; autonomous ``H``); the march stops at the first node at or past
            ``t_end``.
        tangent0: the start's tangent ``dz_0`` (``2n`` numbers; default all ones in the
            weighted coordinates), normalised in the weighted norm
            (``physics.hamiltonian.symplectic_weights``: no coordinate's or time's units).
        snapshots: times at which the indicators are also kept (`ChaosIndicators.snapshots`).
        spectrum: also the full spectrum on the fixed-level map (`lyapunov_spectrum`, a
            second march with ``2n`` vectors: the same nodes).

    Returns:
        `ChaosIndicators`; a failed step is a status on it, never an exception.
    """
    started = time.process_time()
    run = TangentMarch.build(system, q0, p0, t_span, tau0=tau0, scheme=scheme, params=params,
                             steps=steps, compilation=compilation, vectors=1,
                             observation="sync")
    dz0 = start_tangent(system.n, tangent0, run.weights)
    times = np.sort(np.asarray(snapshots, float).reshape(-1))
    p = run.problem
    sums = MegnoSums()
    kept = {key: np.full(times.size, math.nan) for key in ("t", "megno", "megno_instant",
                                                            "fli", "lyapunov")}
    start, failure = run.first_step()
    if failure is None:
        t1, z0, z1 = start
        X1 = run.chunk.tangent.first_step(p.t0, t1, z0, z1, p.theta, dz0)
        norm = float(np.linalg.norm(run.weights * X1[-2 * system.n:, 0]))
        _take(sums, kept, times, np.array([t1 - p.t0]), np.array([math.log(norm)]), p.t0)
        status, message = yield_from(run.chunks(start, X1 / norm), sums, kept, times, p.t0)
    else:
        status, message = failure
    values = sums.values()
    result = ChaosIndicators(megno=values["megno"], megno_instant=values["megno_instant"],
                             fli=values["fli"], lyapunov=values["lyapunov"],
                             t=p.t0 + sums.t, steps=sums.steps, status=status, message=message,
                             snapshots=kept)
    result.seconds = time.process_time() - started
    if spectrum:
        result.spectrum = lyapunov_spectrum(system, q0, p0, t_span, tau0=tau0, scheme=scheme,
                                            params=params, steps=steps,
                                            compilation=compilation)
    return result


def yield_from(chunks, sums: MegnoSums, kept: dict, times, t0: float):
    """Feed every accepted chunk step into ``sums`` (and the snapshots); the generator's
    final ``(status, message)``."""
    while True:
        try:
            columns, count = next(chunks)
        except StopIteration as end:
            return end.value
        _take(sums, kept, times, columns["t_next"][:count] - t0, columns["ell"][:count, 0], t0)


def _take(sums: MegnoSums, kept: dict, times, t: np.ndarray, ell: np.ndarray, t0: float):
    """Add the steps to the sums; fill the snapshots the new nodes reach first."""
    values = sums.add(t, ell)
    if not times.size:
        return
    absolute = t + t0
    for i, when in enumerate(times):
        if math.isnan(kept["t"][i]) and absolute[-1] >= when:
            j = int(np.searchsorted(absolute, when))
            for key in kept:
                kept[key][i] = values[key][j] + (t0 if key == "t" else 0.0)
