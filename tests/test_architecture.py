"""The package's structure, checked: no import cycle, each folder imports only the layers below
it, and no function or class grows past the size a reader can hold."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "ddvp_nlp"

# What each part may import (besides itself and the base modules): the layers of the README's
# architecture section, bottom to top.
BASE = {"errors", "validation", "cache", "solution"}
ALLOWED = {
    "base": {"base"},
    "physics": {"base"},
    "discrete": {"base", "physics"},
    "scenes": {"base", "physics"},
    "solvers": {"base", "physics", "discrete"},
    "studies": {"base", "physics", "discrete", "solvers", "scenes", "io"},
    "io": {"base", "physics", "discrete", "solvers", "scenes", "studies"},
    "cli": {"base", "physics", "discrete", "solvers", "scenes", "studies", "io"},
    "__init__": {"base", "physics", "discrete", "solvers", "scenes"},
}
# The one import across the layers: the root's public ``plot`` is a facade over io/plotting.py,
# imported inside the function, so `from ddvp_nlp import plot` works while `import ddvp_nlp`
# loads no figure code and no module below io/ can reach io/ (docs/architecture.md).
FACADES = {("__init__", "io.plotting")}
MAX_FUNCTION_LINES = 80
MAX_CLASS_LINES = 200


def modules() -> dict[str, Path]:
    found = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        found[name or "__init__"] = path
    return found


def imports(name: str, path: Path) -> set[str]:
    """The package modules ``name`` imports (at any depth of its code)."""
    package = name.split(".")[:-1] if not path.name == "__init__.py" else name.split(".")
    if name == "__init__":
        package = []
    known = modules()
    result = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = package[:len(package) - node.level + 1]
            target = ".".join(base + ([node.module] if node.module else []))
            for alias in node.names:
                full = f"{target}.{alias.name}" if target else alias.name
                result.add(full if full in known else target)
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("ddvp_nlp."):
            result.add(node.module[len("ddvp_nlp."):])
    return {m for m in result if m in known and m != name}


def graph() -> dict[str, set[str]]:
    return {name: imports(name, path) for name, path in modules().items()}


def part(module: str) -> str:
    head = module.split(".")[0]
    return "base" if head in BASE else head


def find_cycle(edges: dict[str, set[str]]):
    """One import cycle as a list of modules, or None (depth-first search)."""
    state, stack = {}, []

    def visit(node):
        state[node] = "open"
        stack.append(node)
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == "open":
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                cycle = visit(nxt)
                if cycle:
                    return cycle
        state[node] = "done"
        stack.pop()
        return None

    for node in sorted(edges):
        if node not in state:
            cycle = visit(node)
            if cycle:
                return cycle
    return None


def test_the_cycle_finder_finds_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_no_import_cycle():
    assert find_cycle(graph()) is None


def test_each_part_imports_only_the_layers_below_it():
    wrong = [f"{module} imports {target}" for module, targets in graph().items()
             for target in targets
             if part(target) != part(module) and part(target) not in ALLOWED[part(module)]
             and (module, target) not in FACADES]
    assert wrong == []


def test_the_facade_is_the_roots_only_import_of_io_and_it_is_lazy():
    """The exception above stays one edge, made inside a function: importing the package
    loads nothing of io/."""
    import subprocess
    import sys

    assert {t for t in graph()["__init__"] if part(t) == "io"} == {"io.plotting"}
    tree = ast.parse((PACKAGE / "__init__.py").read_text())
    top_level = [node.module for node in tree.body if isinstance(node, ast.ImportFrom)]
    assert not any((module or "").startswith("io") for module in top_level)
    loaded = subprocess.run([sys.executable, "-c", "import sys, ddvp_nlp; print(sorted(m for m "
                             "in sys.modules if m.startswith('ddvp_nlp.io')))"],
                            capture_output=True, text=True, check=True).stdout.strip()
    assert loaded == "[]"


def _docstring_lines(node) -> int:
    first = node.body[0] if node.body else None
    if isinstance(first, ast.Expr) and isinstance(getattr(first, "value", None), ast.Constant) \
            and isinstance(first.value.value, str):
        return first.end_lineno - first.lineno + 1
    return 0


def sizes():
    """``(kind, qualified name, lines)`` of every function and class in the package, counted
    from the ``def`` to the last line, without the docstring (a long Args list is welcome)."""
    for name, path in modules().items():
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                kind = "class" if isinstance(node, ast.ClassDef) else "function"
                lines = node.end_lineno - node.lineno + 1 - _docstring_lines(node)
                yield kind, f"{name}.{node.name}", lines


@pytest.mark.parametrize("kind, limit", [("function", MAX_FUNCTION_LINES),
                                         ("class", MAX_CLASS_LINES)])
def test_no_function_or_class_is_too_long(kind, limit):
    too_long = [(name, lines) for k, name, lines in sizes() if k == kind and lines > limit]
    assert too_long == []
