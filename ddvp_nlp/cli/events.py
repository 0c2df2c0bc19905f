"""``ddvp march --t-eval`` and ``--event``: output times and event functions typed on the
command line.

An event is ``EXPR[;up|down|both][;terminal[=N]]``: ``EXPR`` an arithmetic expression in
``t``, ``q1..qn``, ``p1..pn``, the scene's parameters and ``pi``, with ``+ - * / **``,
parentheses, numbers and the functions of `FUNCTIONS`, each called with its number of
positional arguments (``sin(q1)``, ``arctan2(q2, q1)``; ``sin()``, ``sin(q1, q1)``, a keyword or
a ``*`` argument is refused: numpy would take the extra one as its output array); the event is
where it is zero
(``up``: crossed from negative to non-negative, ``down``: the reverse, ``both`` the default);
``terminal`` ends the march at the first crossing (``terminal=N``: at the N-th). The text is
parsed by Python's ``ast`` and evaluated by walking that tree over numpy arrays: only the node
kinds and names above are accepted, so an expression can compute, never run code (no
attribute, subscript, call of anything but the listed functions, comprehension or lambda),
and nested no deeper than `MAX_DEPTH`. Every refusal is an `InputError` naming the
expression, raised when it is parsed (before anything is solved).
"""

from __future__ import annotations

import ast
import math
import operator

import numpy as np

from ..errors import InputError

# Each function an expression may call, with the number of positional arguments it takes: a
# numpy ufunc takes one more (its output array), which had made 'sin(q1, q1)' write into q1.
ARITY = {**dict.fromkeys(("sin", "cos", "tan", "arcsin", "arccos", "arctan", "sinh", "cosh",
                          "tanh", "exp", "log", "log10", "sqrt", "abs", "sign"), 1),
         **dict.fromkeys(("arctan2", "hypot", "minimum", "maximum"), 2)}
FUNCTIONS = {name: getattr(np, name) for name in ARITY}
OPERATORS = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
             ast.Div: operator.truediv, ast.Pow: operator.pow, ast.USub: operator.neg,
             ast.UAdd: operator.pos}
DIRECTIONS = {"up": 1, "+": 1, "down": -1, "-": -1, "both": 0}
# Longest expression read: an event is a line, not a program.
MAX_EXPRESSION = 1000
# Deepest nesting of operations read (a chain of 999 signs had overflowed the checker's
# recursion).
MAX_DEPTH = 200


class Expression:
    """A checked expression ``g(t, q, p)`` over arrays (``vectorized``: ``t`` ``(M,)``, ``q``
    and ``p`` ``(M, n)``), with the event attributes ``direction`` and ``terminal``."""

    vectorized = True

    def __init__(self, text: str, n: int, params: dict, *, direction: int = 0,
                 terminal: int = 0):
        self.text, self.n, self.params = text, n, dict(params)
        self.direction, self.terminal = direction, terminal
        if len(text) > MAX_EXPRESSION:
            raise InputError(f"--event: the expression is longer than {MAX_EXPRESSION} "
                             "characters")
        try:
            self.tree = ast.parse(text.strip(), mode="eval").body
        except SyntaxError as exc:
            raise InputError(f"--event {text!r}: not an expression ({exc.msg})") from None
        self._check(self.tree, 0)

    def names(self) -> set[str]:
        return {"t", "pi", *self.params, *(f"{s}{i}" for s in "qp" for i in
                                           range(1, self.n + 1))}

    def _check(self, node, depth: int) -> None:
        """Every node an allowed kind, every name known, every call of a listed function with
        its number of positional arguments, no deeper than `MAX_DEPTH`: an `InputError`
        names the first that is not."""
        if depth > MAX_DEPTH:
            raise InputError(f"--event {self.text!r}: nested deeper than {MAX_DEPTH} "
                             "operations")
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) \
                and not isinstance(node.value, bool):
            try:
                float(node.value)
            except OverflowError:  # an integer literal beyond any float
                raise InputError(f"--event {self.text!r}: a number of {len(str(node.value))} "
                                 "digits is beyond the floating-point range") from None
            return
        if isinstance(node, ast.Name):
            if node.id not in self.names():
                raise InputError(f"--event {self.text!r}: unknown name {node.id!r} (known: t, "
                                 f"q1..q{self.n}, p1..p{self.n}, pi"
                                 + "".join(f", {k}" for k in self.params) + ")")
            return
        if isinstance(node, ast.BinOp) and type(node.op) in OPERATORS:
            self._check(node.left, depth + 1)
            self._check(node.right, depth + 1)
            return
        if isinstance(node, ast.UnaryOp) and type(node.op) in OPERATORS:
            self._check(node.operand, depth + 1)
            return
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                and node.func.id in FUNCTIONS:
            self._check_call(node)
            for argument in node.args:
                self._check(argument, depth + 1)
            return
        raise InputError(f"--event {self.text!r}: {ast.unparse(node)!r} is not allowed (an "
                         f"expression of numbers, names, + - * / **, parentheses and "
                         f"{', '.join(FUNCTIONS)})")

    def _check_call(self, node: ast.Call) -> None:
        """A call of a listed function: its number of arguments, all positional."""
        name, wanted = node.func.id, ARITY[node.func.id]
        if node.keywords or any(isinstance(a, ast.Starred) for a in node.args):
            raise InputError(f"--event {self.text!r}: {ast.unparse(node)!r} is not allowed: "
                             f"{name} takes {_arguments(wanted)}, positional only (no keyword "
                             "or * argument)")
        if len(node.args) != wanted:
            raise InputError(f"--event {self.text!r}: {ast.unparse(node)!r}: {name} takes "
                             f"{_arguments(wanted)}, got {len(node.args)}")

    def __call__(self, t, q, p):
        t = np.asarray(t, dtype=float)
        q, p = np.atleast_2d(q), np.atleast_2d(p)
        # numpy scalars: a power past the range is inf, not Python's OverflowError
        values = {"t": t, "pi": np.float64(math.pi),
                  **{k: np.float64(v) for k, v in self.params.items()}}
        for i in range(self.n):
            values[f"q{i + 1}"], values[f"p{i + 1}"] = q[:, i], p[:, i]
        with np.errstate(all="ignore"):
            result = self._value(self.tree, values)
        return np.broadcast_to(np.asarray(result, dtype=float), t.shape)

    def _value(self, node, values):
        if isinstance(node, ast.Constant):
            return np.float64(node.value)
        if isinstance(node, ast.Name):
            return values[node.id]
        if isinstance(node, ast.BinOp):
            return OPERATORS[type(node.op)](self._value(node.left, values),
                                            self._value(node.right, values))
        if isinstance(node, ast.UnaryOp):
            return OPERATORS[type(node.op)](self._value(node.operand, values))
        return FUNCTIONS[node.func.id](*(self._value(a, values) for a in node.args))

    def describe(self) -> dict:
        """The event as ``meta.json`` records it."""
        return {"expression": self.text, "direction": {1: "up", -1: "down", 0: "both"}[
            self.direction], "terminal": self.terminal}


def _arguments(count: int) -> str:
    return "1 argument" if count == 1 else f"{count} arguments"


def parse_event(text: str, n: int, params: dict) -> Expression:
    """``EXPR[;up|down|both][;terminal[=N]]`` (module docstring)."""
    if not isinstance(text, str) or not text.strip():
        raise InputError(f"--event must be EXPR[;up|down|both][;terminal[=N]], got {text!r}")
    expression, *modifiers = [part.strip() for part in text.split(";")]
    direction, terminal = 0, 0
    for modifier in modifiers:
        name, sep, value = modifier.partition("=")
        if modifier in DIRECTIONS:
            direction = DIRECTIONS[modifier]
        elif name.strip() == "terminal":
            terminal = _count(text, value) if sep else 1
        else:
            raise InputError(f"--event {text!r}: {modifier!r} is neither up, down, both nor "
                             "terminal[=N]")
    return Expression(expression, n, params, direction=direction, terminal=terminal)


def _count(text: str, value: str) -> int:
    try:
        count = int(value)
    except ValueError:
        count = 0
    if count < 1:
        raise InputError(f"--event {text!r}: terminal=N needs a count N >= 1, got {value!r}")
    return count


def parse_times(text: str, t_span) -> np.ndarray:
    """``--t-eval``: ``T1,T2,...`` or ``START:STOP:COUNT`` (``COUNT`` evenly spaced times, both
    ends included), checked by the library's one check of output times (finite, sorted, inside
    ``t_span``; `validation.check_times`) under the option's name."""
    from ..validation import check_integer, check_memory, check_times

    parts = text.split(":")
    try:
        if len(parts) == 3:
            count = check_integer("--t-eval COUNT", int(parts[2]), minimum=1)
            check_memory("--t-eval COUNT", count, count * 8.0 * 8, "the output times")
            times = np.linspace(float(parts[0]), float(parts[1]), count)
        elif len(parts) == 1:
            times = np.array([float(v) for v in text.split(",")])
        else:
            raise ValueError
    except ValueError:
        raise InputError(f"--t-eval must be T1,T2,... or START:STOP:COUNT, got {text!r}") \
            from None
    return check_times(times, t_span, name=f"--t-eval {text!r}")
