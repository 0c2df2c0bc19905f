"""Holonomic constraints ``g(q, t; params) = 0`` of a system, declared and checked.

The user writes ``g`` beside ``H`` (or ``L``) as a plain function on the same CasADi symbols::

    def circle(q, t):
        return q[0]**2 + q[1]**2 - 1

``g`` returns a column of ``m`` expressions (a scalar counts as one). The system keeps it as
``system.G`` (the SX column in the system's own symbols ``q, t, theta``), ``system.constraints``
(the user's function, or ``None``) and ``system.n_constraints`` (``m``, 0 without constraints).
Everything that does not need a state is checked here, when the system is made
(`constraint_column`); what needs one (a Jacobian of full rank, finite values) is checked at
the start of a solve (`check_start_constraints`). Each failure is an ``InputError`` that names
the constraint.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..cache import cached
from ..errors import InputError

# the relative size below which the constraint Jacobian's smallest singular value counts as zero
RANK_TOLERANCE = 1e-10


def constraint_column(system, function, guard, as_sx) -> ca.SX:
    """``g(q, t, **params)`` on the system's symbols as an SX column, checked: a CasADi (or
    numeric) vector of ``1 .. n-1`` rows, each depending on ``q``, on no symbol but ``q``,
    ``t`` and the parameters. ``guard(whose)``: the context the user's function runs in
    (``hamiltonian.numpy_on_symbols``); ``as_sx``: how its value is read as SX, as ``H``'s is
    (``hamiltonian.as_sx``; both passed in: ``hamiltonian.py`` imports this module)."""
    name = system.name
    if not callable(function):
        raise InputError(f"constraints of {name!r} must be a function g(q, t, ...), got "
                         f"{function!r}")
    symbols = {key: system.theta[i] for i, key in enumerate(system.params)}
    try:
        with guard(f"constraints of {name!r}"):
            value = function(system.q, system.t, **symbols)
    except InputError:
        raise
    except Exception as exc:  # the user's function; say whose it was
        raise InputError(f"constraints of {name!r} failed on symbolic input: "
                         f"{type(exc).__name__}: {exc}") from exc
    column = _as_column(value, name, as_sx)
    m = column.size1()
    if m == 0:
        raise InputError(f"constraints of {name!r} returned an empty vector: give None for a "
                         "system without constraints")
    if m >= system.n:
        raise InputError(f"constraints of {name!r} has {m} rows for n = {system.n} "
                         "coordinates: at most n - 1 independent constraints leave a motion")
    given = ca.vertcat(system.q, system.t, system.theta)
    stray = [s.name() for s in ca.symvar(column) if not ca.depends_on(s, given)]
    if stray:
        raise InputError(f"constraints of {name!r} depend on symbols they were not given "
                         f"(g(q, t, ...) has no p): {', '.join(stray)}")
    for row in range(m):
        if not ca.depends_on(column[row], system.q):
            raise InputError(f"constraint row {row} of {name!r} does not depend on q "
                             f"(g[{row}] = {column[row]}): it constrains no coordinate")
    return column


def _as_column(value, name: str, as_sx) -> ca.SX:
    if isinstance(value, (list, tuple)):
        try:
            value = ca.vertcat(*[ca.SX(v) if isinstance(v, (int, float)) else v
                                 for v in value]) if value else ca.SX(0, 1)
        except Exception as exc:
            raise InputError(f"constraints of {name!r} returned a list that is not a vector of "
                             f"CasADi expressions: {exc}") from exc
    value = as_sx(value, name, "constraints", "a CasADi vector")
    if value.size2() != 1 and value.size1() == 1:
        value = value.T
    if value.size2() != 1:
        raise InputError(f"constraints of {name!r} must return a vector (m x 1), got shape "
                         f"{value.size1()}x{value.size2()}")
    return value


def constraint_function(system) -> ca.Function:
    """``(q, t, theta) -> (g, G = dg/dq, g_t = dg/dt)``, built once per system."""
    def build():
        G = system.G
        return ca.Function("constraints", [system.q, system.t, system.theta],
                           [G, ca.jacobian(G, system.q), ca.jacobian(G, system.t)],
                           ["q", "t", "theta"], ["g", "G", "g_t"])
    return cached(system, "constraints", build)


def check_start_constraints(system, q, t, theta, *, what: str = "q0") -> None:
    """At the state ``q`` (time ``t``): ``g`` and its Jacobian finite, the Jacobian of full
    rank ``m`` (a zero row: a singular constraint; dependent rows: redundant constraints)."""
    g, G, _ = (np.asarray(v, float) for v in constraint_function(system)(q, t, theta))
    G = G.reshape(system.n_constraints, system.n)
    if not (np.all(np.isfinite(g)) and np.all(np.isfinite(G))):
        raise InputError(f"constraints of {system.name!r} are not finite at {what} = "
                         f"{np.asarray(q).tolist()}: g = {g.ravel().tolist()}")
    scale = np.abs(G).max(initial=0.0)
    rows = np.linalg.norm(G, axis=1)
    for row, size in enumerate(rows):
        if size <= RANK_TOLERANCE * max(scale, np.finfo(float).tiny):
            raise InputError(f"constraint row {row} of {system.name!r} has a singular Jacobian "
                             f"at {what} = {np.asarray(q).tolist()} (dg[{row}]/dq = 0): "
                             "it does not determine a constraint force there")
    singular = np.linalg.svd(G, compute_uv=False)
    if singular[-1] <= RANK_TOLERANCE * singular[0]:
        raise InputError(
            f"constraints of {system.name!r} are redundant at {what} = "
            f"{np.asarray(q).tolist()}: their Jacobian has rank "
            f"{int(np.sum(singular > RANK_TOLERANCE * singular[0]))} < "
            f"{system.n_constraints} rows (a row is a combination of others); drop one")




def refuse_constrained(system, solver: str) -> None:
    """``InputError`` where ``solver`` has not learned constraints yet and ``system`` has some:
    an unconstrained solver never runs on a constrained system silently."""
    if getattr(system, "n_constraints", 0):
        raise InputError(f"{solver} does not support constrained systems yet "
                         f"({getattr(system, 'name', 'system')!r} has "
                         f"{system.n_constraints} constraints); march it with march(...)")


__all__ = ["check_start_constraints", "constraint_column", "constraint_function",
           "refuse_constrained"]
