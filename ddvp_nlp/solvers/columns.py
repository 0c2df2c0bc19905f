"""Reductions of node tables (rows: nodes, columns: the 2..2n components of a state), column by
column.

numpy reduces a C-ordered ``(N, d)`` table along either axis with an inner loop of length ``d``
when ``d`` is small, and that is slow: on 22 213 rows of 4 columns ``values.min(axis=0)`` took
1.6 ms and ``np.max(values, axis=1)`` 2.1 ms, where the same numbers computed one column at a
time took 0.13 and 0.2 ms (measured on the 2-core machine; the march's own row maximum of the
paper's example went from 0.8 to 0.05 ms). The accuracy check makes a dozen such reductions
over every node, so these helpers are what keeps it at the cost of its compiled parts. Past
``WIDE`` columns numpy's own reduction is the faster and is used. Every function gives the
same numbers as the numpy expression it names (NaN propagates as there).
"""

from __future__ import annotations

import numpy as np

__all__ = ["column_argmax", "column_extremes", "column_span", "row_max", "row_max_abs",
           "row_max_ratio", "row_norm"]

WIDE = 16  # columns past which numpy's reduction along an axis is the faster


def row_max(values: np.ndarray) -> np.ndarray:
    """``np.max(values, axis=1)``."""
    if values.shape[1] > WIDE or values.shape[1] == 0:
        return np.max(values, axis=1)
    out = values[:, 0].copy()
    for j in range(1, values.shape[1]):
        np.maximum(out, values[:, j], out=out)
    return out


def row_max_abs(values: np.ndarray) -> np.ndarray:
    """``np.max(np.abs(values), axis=1)``."""
    if values.shape[1] > WIDE or values.shape[1] == 0:
        return np.max(np.abs(values), axis=1)
    out = np.abs(values[:, 0])
    for j in range(1, values.shape[1]):
        np.maximum(out, np.abs(values[:, j]), out=out)
    return out


def row_max_ratio(values: np.ndarray, scale) -> np.ndarray:
    """``np.max(values / scale, axis=1)`` with ``scale`` one value per column, or one per row
    and column (the shape of ``values``)."""
    scale = np.broadcast_to(np.asarray(scale, float), values.shape)
    if values.shape[1] > WIDE or values.shape[1] == 0:
        return np.max(values / scale, axis=1)
    out = values[:, 0] / scale[:, 0]
    for j in range(1, values.shape[1]):
        np.maximum(out, values[:, j] / scale[:, j], out=out)
    return out


def row_norm(values: np.ndarray) -> np.ndarray:
    """``np.sqrt(np.sum(values ** 2, axis=1))``."""
    if values.shape[1] > WIDE or values.shape[1] == 0:
        return np.sqrt(np.sum(values ** 2, axis=1))
    out = values[:, 0] ** 2
    for j in range(1, values.shape[1]):
        out += values[:, j] ** 2
    return np.sqrt(out)


def column_extremes(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(values.min(axis=0), values.max(axis=0), np.abs(values).max(axis=0))``."""
    if values.shape[1] > WIDE:
        return values.min(axis=0), values.max(axis=0), np.abs(values).max(axis=0)
    columns = [values[:, j] for j in range(values.shape[1])]
    low = np.array([c.min() for c in columns])
    high = np.array([c.max() for c in columns])
    return low, high, np.maximum(np.abs(low), np.abs(high))


def column_span(values: np.ndarray) -> np.ndarray:
    """``np.ptp(values, axis=0)``."""
    low, high, _ = column_extremes(values)
    return high - low


def column_argmax(values: np.ndarray) -> np.ndarray:
    """``np.argmax(values, axis=0)``."""
    if values.shape[1] > WIDE or values.shape[0] == 0:
        return np.argmax(values, axis=0)
    return np.array([np.argmax(values[:, j]) for j in range(values.shape[1])], dtype=np.intp)
