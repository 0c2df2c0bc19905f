"""Derivatives of a verified grid solution by the implicit-function theorem (issue 47): what the
fixed-end and periodic families' ``derivatives=`` share.

A grid solution ``x`` solves ``F(x, v) = 0``, ``v`` the problem's inputs (ends, energy,
parameters). Where ``F_x`` is regular, ``x(v)`` is smooth and

    ``F_x dx/dv = -F_v``

gives its derivative: one more factorisation of the Jacobian the grid's Newton factors at every
iteration, at the solution, then one solve per input column (forward; `Linearisation.forward`),
or one transposed solve per output (reverse; `Linearisation.adjoint`). Every node time is a
component of ``x``, so the derivative includes the steps' own (``d tau_k / dv``): nothing is
frozen.

Honesty: each input's derivative is checked by a central finite difference of the discrete
solve itself along one random direction (`directional_check`: two Newton solves of the same
assembly from ``x``, a step of ``CHECK_STEP`` of the input's scale), and the verdict
(``"agrees"`` within ``AGREEMENT`` relative on the outputs a family reports, else
``"disagrees"``; ``"not checked"`` if a re-solve does not converge) is returned beside the
numbers, with an error estimate of the solves: the residual ``F_x dx + F_v`` of the computed
``dx`` solved once more with the same factors (one step of iterative refinement, not added). An
estimate above ``ILL_CONDITIONED`` marks the derivative ill-conditioned (fewer than about six
digits of it can be trusted).

Not a condition number: the 1-norm condition of the fixed-end band grows like ``N^4`` (its time
rows; 2e7 at 101 nodes, 2e11 at 1001 on the pendulum, measured), a bound that says nothing of
the end momenta, whose estimate stays at 1e-13 on 1e5 nodes; the estimate of all the nodes'
derivatives (node times included) is reported beside, 1e-4 there.
"""

from __future__ import annotations

import time

import numpy as np

from ... import validation
from ...errors import InputError
from .linear import Factorization
from .newton import FullSteps, newton
from .problem import GridProblem

EPS = float(np.finfo(float).eps)
# The directional check's step, relative to the input's scale: central differences lose
# about h^2 to truncation and eps/h to round-off, balanced near eps^(1/3) ~ 6e-6.
CHECK_STEP = 1e-5
# The check agrees when the finite difference and the derivative differ by at most this,
# relative to the derivative's largest entry.
AGREEMENT = 1e-6
# An error estimate above this: the derivative is flagged ill-conditioned.
ILL_CONDITIONED = 1e-6
SEED = 47


class DerivativesRefused(KeyError):
    """Derivatives asked of a solve that did not find a verified solution."""

    def __str__(self) -> str:
        return str(self.args[0])


class Refused(dict):
    """``Solution.derivatives`` of a failed solve: empty; any key raises `DerivativesRefused`
    with the reason (the solve's status), so that no number is read from it."""

    def __init__(self, reason: str):
        super().__init__()
        self.reason = reason

    def __missing__(self, key):
        raise DerivativesRefused(f"no derivatives ({key!r} asked): {self.reason}")


def check_names(derivatives, allowed: tuple, what: str) -> tuple[str, ...]:
    """``derivatives`` of the function ``what`` read by `validation.check_names`."""
    return validation.check_names(derivatives, allowed, f"derivatives of {what}")


class Linearisation:
    """``F_x`` at a solution, factored once: forward and adjoint solves."""

    def __init__(self, problem: GridProblem, x: np.ndarray, data, linear: str = "auto",
                 kernel=None):
        _, jacobian = problem.evaluate(x, data, jacobian=True)
        self.matrix = problem.sparse(jacobian).tocsr()
        self.size = self.matrix.shape[0]
        self.factors = Factorization(problem, jacobian, linear, kernel)
        self.singular = self.factors.singular

    def forward(self, columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(dx, correction)``: ``dx = -F_x^-1 F_v``, ``columns`` ``(size, k)`` the ``F_v`` of
        ``k`` inputs, and the solve of its residual ``F_x dx + F_v`` with the same factors. The
        correction's size beside ``dx``'s (`relative`, on the outputs a family reports)
        estimates the solve's error; it is not added: where it is large it is as uncertain as
        ``dx``."""
        columns = np.asarray(columns, float).reshape(self.size, -1)
        dx, correction = np.empty_like(columns), np.empty_like(columns)
        for j in range(columns.shape[1]):
            dx[:, j] = -self.factors.solve(np.array(columns[:, j], order="F"))
            correction[:, j] = -self.factors.solve(
                np.asarray(self.matrix @ dx[:, j] + columns[:, j], order="F"))
        return dx, correction

    def adjoint(self, cotangent: np.ndarray) -> np.ndarray:
        """``F_x^-T g``: with it ``g . dx/dv = -(F_x^-T g) . F_v`` for every input at once."""
        return self.factors.solve_transposed(np.array(cotangent, float, order="F"))

    def conditioning(self, outputs: float, nodes: float) -> dict:
        """The estimated relative errors of the reported outputs' and of all nodes'
        derivatives (``outputs``, ``nodes``: `relative` of the forward solves' corrections),
        ``ill_conditioned``: singular, or the outputs' estimate above ``ILL_CONDITIONED``,
        and ``nodes_ill_conditioned``: the same of the nodes' estimate (the fixed-end grid's
        node times on 1e5 nodes, a Kepler orbit's nodes along the eccentricity family the
        scheme barely breaks: outputs that do not see that direction keep their digits)."""
        return {"error_estimate": outputs,
                "nodes_error_estimate": nodes,
                "ill_conditioned": bool(self.singular or not np.isfinite(outputs)
                                        or outputs > ILL_CONDITIONED),
                "nodes_ill_conditioned": bool(self.singular or not np.isfinite(nodes)
                                              or nodes > ILL_CONDITIONED)}


def relative(change: np.ndarray, value: np.ndarray) -> float:
    """``max |change| / max |value|`` (``max |change|`` where ``value`` vanishes)."""
    size = float(np.max(np.abs(value), initial=0.0))
    error = float(np.max(np.abs(change), initial=0.0))
    return error / size if size > 0 else error


def step_scales(values: np.ndarray, fallback: float) -> np.ndarray:
    """Per-entry scales of an input for its check's step: ``|v_i|`` (a parameter's value, or
    the size of the motion in an end's coordinate); a zero entry takes the largest of the same
    input, or ``fallback`` if all are zero."""
    values = np.abs(np.atleast_1d(np.asarray(values, float)))
    largest = float(np.max(values, initial=0.0))
    return np.where(values > 0, values, largest if largest > 0 else fallback)


def directional_check(resolve, dx: np.ndarray, scales: np.ndarray, rng, project,
                      values=None) -> dict:
    """Central finite difference of the discrete solve along a random direction ``d`` of one
    input (``dx`` ``(size, k)`` its derivative, ``scales`` ``(k,)`` its step scales):
    ``resolve(delta)`` is the solution at the input moved by ``delta`` (``None``: not solved),
    ``project(x)`` the outputs a family reports of a solution-shaped vector; ``values``: the
    input's own. The derivative predicts the change for the moves the re-solves were given
    as floating point made them, ``(v + delta) - v``: an origin offset by ``1e6`` rounds a
    move of ``5e-6`` of a pendulum's end by ``4e-5`` of itself, and a check blind to that said
    "disagrees" of a derivative right to ``1e-15`` (with it they agree to ``3e-12``).
    Returns the outputs' relative error and its verdict, all nodes' relative error, the step
    and the check's CPU seconds."""
    began = time.process_time()
    direction = rng.standard_normal(dx.shape[1])
    direction /= np.linalg.norm(direction)
    delta = CHECK_STEP * scales * direction
    plus, minus = resolve(delta), resolve(-delta)
    record = {"step": float(CHECK_STEP * np.max(scales)), "direction": direction.tolist()}
    if plus is None or minus is None:
        record.update(relative_error=None, nodes_relative_error=None, verdict="not checked",
                      reason="a perturbed solve did not converge")
    else:
        # the moves the re-solves were given, as rounded (docstring)
        base = np.zeros(dx.shape[1]) if values is None else np.asarray(values, float)
        moved = ((base + delta) - base - ((base - delta) - base)) / 2.0
        predicted = dx @ moved
        differenced = (plus - minus) / 2.0
        error = relative(project(differenced) - project(predicted), project(predicted))
        record.update(relative_error=error,
                      nodes_relative_error=relative(differenced - predicted, predicted),
                      verdict="agrees" if error <= AGREEMENT else "disagrees")
    record["cpu_s"] = time.process_time() - began
    return record


def checked(linear: Linearisation, dx: dict, corrections: dict, resolve_of, scales: dict,
            project, values: dict | None = None) -> dict:
    """Each input's `directional_check` (inputs in ``dx``'s order, one seeded generator,
    ``scales[name]`` its per-entry step scales, ``values[name]`` its values,
    ``resolve_of(name)`` its `resolver`) and the forward solves'
    `Linearisation.conditioning`: ``{"checks": {name: record}, "error_estimate",
    ...}`` for a family's result (``project``: the outputs it reports).

    A family gives each input the size of a change the solution notices, in the input's own
    units (`step_scales` of the motion's size in each coordinate for an end, of the energy the
    motion trades for an energy): never ``|v|`` for an end or an energy, which an offset of
    the origin or a constant added to ``H`` makes as large as it likes (a transfer's ends at
    ``q = 1e4`` were moved by 0.1, a tenth of the motion, and its check said "disagrees")."""
    rng = new_rng()
    checks = {name: directional_check(resolve_of(name), dx[name], scales[name], rng, project,
                                      None if values is None else values[name])
              for name in dx}
    return {"checks": checks, **linear.conditioning(
        max(relative(project(corrections[k]), project(dx[k])) for k in dx),
        max(relative(corrections[k], dx[k]) for k in dx))}


def resolver(problem: GridProblem, x: np.ndarray, data_at, target: np.ndarray, *,
             tau_floor: float, linear: str = "auto", kernel=None):
    """``resolve(delta)`` for `directional_check`: the grid's Newton on ``problem`` from ``x``
    with the data ``data_at(delta)``, to the family's own per-row ``target`` (whole steps,
    then the line search if they fail); ``None`` if it does not converge."""

    def resolve(delta):
        data = data_at(delta)
        # whole Newton steps first: a step from the solution lands within O(delta^2), where
        # the line search's simplified correction, carried through an ill-conditioned F_x
        # (the fixed-end band's node times), can refuse every step (measured on the pendulum)
        result = newton(problem, x.copy(), data, target, tau_floor=tau_floor, max_iter=8,
                        linear=linear, kernel=kernel, test=FullSteps())
        if not result.converged:
            result = newton(problem, x.copy(), data, target, tau_floor=tau_floor,
                            max_iter=20, linear=linear, kernel=kernel)
        if not result.converged or not np.all(np.isfinite(result.x)):
            return None
        return result.x
    return resolve


def new_rng():
    """The checks' random directions: seeded, so that a run repeats."""
    return np.random.default_rng(SEED)


class GridGradient(dict):
    """A grid solution's reverse-mode gradient by input name, with ``error_estimate`` (the
    transposed solve's residual solved once more, relative to the adjoint: `reverse`) and
    ``ill_conditioned`` (singular ``F_x``, or the estimate above ``ILL_CONDITIONED``)."""

    def __init__(self, values, *, error_estimate: float, ill_conditioned: bool):
        super().__init__(values)
        self.error_estimate, self.ill_conditioned = error_estimate, ill_conditioned


def check_grid_cotangent(cotangent, shapes: dict, what: str) -> dict:
    """``cotangent`` (a mapping from some names of ``shapes`` to arrays of those shapes, finite)
    as float arrays by name; an ``InputError`` names a wrong key, shape or entry (``what``:
    the solve, for the message)."""
    if not hasattr(cotangent, "items"):
        raise InputError(f"cotangent of {what} must be a mapping from names in "
                         f"{', '.join(shapes)} to arrays, got {cotangent!r:.80}")
    if not cotangent:
        raise InputError(f"cotangent of {what} is empty: give one of {', '.join(shapes)}")
    found = {}
    for name, value in cotangent.items():
        if name not in shapes:
            raise InputError(f"cotangent of {what}: unknown name {name!r} (choose from "
                             f"{', '.join(shapes)})")
        try:
            array = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"cotangent[{name!r}] must be real numbers of shape "
                             f"{shapes[name]}, got {value!r:.80}") from None
        if array.shape != shapes[name]:
            raise InputError(f"cotangent[{name!r}] must have shape {shapes[name]}, got "
                             f"{array.shape}")
        bad = np.argwhere(~np.isfinite(np.atleast_1d(array)))
        if bad.size:
            raise InputError(f"cotangent[{name!r}] must be finite, got "
                             f"{float(np.atleast_1d(array)[tuple(bad[0])])!r} at "
                             f"{list(map(int, bad[0]))}")
        found[name] = array
    return found


def reverse(linear: Linearisation, c: np.ndarray, columns: dict) -> GridGradient:
    """``dL/dv = -(F_x^-T c) . F_v`` for each input's ``F_v`` in ``columns`` (name -> (size,
    k)), ``L = c . x``: one transposed solve on ``linear``'s factors, and one more of its
    residual for the error estimate."""
    lam = linear.adjoint(c)
    correction = linear.adjoint(c - linear.matrix.T @ lam)
    values = {}
    for name, F_v in columns.items():
        values[name] = -(np.asarray(F_v, float).T @ lam)
    estimate = relative(correction, lam)
    return GridGradient(values, error_estimate=estimate,
                        ill_conditioned=bool(linear.singular or not np.isfinite(estimate)
                                             or estimate > ILL_CONDITIONED))
