"""Hooks of the architecture tests."""

from pathlib import Path

from helpers import syntax

HERE = Path(__file__).resolve().parent


def pytest_runtest_teardown(item, nextitem):
    """The syntax trees of the 400-odd files the rules read (``helpers.syntax``: parsed once
    for this folder's tests) dropped after this folder's last test: kept, their 850 000 nodes
    were walked by every full pass of Python's cycle collector for the rest of the run (about
    1 s of CPU a pass on a 2-core machine, passes that came more often as the heap grew). A run
    in another order parses them again when it comes back here."""
    if nextitem is None or HERE not in Path(nextitem.path).resolve().parents:
        syntax.parsed.cache_clear()
        syntax.walk.cache_clear()
