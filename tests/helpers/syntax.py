"""Syntax trees of the package's, the tests' and the scripts' files, parsed once per test run:
the rules of tests/architecture/ read the same 400-odd files in several tests (parsing them
was most of those tests' cost). Callers only read the trees; tests/architecture/conftest.py
drops them when that folder's tests are done."""

from __future__ import annotations

import ast
import functools
from pathlib import Path


@functools.cache
def parsed(path: Path) -> ast.Module:
    """``path``'s syntax tree."""
    return ast.parse(path.read_text(), filename=str(path))


@functools.cache
def walk(tree: ast.AST) -> tuple[ast.AST, ...]:
    """Every node of ``tree`` in ``ast.walk``'s order, listed once (a tree is hashed by
    identity, and `parsed` keeps it alive)."""
    return tuple(ast.walk(tree))
