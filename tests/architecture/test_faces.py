"""Each public face is written in three places (its name table, its ``TYPE_CHECKING`` imports for
readers and static tools, and ``__all__``); this holds them to agreeing, read from the source so
that no face has to be imported (issue 44)."""

import ast
from pathlib import Path

import pytest

pytestmark = pytest.mark.smoke  # the quick tier: tests/README.md

PACKAGE = Path(__file__).resolve().parents[2] / "ddvp_nlp"
FACES = ["solvers", "io", "runner", "studies"]


def _parts(path: Path):
    """The face's name table (a dict literal of name -> module), its TYPE_CHECKING names, its
    ``__all__``, and the names it imports or defines at the top level outside TYPE_CHECKING."""
    tree = ast.parse(path.read_text())
    table, checking, listed, eager = set(), set(), set(), set()
    for node in tree.body:
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            checking |= {a.asname or a.name for n in node.body for a in n.names}
        elif isinstance(node, ast.Assign):
            target = node.targets[0]
            if getattr(target, "id", None) == "__all__":
                listed = {ast.literal_eval(e) for e in node.value.elts}
            elif getattr(target, "id", None) == "PUBLIC":
                table = {ast.literal_eval(k) for k in node.value.keys}
            elif isinstance(target, ast.Tuple) and isinstance(node.value, ast.Call):
                # ``_solver, _names = lazy_exports(__name__, {name: "solvers" for name in (...)})``
                for arg in node.value.args:
                    if isinstance(arg, ast.DictComp):
                        table = {ast.literal_eval(e) for e in arg.generators[0].iter.elts}
            elif getattr(target, "id", None) == "__version__":
                eager.add("__version__")
        elif isinstance(node, ast.ImportFrom) and node.level == 1:
            eager |= {a.asname or a.name for a in node.names}
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef)) and not node.name.startswith("_"):
            eager.add(node.name)
    return table, checking, listed, eager


@pytest.mark.parametrize("face", FACES)
def test_a_face_name_table_type_checking_imports_and_all_agree(face):
    table, checking, listed, _ = _parts(PACKAGE / face / "__init__.py")
    assert table, f"{face}: no name table found"
    assert checking == table, f"{face}: TYPE_CHECKING imports differ: {checking ^ table}"
    assert listed == table, f"{face}: __all__ differs from the name table: {listed ^ table}"


def test_the_users_face_is_its_eager_imports_plus_its_lazy_table():
    table, checking, listed, eager = _parts(PACKAGE / "__init__.py")
    assert table and checking == table, checking ^ table
    # every eager import or definition is public but the two that start the package
    public_eager = eager - {"startup", "lazy_exports"}
    assert listed == table | public_eager, listed ^ (table | public_eager)
