"""Hooks of the architecture tests."""

import gc
from pathlib import Path

from helpers import syntax

HERE = Path(__file__).resolve().parent


def pytest_runtest_setup(item):
    """No cycle collector while this folder's tests run: they parse the 400-odd files the rules
    read (``helpers.syntax``, once for the folder), 850 000 nodes that hold no cycle, and the
    collector's full passes walked them again and again as they were made (2.5 s of CPU on a
    2-core machine). Back on after the folder's last test (below)."""
    gc.disable()


def pytest_runtest_teardown(item, nextitem):
    """The syntax trees dropped after this folder's last test, and the collector back on: kept,
    the trees were walked by every full pass of the collector for the rest of the run (about
    1 s of CPU a pass late in the run). A run in another order parses them again when it comes
    back here."""
    if nextitem is None or HERE not in Path(nextitem.path).resolve().parents:
        syntax.parsed.cache_clear()
        syntax.walk.cache_clear()
        gc.enable()
