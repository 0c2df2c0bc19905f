"""Built CasADi functions, kept per system so that each is built once.

Building a CasADi function (symbolic derivatives, a rootfinder, generated and compiled C) costs
milliseconds to seconds; every march, check and study of the same system and scheme reuses it.
A cache entry is found by its owner (a system, held by weak reference, so entries go when the
system goes) and a key whose first element names the kind of function, for example
``("canonical", scheme)`` or ``("march", scheme)``; the rest says what it was built for.

Two caches, with two lifetimes:

- ``FUNCTIONS``: small per-interval and per-step functions, kept as long as their system;
- ``PROBLEMS``: whole grid problems, built assemblies and IPOPT builds (their size grows with
  the node count), at most ``PROBLEMS.limit`` per system, the least recently used dropped
  first.

A function evaluated over many nodes block by block is ``blocks.py``'s.
"""

from __future__ import annotations

import weakref
from collections import OrderedDict
from collections.abc import Callable, Hashable
from importlib import import_module
from typing import TypeVar

T = TypeVar("T")


class FunctionCache:
    """Objects built once per ``(owner, key)``; ``limit`` bounds the entries of one owner."""

    def __init__(self, limit: int | None = None):
        self.limit = limit
        self._entries: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

    def get(self, owner: object, key: Hashable, build: Callable[[], T]) -> T:
        """The entry of ``owner`` under ``key``, built by ``build()`` the first time."""
        entries = self._entries.setdefault(owner, OrderedDict())
        if key in entries:
            entries.move_to_end(key)
            return entries[key]
        value = build()
        entries[key] = value
        if self.limit is not None:
            while len(entries) > self.limit:
                entries.popitem(last=False)
        return value

    def keys(self, owner: object) -> list:
        """The keys held for ``owner``, oldest first."""
        return list(self._entries.get(owner, ()))

    def discard(self, owner: object, dropped: Callable[[Hashable], bool]) -> None:
        """Drop the entries of ``owner`` whose key ``dropped(key)`` is true."""
        entries = self._entries.get(owner)
        for key in [k for k in entries or () if dropped(k)]:
            del entries[key]

    def clear(self, owner: object | None = None) -> None:
        """Drop every entry (of ``owner`` only, if given)."""
        if owner is None:
            self._entries = weakref.WeakKeyDictionary()
        else:
            self._entries.pop(owner, None)


FUNCTIONS = FunctionCache()
PROBLEMS = FunctionCache(limit=2)


def cached(owner: object, key: Hashable, build: Callable[[], T]) -> T:
    """``FUNCTIONS.get(owner, key, build)``."""
    return FUNCTIONS.get(owner, key, build)


def lazy_exports(package: str, names: dict[str, str]):
    """``(__getattr__, __dir__)`` for a package whose public ``names`` (name -> submodule)
    are imported when first asked for (PEP 562), so that importing one of its modules, or the
    package, does not load the others and what they import."""
    def getattr_(name: str):
        if name not in names:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(import_module(f"{package}.{names[name]}"), name)
        vars(import_module(package))[name] = value  # found directly from now on
        return value

    def dir_():
        return sorted(set(vars(import_module(package))) | set(names))

    return getattr_, dir_

__all__ = ["FUNCTIONS", "FunctionCache", "PROBLEMS", "cached", "lazy_exports"]
