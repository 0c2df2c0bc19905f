"""The package's structure, checked: the library (base modules, physics, discrete, solvers) and
the workbench on top of it (scenes, io, runner, studies, cli); no import cycle; each part imports
only the parts below it; the workbench and the scripts use only public names (a package's
``__all__``); no two modules share a file name; the module map of docs/architecture.md names
every module once; no function or class grows past the size a reader can hold."""

import ast
import functools
import importlib
import re
from pathlib import Path

import pytest
from helpers.syntax import parsed, walk

pytestmark = pytest.mark.smoke  # the quick tier: tests/README.md

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "ddvp_nlp"

# The library: the model of its field. The workbench: what is built on it.
BASE = {"errors", "validation", "cache", "blocks", "safe_files", "solution", "startup",
        "progress"}
LIBRARY = {"base", "physics", "discrete", "solvers"}
WORKBENCH = {"scenes", "io", "runner", "studies", "cli"}
# What each part may import (besides itself), bottom to top.
ALLOWED = {
    "base": {"base"},
    "physics": {"base"},
    "discrete": {"base", "physics"},
    "solvers": {"base", "physics", "discrete"},
    "scenes": {"base", "physics", "discrete", "solvers"},
    "io": {"base", "physics", "discrete", "solvers", "scenes"},
    "runner": {"base", "solvers", "io"},
    "studies": {"base", "physics", "discrete", "solvers", "scenes", "io", "runner"},
    "cli": {"base", "physics", "discrete", "solvers", "scenes", "io", "runner", "studies"},
    "__init__": {"base", "physics", "discrete", "solvers", "scenes"},
}
# The two imports across the layers: the root's public ``plot`` is a facade over
# io/run_figure.py and its ``compare`` over studies/comparison.py, each imported inside the
# function, so that `from ddvp_nlp import plot, compare` works while `import ddvp_nlp` loads
# no figure code and no study (docs/architecture.md).
FACADES = {("__init__", "io.run_figure"), ("__init__", "studies.comparison")}
MAX_FUNCTION_LINES = 80
MAX_CLASS_LINES = 200


@functools.cache
def modules() -> dict[str, Path]:
    """The package's modules by dotted name (listed once; callers only read it)."""
    found = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        found[name or "__init__"] = path
    return found


def imports(name: str, path: Path) -> set[str]:
    """The package modules ``name`` imports (at any depth of its code): relative and absolute
    ``from ... import``, ``import ddvp_nlp.x``, and ``importlib.import_module("ddvp_nlp.x")``
    with a literal name; ``from package import module`` counts as the module."""
    package = name.split(".")[:-1] if not path.name == "__init__.py" else name.split(".")
    if name == "__init__":
        package = []
    known = modules()
    result = set()

    def add(target: str, names=()):
        for alias in names:
            full = f"{target}.{alias}" if target else alias
            if full in known:
                result.add(full)
                continue
            result.add(target)
        if not names:
            result.add(target)

    for node in walk(parsed(path)):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = package[:len(package) - node.level + 1]
            add(".".join(base + ([node.module] if node.module else [])),
                [alias.name for alias in node.names])
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("ddvp_nlp"):
            add(node.module[len("ddvp_nlp."):] if "." in node.module else "",
                [alias.name for alias in node.names])
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("ddvp_nlp."):
                    add(alias.name[len("ddvp_nlp."):])
        elif isinstance(node, ast.Call) and ast.unparse(node.func).endswith("import_module") \
                and node.args and isinstance(node.args[0], ast.Constant) \
                and str(node.args[0].value).startswith("ddvp_nlp."):
            add(str(node.args[0].value)[len("ddvp_nlp."):])
    return {m for m in result if m in known and m != name}


def test_the_import_graph_sees_every_form_of_import(tmp_path, monkeypatch):
    path = tmp_path / "fake.py"
    path.write_text("import ddvp_nlp.solvers.bvp.fixed_ends as a\n"
                    "from ddvp_nlp.solvers import periodic\n"
                    "from ..grid import newton\n"
                    "import importlib\n"
                    "importlib.import_module('ddvp_nlp.solvers.higher.window_solve')\n")
    assert imports("solvers.marching.fake", path) == {
        "solvers.bvp.fixed_ends", "solvers.periodic", "solvers.grid.newton",
        "solvers.higher.window_solve"}


@functools.cache
def graph() -> dict[str, set[str]]:
    """Each package module's imports of the package (computed once; callers only read it)."""
    return {name: imports(name, path) for name, path in modules().items()}


def part(module: str) -> str:
    head = module.split(".")[0]
    return "base" if head in BASE else head


def find_cycle(edges: dict[str, set[str]]):
    """One import cycle as a list of modules, or None (depth-first search)."""
    state, stack = {}, []

    def visit(node):
        state[node] = "open"
        stack.append(node)
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == "open":
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                cycle = visit(nxt)
                if cycle:
                    return cycle
        state[node] = "done"
        stack.pop()
        return None

    for node in sorted(edges):
        if node not in state:
            cycle = visit(node)
            if cycle:
                return cycle
    return None


def test_the_cycle_finder_finds_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_no_import_cycle():
    # a facade is imported inside a function, when called: no cycle at import time
    edges = {module: {t for t in targets if (module, t) not in FACADES}
             for module, targets in graph().items()}
    assert find_cycle(edges) is None


def test_each_part_imports_only_the_layers_below_it():
    wrong = [f"{module} imports {target}" for module, targets in graph().items()
             for target in targets
             if part(target) != part(module) and part(target) not in ALLOWED[part(module)]
             and (module, target) not in FACADES]
    assert wrong == []


def test_the_facades_are_the_roots_only_imports_of_the_workbench_and_they_are_lazy():
    """The exceptions above stay two edges, each made inside a function: importing the
    package loads nothing of io/ or studies/."""
    import subprocess
    import sys

    assert {t for t in graph()["__init__"] if part(t) in WORKBENCH - {"scenes"}} == {
        target for _, target in FACADES}
    tree = ast.parse((PACKAGE / "__init__.py").read_text())
    top_level = [node.module for node in tree.body if isinstance(node, ast.ImportFrom)]
    assert not any((module or "").startswith(("io", "studies")) for module in top_level)
    loaded = subprocess.run([sys.executable, "-c", "import sys, ddvp_nlp; print(sorted(m for m "
                             "in sys.modules if m.startswith(('ddvp_nlp.io', "
                             "'ddvp_nlp.studies'))))"],
                            capture_output=True, text=True, check=True).stdout.strip()
    assert loaded == "[]"


def _docstring_lines(node) -> int:
    first = node.body[0] if node.body else None
    if isinstance(first, ast.Expr) and isinstance(getattr(first, "value", None), ast.Constant) \
            and isinstance(first.value.value, str):
        return first.end_lineno - first.lineno + 1
    return 0


def sizes():
    """``(kind, qualified name, lines)`` of every function and class in the package, counted
    from the ``def`` to the last line, without the docstring (a long Args list is welcome)."""
    for name, path in modules().items():
        tree = parsed(path)
        for node in walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                kind = "class" if isinstance(node, ast.ClassDef) else "function"
                lines = node.end_lineno - node.lineno + 1 - _docstring_lines(node)
                yield kind, f"{name}.{node.name}", lines


@pytest.mark.parametrize("kind, limit", [("function", MAX_FUNCTION_LINES),
                                         ("class", MAX_CLASS_LINES)])
def test_no_function_or_class_is_too_long(kind, limit):
    too_long = [(name, lines) for k, name, lines in sizes() if k == kind and lines > limit]
    assert too_long == []


# --- inside solvers/: a folder per family, each with its written contract ---------------------

SOLVER_CORE = {"options", "driver", "dense", "compiler", "columns"}
# what each family of solvers/ may import besides the core (and itself)
SOLVER_FAMILIES = {
    "exact": set(),
    "accuracy": {"exact"},
    "grid": set(),
    "marching": {"accuracy"},
    "baselines": {"marching", "accuracy"},
    "bvp": {"grid", "marching", "exact", "accuracy"},
    "periodic": {"grid", "marching", "exact", "accuracy"},
    "higher": {"grid", "exact", "accuracy"},
    "chaos": {"marching", "exact"},
}


def _solver_part(module: str) -> str | None:
    """``march``, ``grid`` ... for a module inside a family of solvers/, ``core`` for a core
    module, ``None`` outside solvers/."""
    parts = module.split(".")
    if parts[0] != "solvers" or len(parts) < 2:
        return None
    return parts[1] if parts[1] in SOLVER_FAMILIES else "core"


def test_solvers_holds_only_its_families_and_core_modules():
    top = {path.stem for path in (PACKAGE / "solvers").glob("*.py")}
    folders = {path.name for path in (PACKAGE / "solvers").iterdir()
               if path.is_dir() and (path / "__init__.py").exists()}
    assert top == SOLVER_CORE | {"__init__"}
    assert folders == set(SOLVER_FAMILIES)


def family_violations(edges: dict[str, set[str]]) -> list[str]:
    """The imports of ``edges`` (module -> modules) that break the rules of solvers/."""
    wrong = []
    for module, targets in edges.items():
        source = _solver_part(module)
        if source is None:
            continue
        allowed = set() if source == "core" else SOLVER_FAMILIES[source]
        for target in targets:
            part = _solver_part(target)
            if part not in (None, "core", source) and part not in allowed:
                wrong.append(f"{module} imports {target}")
    return wrong


def test_each_family_imports_only_what_its_rules_allow():
    """The core imports no family; exact/ and grid/ only the core; accuracy/ also exact/;
    marching/ also accuracy/; baselines/ also marching/; bvp/ and periodic/ grid/, marching/, exact/
    and accuracy/; higher/ grid/, exact/ and accuracy/; chaos/ marching/ and exact/."""
    assert family_violations(graph()) == []


def test_the_family_rule_catches_forbidden_imports():
    assert family_violations({
        "solvers.marching.initial_value": {"solvers.bvp.fixed_ends", "solvers.driver"},
        "solvers.driver": {"solvers.marching.initial_value"},
        "solvers.bvp.first_guess": {"solvers.marching.initial_value"},
        "solvers.exact.flow": {"solvers.accuracy.judgement"},
        "solvers.grid.newton": {"solvers.periodic.closed_grid"}}) == [
        "solvers.marching.initial_value imports solvers.bvp.fixed_ends",
        "solvers.driver imports solvers.marching.initial_value",
        "solvers.exact.flow imports solvers.accuracy.judgement",
        "solvers.grid.newton imports solvers.periodic.closed_grid"]


@pytest.mark.parametrize("family", sorted(SOLVER_FAMILIES))
def test_each_family_states_its_contract_as_numbered_rules(family):
    """Each family's ``__init__`` states, as scipy's ``OdeSolver`` does, the rules an
    implementer must keep, numbered (where things are is the module map's job:
    docs/architecture.md)."""
    doc = ast.get_docstring(ast.parse((PACKAGE / "solvers" / family / "__init__.py")
                                      .read_text())) or ""
    numbered = [line for line in doc.splitlines() if line[:3] in {f"{k}. " for k in range(10)}]
    assert len(numbered) >= 3, doc[:200]


# --- names: no private name across modules, registries filled where they are defined ----------

# The private-looking names of a namedtuple are its public interface.
NAMEDTUPLE_API = {"_fields", "_asdict", "_replace", "_make"}
# Documented public functions of the standard library whose names start with "_": os._exit
# (a forked worker's end, and what a scene's code may not call).
STDLIB_API = {"_exit"}


def private_uses(path: Path) -> list[str]:
    """Private names (``_x``) this module takes from another one: imported by name, or read as
    an attribute of anything but ``self`` and ``cls``."""
    found = []
    tree = parsed(path)
    for node in walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.level or (node.module or "")
                                                  .startswith("ddvp_nlp")):
            found += [f"import {alias.name} (line {node.lineno})" for alias in node.names
                      if alias.name.startswith("_") and not alias.name.startswith("__")]
        elif isinstance(node, ast.Attribute) and node.attr.startswith("_") \
                and not node.attr.startswith("__") and node.attr not in NAMEDTUPLE_API \
                and node.attr not in STDLIB_API:
            # a subclass's override calling the method it overrides (``super()._step``) is
            # the class's own interface, like ``self._step``
            if not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")) \
                    and ast.unparse(node.value) != "super()":
                found.append(f"{ast.unparse(node)} (line {node.lineno})")
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                and node.func.id in ("getattr", "setattr", "hasattr") and len(node.args) >= 2 \
                and isinstance(node.args[1], ast.Constant) \
                and str(node.args[1].value).startswith("_") \
                and not str(node.args[1].value).startswith("__"):
            found.append(f"{ast.unparse(node)} (line {node.lineno})")
    return found


def test_no_private_name_is_used_across_modules():
    used = {name: private_uses(path) for name, path in modules().items()}
    assert {name: uses for name, uses in used.items() if uses} == {}


def test_the_assignment_check_finds_a_registry_filled_from_outside(tmp_path):
    path = tmp_path / "avf.py"
    path.write_text("from ddvp_nlp.solvers.baselines import fixed_step\n"
                    "fixed_step.IMPLICIT_STEPS['avf'] = 1\nfixed_step.CHUNK = 3\n"
                    "import warnings\nwarnings.formatwarning = print\n")
    assert foreign_assignments(path) == ["fixed_step.IMPLICIT_STEPS['avf'] (line 2)",
                                         "fixed_step.CHUNK (line 3)"]


def test_the_private_name_check_finds_both_kinds(tmp_path):
    path = tmp_path / "m.py"
    path.write_text("from .other import _helper\nx = scene._exact(1)\ny = self._ok\n"
                    "z = row._asdict()\nw = getattr(module, '_checked')\n")
    assert sorted(private_uses(path)) == ["getattr(module, '_checked') (line 5)",
                                          "import _helper (line 1)", "scene._exact (line 2)"]


def bound_modules(tree, package: list[str]) -> set[str]:
    """Names this code binds to modules of the package (``from . import stepper``, ``from
    ddvp_nlp.solvers import compiler``, ``import ddvp_nlp.x as y``); ``package`` is the
    importing module's package, as a list of names (empty outside the package)."""
    known = modules()
    bound = set()
    for node in walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1] + \
                    (node.module.split(".") if node.module else [])
            elif (node.module or "").startswith("ddvp_nlp"):
                base = node.module.split(".")[1:]
            else:
                continue
            for alias in node.names:
                if ".".join([*base, alias.name]) in known:
                    bound.add(alias.asname or alias.name)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("ddvp_nlp.") and alias.asname:
                    bound.add(alias.asname)
    return bound


def foreign_assignments(path: Path, package: list[str] | None = None) -> list[str]:
    """Assignments into another package module's namespace (``module.NAME = ...``,
    ``module.TABLE[key] = ...``): a registry filled by an import's side effect, or a global
    switched from outside."""
    tree = parsed(path)
    bound = bound_modules(tree, package or [])
    found = []
    for node in walk(tree):
        targets = node.targets if isinstance(node, ast.Assign) else \
            [node.target] if isinstance(node, ast.AugAssign) else []
        for target in targets:
            base = target.value if isinstance(target, ast.Subscript) else target
            if isinstance(base, ast.Attribute) and isinstance(base.value, ast.Name) \
                    and base.value.id in bound:
                found.append(f"{ast.unparse(target)} (line {node.lineno})")
    return found


def test_no_module_fills_or_switches_another_ones_globals():
    assigned = {name: foreign_assignments(path, name.split(".")[:-1]
                                          if path.name != "__init__.py" else name.split("."))
                for name, path in modules().items()}
    assert {name: found for name, found in assigned.items() if found} == {}


def _switches_a_setting(call: ast.Call) -> bool:
    """``monkeypatch.setattr(module, "NAME", ...)``, ``monkeypatch.setattr("pkg.mod.NAME",
    ...)`` or ``monkeypatch.setitem(module.TABLE, ...)``: a module's constant or registry
    switched (an upper-case name; replacing a function stays allowed)."""
    function = ast.unparse(call.func)
    if function.endswith("setitem") and call.args:
        target = ast.unparse(call.args[0])
        return "." in target and target.split(".")[-1].isupper()
    if not function.endswith("setattr") or not call.args:
        return False
    first = call.args[0]
    if isinstance(first, ast.Constant) and isinstance(first.value, str) and "." in first.value:
        return first.value.rsplit(".", 1)[1].isupper()
    return len(call.args) >= 2 and isinstance(call.args[1], ast.Constant) \
        and str(call.args[1].value).lstrip("_").isupper()


def test_the_switch_check_finds_every_form():
    calls = ['monkeypatch.setattr(stepper, "MAX_CALLS", 1)', 'monkeypatch.setattr(c, "_WARNED", 1)',
             'monkeypatch.setattr("ddvp_nlp.cli.main.COMMANDS", {})',
             'monkeypatch.setitem(cli_main.COMMANDS, "scenes", f)',
             'monkeypatch.setattr(stress, "default_cases", f)']
    found = [_switches_a_setting(ast.parse(call).body[0].value) for call in calls]
    assert found == [True, True, True, True, False]


# A file that holds neither form below (no setattr or setitem call, no assignment to an
# attribute of an upper-case name: ``x.NAME = ``, ``x.NAME[k] = ``, ``x.NAME += ``) is not
# parsed by the next test: of the tests' and scripts' 200-odd files, about fifty are.
MAY_SWITCH = re.compile(r"set(?:attr|item)\s*\(|\.\s*[A-Z]\w*[\s\\]*(?:\[.*?\])?[\s\\]*"
                        r"[-+*/%|&^@]?=(?!=)", re.S)


def test_the_switch_filter_keeps_every_form_the_checks_find(tmp_path):
    sources = ['monkeypatch.setattr(stepper, "MAX_CALLS", 1)',
               'monkeypatch.setitem(cli_main.COMMANDS, "scenes", f)',
               "from ddvp_nlp.solvers.baselines import fixed_step\nfixed_step.CHUNK = 3\n",
               "from ddvp_nlp.solvers.baselines import fixed_step\n"
               "fixed_step.IMPLICIT_STEPS['avf'] = 1\n",
               "from ddvp_nlp.solvers.baselines import fixed_step\nfixed_step.CHUNK += 3\n",
               "from ddvp_nlp.solvers.baselines import fixed_step\nfixed_step.CHUNK \\\n    = 3\n"]
    for number, source in enumerate(sources):
        path = tmp_path / f"m{number}.py"
        path.write_text(source)
        found = [n for n in walk(parsed(path)) if isinstance(n, ast.Call)
                 and _switches_a_setting(n)] + foreign_assignments(path)
        assert found and MAY_SWITCH.search(source), source
    assert not MAY_SWITCH.search("x = module.CHUNK\nif a.B == 1: pass\n")


def test_tests_and_scripts_pass_configuration_instead_of_switching_globals():
    """Solver choices are arguments or option fields: neither the tests nor the benchmarks
    assign a module's constants (``monkeypatch.setattr(module, "NAME", ...)`` or
    ``module.NAME = ...``); replacing a function to inject a fault stays allowed."""
    root = PACKAGE.parent
    switched = []
    for path in [*(root / "tests").rglob("*.py"), *(root / "scripts").rglob("*.py")]:
        if not MAY_SWITCH.search(path.read_text()):
            continue
        tree = parsed(path)
        for node in walk(tree):
            if isinstance(node, ast.Call) and _switches_a_setting(node):
                switched.append(f"{path.name}: {ast.unparse(node)}")
        switched += [f"{path.name}: {found}" for found in foreign_assignments(path)
                     if found.split(".")[1][:1].isupper()]
    assert switched == []


# --- the library and the workbench: public names only ------------------------------------------

# The library's faces: a workbench module or a script imports from the library only through
# these (a package's __init__ or a base module), and only names in its __all__.
LIBRARY_FACES = {"physics", "discrete", "solvers"} | BASE


def _absolute(module: str | None, level: int, package: list[str]) -> str:
    if not level:
        return (module or "")[len("ddvp_nlp."):] if (module or "").startswith("ddvp_nlp.") \
            else ("" if module == "ddvp_nlp" else "?")
    base = package[:len(package) - level + 1]
    return ".".join(base + ([module] if module else []))


def public_name_violations(path: Path, package: list[str] | None, faces: dict) -> list[str]:
    """Imports in ``path`` that reach past a face: a module inside a face's package, or a name
    not in the face's ``__all__``. ``faces``: face module -> its ``__all__``; ``package``: the
    importing module's package (``None`` outside ddvp_nlp)."""
    wrong = []
    for node in walk(parsed(path)):
        if isinstance(node, ast.Import):
            wrong += [f"import {a.name} (line {node.lineno})" for a in node.names
                      if a.name.startswith("ddvp_nlp.") and
                      a.name[len("ddvp_nlp."):].split(".")[0] in {f.split(".")[0] for f in faces}]
            continue
        if not isinstance(node, ast.ImportFrom):
            continue
        if node.level and package is None:
            continue
        target = _absolute(node.module, node.level, package or [])
        head = target.split(".")[0]
        if head not in {f.split(".")[0] for f in faces}:
            continue
        if target not in faces:
            wrong.append(f"from {target} import ... (line {node.lineno}): not a public face")
            continue
        wrong += [f"from {target} import {a.name} (line {node.lineno}): not in its __all__"
                  for a in node.names if a.name not in faces[target]]
    return wrong


def _faces(names) -> dict:
    return {name: set(importlib.import_module(f"ddvp_nlp.{name}").__all__) for name in names}


def test_the_workbench_uses_only_the_librarys_public_names():
    faces = _faces(LIBRARY_FACES)
    wrong = {}
    for name, path in modules().items():
        if part(name) not in WORKBENCH:
            continue
        package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        found = public_name_violations(path, package, faces)
        if found:
            wrong[name] = found
    assert wrong == {}


def test_the_public_name_check_finds_every_way_past_a_face(tmp_path):
    path = tmp_path / "m.py"
    path.write_text("from ..solvers.marching.chunk import Chunk\nfrom ..solvers import march, _x\n"
                    "import ddvp_nlp.physics.hamiltonian\nfrom ..errors import InputError\n")
    faces = {"solvers": {"march"}, "errors": {"InputError"}, "physics": set()}
    assert sorted(public_name_violations(path, ["studies"], faces)) == [
        "from solvers import _x (line 2): not in its __all__",
        "from solvers.marching.chunk import ... (line 1): not a public face",
        "import ddvp_nlp.physics.hamiltonian (line 3)"]


def test_the_library_imports_nothing_of_the_workbench():
    wrong = [f"{module} imports {target}" for module, targets in graph().items()
             if part(module) in LIBRARY for target in targets if part(target) in WORKBENCH]
    assert wrong == []


def test_every_face_lists_only_names_it_has():
    for name in sorted(LIBRARY_FACES | WORKBENCH):
        face = importlib.import_module(f"ddvp_nlp.{name}")
        for public in getattr(face, "__all__", ()):
            assert getattr(face, public) is not None, f"ddvp_nlp.{name}.{public}"


# The scripts that measure a library internal, and the internals they name (each import says so
# in a comment): the faces stay what the workbench composes (issue 44), and a refactor that moves
# one of these breaks this list, not the script.
INTERNALS_FOR_SCRIPTS = {
    "scripts/benchmarks/bench_bvp.py": {"solvers.grid.linear"},
    "scripts/benchmarks/bench_periodic.py": {"solvers.periodic.first_orbit"},
    "scripts/benchmarks/bench_constraints.py": {"discrete.constrained",
                                                "solvers.marching.constrained_march"},
    "scripts/benchmarks/bench_double_pendulum.py": {"discrete.constrained",
                                                    "solvers.baselines.rattle"},
    "scripts/benchmarks/bench_shake_tolerance.py": {"solvers.baselines.rattle"},
    "scripts/benchmarks/bench_rattle.py": {"solvers.baselines.rattle",
                                           "solvers.exact.constrained_flow",
                                           "solvers.exact.constrained_reference"},
    "scripts/pages/chaos_page.py": {"solvers.chaos.exact_indicators"},
    "scripts/pages/comparison_page.py": {"solvers.baselines.fixed_step"},
    # damaged shard parts written through the tool's own writer, for the merge's checks
    "scripts/pages/faults.py": {"io.chaos_files", "studies.chaos_map"},
    "scripts/pages/stability_study.py": {"solvers.exact.variational"},
    "scripts/pages/gradients_page.py": {"solvers.marching.derivatives"},
}


def test_scripts_and_examples_use_only_public_names():
    """A script or an example imports the root's names or a package's ``__all__``, never a
    module inside a package (but the internals ``INTERNALS_FOR_SCRIPTS`` lists): a refactor that
    moves a name breaks this test, not the script."""
    packages = {name for name, path in modules().items() if path.name == "__init__.py"
                and name != "__init__"} | BASE
    faces = _faces(packages)
    faces[""] = set(importlib.import_module("ddvp_nlp").__all__)
    wrong = {}
    for path in [*(ROOT / "scripts").rglob("*.py"), *(ROOT / "examples").rglob("*.py")]:
        where = str(path.relative_to(ROOT))
        allowed = INTERNALS_FOR_SCRIPTS.get(where, set())
        found = [f for f in public_name_violations(path, None, faces)
                 if not any(f.startswith(f"from {module} import ... ") for module in allowed)]
        if found:
            wrong[where] = found
        unused = [m for m in allowed if f"from ddvp_nlp.{m} import" not in path.read_text()]
        assert unused == [], f"{where}: listed internals it no longer imports: {unused}"
    assert wrong == {}


def test_no_two_modules_share_a_file_name():
    seen = {}
    for path in [*PACKAGE.rglob("*.py"), *(ROOT / "problems").glob("*.py")]:
        if path.name in ("__init__.py", "__main__.py"):
            continue
        seen.setdefault(path.name, []).append(str(path.relative_to(ROOT)))
    assert {name: paths for name, paths in seen.items() if len(paths) > 1} == {}


def module_map() -> list[str]:
    """The module paths the map of docs/architecture.md lists (its "Module map" section: one
    ``path`` per line of a code block, relative to ``ddvp_nlp/``)."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    section = text.split("## Module map", 1)[1].split("\n## ", 1)[0]
    block = section.split("```text", 1)[1].split("```", 1)[0]
    return re.findall(r"^\s*([\w/]+\.py)\b", block, flags=re.M)


def test_the_module_map_names_every_module_once():
    listed = module_map()
    actual = sorted(str(path.relative_to(PACKAGE)) for path in PACKAGE.rglob("*.py")
                    if path.name != "__main__.py")
    assert sorted(set(listed)) == sorted(listed), "a module is listed twice"
    assert sorted(listed) == actual


def test_no_lazy_public_name_is_also_a_module_of_its_package():
    """A face that loads its names on first use (a module ``__getattr__``) cannot export a
    name its package has a module of: importing ``package.name`` binds the module in the
    package, and ``from package import name`` gives the module from then on (``solvers.march``
    shadowed ``march`` until it became ``solvers/marching/``). A face that imports its names
    (``from .main import main``) binds them after the module and keeps them."""
    shadowed = {}
    for name, path in modules().items():
        if path.name != "__init__.py" or name == "__init__" \
                or "__getattr__" not in path.read_text():
            continue
        submodules = {child.stem for child in path.parent.glob("*.py")} | \
            {child.name for child in path.parent.iterdir() if (child / "__init__.py").exists()}
        clash = set(importlib.import_module(f"ddvp_nlp.{name}").__all__) & submodules
        if clash:
            shadowed[name] = sorted(clash)
    assert shadowed == {}


def test_every_slow_mark_says_why_in_its_own_file():
    """The slow tier is marked by meaning in the test files (tests/conftest.py): every
    `pytest.mark.slow` and `pytest.mark.slow_when` is a call with a why= among the reasons the
    conftest knows; a bare mark, or one with another reason, is listed here."""
    from helpers.tiers import SLOW_REASONS

    def is_slow_mark(node):
        return (isinstance(node, ast.Attribute) and node.attr in {"slow", "slow_when"}
                and isinstance(node.value, ast.Attribute) and node.value.attr == "mark")

    bad, marks = [], 0
    for file in sorted((ROOT / "tests").rglob("*.py")):
        if file.name == "conftest.py":  # marks the cases its predicates chose, why= passed on
            continue
        if "slow" not in file.read_text():  # no mark to read: not parsed
            continue
        tree = parsed(file)
        calls = {id(c.func): c for c in walk(tree) if isinstance(c, ast.Call)}
        for node in filter(is_slow_mark, walk(tree)):
            marks += 1
            call = calls.get(id(node))
            why = {k.arg: k.value for k in (call.keywords if call else [])}.get("why")
            if not (isinstance(why, ast.Constant) and why.value in SLOW_REASONS):
                bad.append(f"{file.relative_to(ROOT)}:{node.lineno}")
    assert marks > 50 and bad == []
