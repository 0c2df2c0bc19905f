"""The reference of a constrained system's exact flow: the projected index-reduced flow of
``constrained.py`` as the pair of runs of ``reference.py``, from a start checked to lie on the
constraint manifold. (A module of its own: ``flow.py`` reads ``constrained.py`` for the field,
and ``reference.py`` reads ``flow.py``.)"""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from .constrained import check_consistent, check_constrained
from .reference import Reference, exact_reference


def constrained_reference(system, z0, t0: float, t_end: float, theta, *,
                          rtol: float = 1e-12, scale=None, compiler: str | None = "auto",
                          cache_dir=None) -> Reference:
    """The reference of a constrained system's exact flow from a consistent ``z0`` over
    ``[t0, t_end]``: the projected index-reduced flow as a pair of runs (``reference.py``),
    the finer at ``rtol / 10``, with its own error bound (`Reference.error`). Checks the
    inputs (named errors) and refuses a start off the manifold (`check_consistent`)."""
    check_constrained(system)
    z0 = np.asarray(z0, float)
    if z0.shape != (2 * system.n,) or not np.all(np.isfinite(z0)):
        raise InputError(f"z0 must be {2 * system.n} finite numbers, got {z0.tolist()}")
    for name, value in (("t0", t0), ("t_end", t_end)):
        if not np.isfinite(value):
            raise InputError(f"{name} must be finite, got {value!r}")
    if not (isinstance(rtol, (int, float)) and 1e-14 <= rtol < 1e-2):
        raise InputError(f"rtol must be in [1e-14, 1e-2), got {rtol!r}")
    theta = np.asarray(theta, float).reshape(system.theta.numel())
    if scale is not None:
        scale = np.broadcast_to(np.asarray(scale, float), z0.shape)
        if not np.all(scale > 0) or not np.all(np.isfinite(scale)):
            raise InputError(f"scale must be positive and finite, got {scale.tolist()}")
    size = np.full(z0.shape, np.max(np.abs(z0)) or 1.0) if scale is None else scale
    z0 = check_consistent(system, z0, float(t0), theta, size)
    return exact_reference(system, z0, float(t0), float(t_end), theta, rtol=rtol,
                           scale=scale, compiler=compiler, cache_dir=cache_dir)
