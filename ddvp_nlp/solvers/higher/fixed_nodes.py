"""The data of a higher-order fixed-endpoint problem and what follows from it: the ``data`` of
its `GridRequest`, and the helpers the solves and the
verification read it by (``window_solve.py``, ``window_nlp.py``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..grid.problem import GridRequest
from .windows import HigherEnds


@dataclass
class FixedNodes:
    """The data of a higher-order fixed-endpoint problem (the ``data`` of its
    `GridRequest`): the ``l`` fixed nodes at each end, ``t_start`` ``(l,)``,
    ``q_start`` ``(l, n)``, likewise at the stop."""

    t_start: np.ndarray
    q_start: np.ndarray
    t_stop: np.ndarray
    q_stop: np.ndarray

    @property
    def times(self) -> np.ndarray:
        return np.concatenate([self.t_start, self.t_stop])


def order(request: GridRequest[FixedNodes]) -> int:
    return request.system.order


def uniform(request: GridRequest[FixedNodes]) -> np.ndarray:
    """Every node time on uniform steps between the fixed ones."""
    data, l, N = request.data, order(request), request.nodes  # noqa: E741 (l: the order)
    inner = np.linspace(data.t_start[-1], data.t_stop[0], N - 2 * l + 2)[1:-1]
    return np.concatenate([data.t_start, inner, data.t_stop])


def mean_step(request: GridRequest[FixedNodes]) -> float:
    data = request.data
    return (data.t_stop[0] - data.t_start[-1]) / (request.nodes - 2 * order(request) + 1)


def el_scale(request: GridRequest[FixedNodes]) -> float:
    """The Euler-Lagrange rows' factor: an EL row ~ dq / tau^(2l-1)."""
    return mean_step(request) ** (2 * order(request) - 1)


def data_scale(request: GridRequest[FixedNodes]) -> float:
    """The data's magnitude, ``max |q|`` over the fixed nodes, in the units of ``q`` (no floor
    of 1: in lengths of ``1e-8`` it made every round-off bound ``1e8`` times the rows', and
    Newton stopped ``3e-6`` of the motion short); 1 only where every fixed ``q`` is 0."""
    data = request.data
    scale = float(max(np.max(np.abs(data.q_start)), np.max(np.abs(data.q_stop))))
    return scale if scale > 0 else 1.0


def data_sizes(request: GridRequest[FixedNodes]) -> np.ndarray:
    """``(N m,)``: the size of a change of each unknown the problem notices, taken from the
    data (a diverged iterate does not excuse itself): a time's the mean step, a position's
    the range of that coordinate over the fixed nodes (its magnitude where the ends agree)."""
    data, m = request.data, request.system.n + 1
    q = np.concatenate([data.q_start, data.q_stop])
    ranges = np.ptp(q, axis=0)
    ranges = np.where(ranges > 0, ranges, np.max(np.abs(q), axis=0))
    sizes = np.empty((request.nodes, m))
    sizes[:, 0] = mean_step(request)
    sizes[:, 1:] = np.where(ranges > 0, ranges, data_scale(request))
    return sizes.ravel()


def straight(request: GridRequest[FixedNodes]) -> np.ndarray:
    """Positions interpolated linearly between the ends, on uniform times, packed."""
    data, n = request.data, request.system.n
    t = uniform(request)
    q = np.column_stack([np.interp(t, data.times, np.concatenate([data.q_start[:, i],
                                                                  data.q_stop[:, i]]))
                         for i in range(n)])
    return np.column_stack([t, q]).ravel()


def ends(request: GridRequest[FixedNodes], rule: str) -> HigherEnds:
    """The pinned values: the ``l`` end nodes, and for ``fixed`` every node time."""
    data, l, m = request.data, order(request), request.system.n + 1  # noqa: E741
    given = np.zeros((request.nodes, m))
    given[:l, 0], given[:l, 1:] = data.t_start, data.q_start
    given[-l:, 0], given[-l:, 1:] = data.t_stop, data.q_stop
    if rule == "fixed":
        given[:, 0] = uniform(request)
    return HigherEnds(given.ravel(), request.theta)


def magnitudes(request: GridRequest[FixedNodes]) -> np.ndarray:
    """Each value's magnitude for the round-off estimate (module docstring)."""
    m = request.system.n + 1
    values = np.full((request.nodes, m), data_scale(request))
    values[:, 0] = float(np.max(np.abs(request.data.times)))
    return values.ravel()
