"""tests/ mirrors the package: architecture/ (the rules of the layout), docs/ (the documentation
runs and holds together), library/ (physics, discrete and each family of solvers/), workbench/
(scenes, io, runner, studies, cli) and helpers/ (shared code, not tests). See tests/README.md."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # `from helpers... import`

from ddvp_nlp import load_scene  # noqa: E402


@pytest.fixture
def paper():
    return load_scene("paper_pendulum")


# The long studies and the costliest repetitions (tests/slow_tests.txt, tests/README.md), marked
# slow: the default run leaves them out, and `python -m pytest -m slow` (or `-m "slow or not
# slow"` for everything) runs them.
SLOW = {line.strip() for line in (Path(__file__).parent / "slow_tests.txt").read_text().splitlines()
        if line.strip() and not line.startswith("#")}


@pytest.hookimpl(tryfirst=True)  # before -m deselects
def pytest_collection_modifyitems(config, items):
    root = Path(config.rootpath)
    for item in items:
        path = Path(item.fspath).resolve().relative_to(root).as_posix()
        if f"{path}::{item.name}" in SLOW:
            item.add_marker(pytest.mark.slow)
