"""Fixtures of the documentation tests."""

from pathlib import Path

import pytest
from helpers.forked import WarmPython

from ddvp_nlp.solvers.compiler import cache_folder

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def warm_python(tmp_path_factory):
    """The warm interpreter (tests/helpers/forked.py) that runs the docs' pages and the
    examples, each in a fork of its own: the repository first on the path, matplotlib's Agg
    backend, no bytecode written, a scratch home, and the compiled-code cache the rest of the
    tests use (``DDVP_NLP_CACHE``: with a cache of its own in its scratch home, each page
    compiled its marches' C code again on every run; the cache itself is tested in
    tests/library/test_compiled_code_cache.py)."""
    folder = tmp_path_factory.mktemp("warm-python")
    env = {"PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg", "PATH": "/usr/bin:/bin",
           "HOME": str(folder), "PYTHONDONTWRITEBYTECODE": "1",
           "DDVP_NLP_CACHE": str(cache_folder())}
    python = WarmPython(env, folder)
    yield python
    assert python.close() == 0
