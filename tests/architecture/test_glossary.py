"""The glossary of docs/architecture.md kept by the code: a word the glossary gives one meaning
is not used in the code for the meaning it rules out, checked on the module paths and their
names (identifiers, not prose)."""

import ast
from pathlib import Path

from helpers.syntax import parsed, walk

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "ddvp_nlp"


def identifiers(path: Path):
    """Every name a module defines or binds: functions, classes, arguments, assignments."""
    for node in walk(parsed(path)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            yield node.name
        elif isinstance(node, ast.arg):
            yield node.arg
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            yield node.id
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            yield node.attr


def words_in(folder: str, word: str) -> list[str]:
    found = []
    for path in sorted((PACKAGE / folder).rglob("*.py")):
        for name in identifiers(path):
            if word in name.lower():
                found.append(f"{path.relative_to(ROOT)}: {name}")
    return found


def test_the_glossary_table_exists_with_the_words_checked_here():
    text = (ROOT / "docs" / "architecture.md").read_text()
    glossary = text[text.index("## Glossary"):]
    for word in ("| grid |", "| stage |", "| journal |", "task table"):
        assert word in glossary, word


def test_grid_means_the_nodes_of_a_whole_grid_problem_not_a_task_table():
    """The runner journals task tables of study runs: none of its names says grid."""
    assert words_in("runner", "grid") == []


def test_a_runge_kutta_stage_is_named_so_only_inside_the_exact_flows_attempt():
    """``stage`` is one run of one solver in a grid solve (`Stage`); a Runge-Kutta stage is
    called so only in ``exact/attempt.py``."""
    found = [entry for entry in words_in("solvers/exact", "stage")
             if not entry.startswith("ddvp_nlp/solvers/exact/attempt.py")]
    assert found == []


def test_the_march_has_one_loop_function_name():
    """``run_march`` named two things (the library's loop and the command); the library's is
    the march session now."""
    defined = [f"{path.relative_to(ROOT)}" for path in sorted(PACKAGE.rglob("*.py"))
               for node in walk(parsed(path))
               if isinstance(node, ast.FunctionDef) and node.name == "run_march"]
    assert len(defined) <= 1, defined
    assert all(path.startswith("ddvp_nlp/cli/") for path in defined)


def test_a_grid_request_counts_nodes_in_every_family():
    """``nodes`` counts nodes everywhere (the glossary): the periodic family's request had
    counted its intervals under that name; it now says ``request.intervals`` where it means
    them."""
    text = (PACKAGE / "solvers" / "periodic" / "orbit.py").read_text()
    assert "request.nodes" not in text
    assert "request.intervals" in text
