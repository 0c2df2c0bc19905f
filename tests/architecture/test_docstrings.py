"""The API pages are rendered from the docstrings by mkdocstrings, which shows a Sphinx role
(``:class:`Scheme` ``) as raw text: docstrings use code spans instead (issue 30)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from helpers.syntax import parsed, walk

import ddvp_nlp

pytestmark = pytest.mark.smoke  # the quick tier: tests/README.md

ROLE = re.compile(r":(?:py:)?(?:class|func|meth|mod|attr|data|obj|exc|ref|math|const|term)"
                  r":`")


def docstrings(path: Path):
    for node in walk(parsed(path)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            text = ast.get_docstring(node, clean=False)
            if text:
                yield getattr(node, "name", path.stem), text


def test_no_docstring_of_the_package_holds_a_raw_sphinx_role():
    root = Path(ddvp_nlp.__file__).parent
    found = [f"{path.relative_to(root)}: {name}: {match.group(0)}"
             for path in sorted(root.rglob("*.py")) for name, text in docstrings(path)
             for match in ROLE.finditer(text)]
    assert not found, "\n".join(found)


def test_the_pattern_sees_a_role():
    assert ROLE.search("See :class:`Scheme` and :py:func:`march`.")
    assert not ROLE.search("See `Scheme` and ``march``.")


# files named in the code that are not the project's: scipy's own coefficients file (read by
# solvers/exact/tableau.py) and the planted files of the fault tests
NOT_OURS = {"dop853_coefficients.py", "evil.py", "h.py", "singular.py"}


def test_every_file_the_code_names_exists():
    """A module, script or docstring that names ``something.py`` names a file that exists
    (a path by its tail, a bare name anywhere in the project): renamed modules leave no stale
    references behind."""
    project = Path(ddvp_nlp.__file__).parent.parent
    folders = ("ddvp_nlp", "problems", "scripts", "tests", "examples", "docs")
    files = [str(path.relative_to(project)) for folder in folders
             for path in (project / folder).rglob("*.py")]
    names = {Path(file).name for file in files}
    stale = []
    for path in [project / file for file in files if not file.startswith(("tests", "docs"))]:
        for match in re.finditer(r"(?<![\w/.-])((?:[\w-]+/)*[\w-]+\.py)\b", path.read_text()):
            ref = match.group(1)
            if Path(ref).name in NOT_OURS:
                continue
            exists = any(file.endswith(ref) for file in files) if "/" in ref else \
                ref in names
            if not exists:
                stale.append(f"{path.relative_to(project)}: {ref}")
    assert not stale, "\n".join(sorted(set(stale)))
