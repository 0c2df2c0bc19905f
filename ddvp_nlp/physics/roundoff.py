"""How large the round-off of evaluating a scalar function can be, read off its expression.

A residual that differences values of ``H`` cannot be driven below the round-off of ``H``'s own
evaluation, and that round-off is set by the magnitudes the value is computed from, not by the
value: the pendulum's ``1 - cos q`` at ``q = 1e-3`` is ``5e-7``, computed from terms of size 1,
so it is known to about ``eps``, not to ``eps`` times ``5e-7``; a Kepler orbit in lengths of
``1e-10`` is computed from terms of the size of its energy, however small that is in the units
chosen. A test of the energy residual against the motion's energy alone refuses the first; one
against a floor of 1 passes the second whatever its error.

`roundoff_bound` gives the first-order running error bound of the evaluation (the standard
running error analysis, as in Higham, *Accuracy and Stability of Numerical Algorithms*,
ch. 3): walking CasADi's instruction list once at a point, each intermediate result
``v = op(a, b)`` carries

    ``e(v) = |v| + |dv/da| e(a) + |dv/db| e(b)``,

the rounding of ``v`` itself plus its operands' bounds carried through; the actual round-off is
at most about ``eps * e`` of the output. The node state and time are unknowns stored at
``eps`` of their size, so an input ``x`` starts with ``e = |x|``; the parameters and the
constants of the expression start with 0: they are the same in every evaluation, so they move
no residual. An operand whose bound is 0 adds nothing, so a derivative that is infinite at the
point (``sqrt`` at 0) does not make the bound NaN. The bound is in the units of the value and
scales with it under any change of units, and it grows where a constant is added to ``H`` or a
coordinate is offset, as the round-off does.

The walk is numeric, in Python, at the one point asked (the start of a march): about a
microsecond per instruction, with no function to build.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import casadi as ca
import numpy as np


def _safe(function) -> float:
    """``|function()|``, infinite where it has no finite value."""
    try:
        return abs(function())
    except (ValueError, ZeroDivisionError, OverflowError):
        return math.inf



# Operations whose derivative is 0 where they are defined (comparisons, logic, rounding)
_FLAT = {ca.OP_LT, ca.OP_LE, ca.OP_EQ, ca.OP_NE, ca.OP_NOT, ca.OP_AND, ca.OP_OR, ca.OP_FLOOR,
         ca.OP_CEIL, ca.OP_SIGN}


class _Generic:
    """``(a, b) -> (v, |dv/da|, |dv/db|)`` for any other CasADi operation, by a function built
    once per operation."""

    def __init__(self):
        self._functions: dict[tuple[int, int], ca.Function] = {}

    def __call__(self, op: int, arity: int, a: float, b: float) -> tuple[float, float, float]:
        key = (op, arity)
        if key not in self._functions:
            x, y = ca.SX.sym("a"), ca.SX.sym("b")
            value = ca.SX.binary(op, x, y) if arity == 2 else ca.SX.unary(op, x)
            self._functions[key] = ca.Function(f"op_{op}", [x, y], [
                value, ca.fabs(ca.jacobian(value, x)), ca.fabs(ca.jacobian(value, y))])
        return tuple(float(v) for v in self._functions[key](a, b))


_GENERIC = _Generic()


class RoundoffBound:
    """The running error bound of one scalar SX function (module docstring), called with the
    function's inputs at a point: ``bound(*inputs) -> float``."""

    def __init__(self, function: ca.Function, unknowns: tuple[int, ...]):
        if not function.is_a("SXFunction") or function.n_out() != 1 or \
                function.nnz_out(0) != 1:
            raise ValueError(f"{function.name()}: not an SX function with one scalar output")
        self.function = function
        self.unknowns = frozenset(unknowns)
        self.program = [(function.instruction_id(k), tuple(function.instruction_input(k)),
                         tuple(function.instruction_output(k)),
                         function.instruction_constant(k)
                         if function.instruction_id(k) == ca.OP_CONST else 0.0)
                        for k in range(function.n_instructions())]
        unsupported = {op for op, args, results, _ in self.program
                       if op not in (ca.OP_INPUT, ca.OP_OUTPUT, ca.OP_CONST)
                       and not (len(args) in (1, 2) and len(results) == 1)}
        if unsupported:
            raise ValueError(f"{function.name()}: operations {sorted(unsupported)} have no "
                             "scalar rule")

    def __call__(self, *inputs) -> float:
        values = [np.asarray(x, float).ravel() for x in inputs]
        work: dict[int, tuple[float, float]] = {}
        bound = 0.0  # an output that is a structural zero is never written
        for op, args, results, constant in self.program:
            if op == ca.OP_INPUT:
                x = float(values[args[0]][args[1]])
                work[results[0]] = (x, abs(x) if args[0] in self.unknowns else 0.0)
            elif op == ca.OP_CONST:
                work[results[0]] = (float(constant), 0.0)
            elif op == ca.OP_OUTPUT:
                bound = work[args[0]][1]
            else:
                a, e_a = work[args[0]]
                b, e_b = work[args[1]] if len(args) == 2 else (0.0, 0.0)
                work[results[0]] = _step(op, len(args), a, b, e_a, e_b)
        return bound


def _step(op: int, arity: int, a: float, b: float, e_a: float,
          e_b: float) -> tuple[float, float]:
    """``(v, e(v))`` of one operation."""
    rule = _RULES.get(op)
    if rule is None:
        value, d_a, d_b = _GENERIC(op, arity, a, b)
    else:
        value = rule[0](a, b)
        d_a, d_b = rule[1](a, b, value)
    if op in _FLAT:
        return value, abs(value)
    bound = abs(value)
    if e_a:
        bound += d_a * e_a
    if e_b:
        bound += d_b * e_b
    return value, bound


def _with_errors(function: Callable) -> Callable:
    """``function`` with IEEE's answers where Python raises (``inf`` for a quotient by 0,
    ``nan`` outside a domain)."""
    def value(a, b):
        try:
            return function(a, b)
        except ZeroDivisionError:
            return math.copysign(math.inf, a) * math.copysign(1.0, b) if a else math.nan
        except (ValueError, OverflowError):
            return math.nan
    return value


# Each common operation: its value in double precision (IEEE's answers where Python raises,
# `_with_errors`) and its partials ``(a, b, v) -> (|dv/da|, |dv/db|)``
_RULES: dict[int, tuple[Callable, Callable]] = {
    ca.OP_ASSIGN: (_with_errors(lambda a, b: a),
        lambda a, b, v: (1.0, 0.0)),
    ca.OP_ADD: (_with_errors(lambda a, b: a + b),
        lambda a, b, v: (1.0, 1.0)),
    ca.OP_SUB: (_with_errors(lambda a, b: a - b),
        lambda a, b, v: (1.0, 1.0)),
    ca.OP_MUL: (_with_errors(lambda a, b: a * b),
        lambda a, b, v: (abs(b), abs(a))),
    ca.OP_DIV: (_with_errors(lambda a, b: a / b),
        lambda a, b, v: (_safe(lambda: 1.0 / b), _safe(lambda: a / (b * b)))),
    ca.OP_NEG: (_with_errors(lambda a, b: -a),
        lambda a, b, v: (1.0, 0.0)),
    ca.OP_SQ: (_with_errors(lambda a, b: a * a),
        lambda a, b, v: (2.0 * abs(a), 0.0)),
    ca.OP_TWICE: (_with_errors(lambda a, b: 2.0 * a),
        lambda a, b, v: (2.0, 0.0)),
    ca.OP_INV: (_with_errors(lambda a, b: 1.0 / a),
        lambda a, b, v: (_safe(lambda: 1.0 / (a * a)), 0.0)),
    ca.OP_SQRT: (_with_errors(lambda a, b: math.sqrt(a)),
        lambda a, b, v: (_safe(lambda: 0.5 / v), 0.0)),
    ca.OP_SIN: (_with_errors(lambda a, b: math.sin(a)),
        lambda a, b, v: (abs(math.cos(a)), 0.0)),
    ca.OP_COS: (_with_errors(lambda a, b: math.cos(a)),
        lambda a, b, v: (abs(math.sin(a)), 0.0)),
    ca.OP_TAN: (_with_errors(lambda a, b: math.tan(a)),
        lambda a, b, v: (1.0 + v * v, 0.0)),
    ca.OP_EXP: (_with_errors(lambda a, b: math.exp(a)),
        lambda a, b, v: (abs(v), 0.0)),
    ca.OP_LOG: (_with_errors(lambda a, b: math.log(a)),
        lambda a, b, v: (_safe(lambda: 1.0 / a), 0.0)),
    ca.OP_FABS: (_with_errors(lambda a, b: abs(a)),
        lambda a, b, v: (1.0, 0.0)),
    ca.OP_ATAN: (_with_errors(lambda a, b: math.atan(a)),
        lambda a, b, v: (1.0 / (1.0 + a * a), 0.0)),
    ca.OP_SINH: (_with_errors(lambda a, b: math.sinh(a)),
        lambda a, b, v: (abs(math.cosh(a)) if abs(a) < 700 else math.inf, 0.0)),
    ca.OP_COSH: (_with_errors(lambda a, b: math.cosh(a)),
        lambda a, b, v: (abs(math.sinh(a)) if abs(a) < 700 else math.inf, 0.0)),
    ca.OP_TANH: (_with_errors(lambda a, b: math.tanh(a)),
        lambda a, b, v: (1.0 - v * v, 0.0)),
    ca.OP_POW: (_with_errors(lambda a, b: math.pow(a, b)),
        lambda a, b, v: (_safe(lambda: b * math.pow(a, b - 1)),
                         _safe(lambda: v * math.log(a)) if a > 0 else 0.0)),
    ca.OP_CONSTPOW: (_with_errors(lambda a, b: math.pow(a, b)),
        lambda a, b, v: (_safe(lambda: b * math.pow(a, b - 1)), 0.0)),
}



def roundoff_bound(function: ca.Function, unknowns: tuple[int, ...]) -> RoundoffBound:
    """The running error bound of ``function`` (an SX function with one scalar output) as a
    callable of its inputs (module docstring). ``unknowns`` are the indices of the inputs that
    start with ``e = |x|`` (the state and time); the others start with 0.

    Raises ``ValueError`` for a function that is not such a function or that uses an operation
    without a scalar rule (a call of another function)."""
    return RoundoffBound(function, unknowns)
