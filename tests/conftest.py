"""tests/ mirrors the package: architecture/ (the rules of the layout), docs/ (the documentation
runs and holds together), library/ (physics, discrete and each family of solvers/), workbench/
(scenes, io, runner, studies, cli) and helpers/ (shared code, not tests). See tests/README.md."""

import compileall
import gc
import sys
from pathlib import Path

import pytest
from hypothesis import settings

sys.path.insert(0, str(Path(__file__).resolve().parent))  # `from helpers... import`

from helpers.tiers import SLOW_REASONS  # noqa: E402

from ddvp_nlp import load_scene  # noqa: E402

# Every hypothesis test draws the same examples on every run, with no time limit per example
# (a deadline is a wall-clock bound, and a loaded machine passes it): the tests' own @settings
# set the number of examples and keep these for what they do not set. Tests had set them one by
# one, and a few dozen had not.
settings.register_profile("ddvp", derandomize=True, deadline=None)
settings.load_profile("ddvp")


def pytest_sessionstart(session):
    """The package's bytecode written once, where Python is told to write none
    (``PYTHONDONTWRITEBYTECODE``): the tests start about a hundred processes (the ``ddvp``
    command, Dask workers, killed runs), and each would compile the package's modules from
    source again (0.2 s of CPU each on a 2-core machine). A fresh copy is only read."""
    if sys.dont_write_bytecode:
        compileall.compile_dir(Path(__file__).resolve().parents[1] / "ddvp_nlp", quiet=1)


@pytest.hookimpl(wrapper=True)
def pytest_collection(session):
    """The test modules' rewritten bytecode written where Python is told to write none
    (``PYTHONDONTWRITEBYTECODE``), as the package's is above: pytest rewrites the asserts of
    every test module it imports (9 of the 15 s of CPU the collection took on a 2-core
    machine) and reads its cached rewrite instead when one is there, checked against the
    source's hash; it writes one only where bytecode may be written. Only for the collection,
    where the test modules are imported."""
    writes = sys.dont_write_bytecode
    sys.dont_write_bytecode = False
    try:
        return (yield)
    finally:
        sys.dont_write_bytecode = writes


def pytest_collection_finish(session):
    """What the collection built (modules, test functions, their parameters: alive for the
    whole run) kept out of the cycle collector's passes (``gc.freeze``): each full pass walked
    it again, a few dozen passes a run."""
    gc.freeze()


@pytest.fixture
def paper():
    return load_scene("paper_pendulum")


# Three tiers (tests/README.md): `python -m pytest -m smoke` (architecture, refusals, one run per
# scheme: under a minute), the default run (what CI runs: everything not slow) and
# `python -m pytest -m slow` (scripts/checks/slow_tier.sh). A test is slow by a mark in its own
# file that says why: `@pytest.mark.slow(why=...)`, or for some cases of a parametrized test
# `@pytest.mark.slow_when(predicate, why=...)`, the predicate taking the case's parameters;
# the reasons are helpers.tiers.SLOW_REASONS.


def _slow_reason(mark, where):
    why = mark.kwargs.get("why")
    if why not in SLOW_REASONS:
        raise pytest.UsageError(f"{where}: @pytest.mark.{mark.name} needs why= one of "
                                f"{sorted(SLOW_REASONS)}, got {why!r}")
    return why


@pytest.hookimpl(tryfirst=True)  # before -m deselects
def pytest_collection_modifyitems(config, items):
    for item in items:
        for mark in item.iter_markers("slow"):
            _slow_reason(mark, item.nodeid)
        for mark in item.iter_markers("slow_when"):
            why = _slow_reason(mark, item.nodeid)
            params = getattr(getattr(item, "callspec", None), "params", {})
            if mark.args[0](**params):
                item.add_marker(pytest.mark.slow(why=why))
