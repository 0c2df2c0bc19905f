"""What starting the package and the ``ddvp`` command loads that a march does not need, counted
in modules, never in seconds: the version is looked up only when asked for, and a march's
parser loads no task runner."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

import ddvp_nlp

pytestmark = pytest.mark.smoke  # the quick tier: tests/README.md


def loaded(code: str) -> list[str]:
    """The modules a fresh interpreter holds after running ``code``."""
    out = subprocess.run([sys.executable, "-c", f"{code}\nimport sys, json\n"
                          "print(json.dumps(sorted(sys.modules)))"],
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def test_neither_the_import_nor_a_marchs_parser_looks_up_the_version():
    # importlib.metadata (and the email package behind it) was a third of what `import
    # ddvp_nlp` added to numpy and casadi
    modules = loaded("import ddvp_nlp\nfrom ddvp_nlp.cli.parser import build_parser\n"
                     "build_parser('march')")
    assert "importlib.metadata" not in modules
    assert [m for m in modules if m.startswith("ddvp_nlp.runner")] == []


def test_the_version_is_there_when_asked_for(capsys):
    from ddvp_nlp.cli import main

    assert "__version__" in dir(ddvp_nlp) and ddvp_nlp.__version__
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out == f"ddvp {ddvp_nlp.__version__}\n"  # on stdout, as before


@pytest.mark.parametrize("argv", [["--version"], ["--help"], []])
def test_the_command_without_a_command_loads_no_solver(argv):
    """``ddvp --version``, ``ddvp --help`` and ``ddvp`` alone build no command's options, whose
    defaults come from the solvers (it had loaded every family and scipy.interpolate)."""
    modules = loaded("from ddvp_nlp.cli.main import main\n"
                     f"try:\n    main({argv!r})\nexcept SystemExit:\n    pass")
    core = {"ddvp_nlp.solvers.options"}  # the option types, loaded by `import ddvp_nlp`
    assert [m for m in modules if m.startswith(("ddvp_nlp.solvers.", "ddvp_nlp.studies",
                                                "scipy.interpolate")) and m not in core] == []
