"""Every script in examples/ runs to the end, in its own process, and prints what it promises."""

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
# A line each script's output must hold: it ran its solve, not only its imports.
EXPECTED = {"march.py": "accuracy check: drifted from t = 2", "own_scene.py": "status=success",
            "fit_parameters.py": "kepler: mu = ", "orbit_design.py": "arrival mismatch",
            "fixed_endpoint.py": "status=success", "compare.py": "fixed ",
            "dense_output.py": "at t_end:"}


def test_every_example_is_listed():
    assert sorted(path.name for path in EXAMPLES.glob("*.py")) == sorted(EXPECTED)


@pytest.mark.slow_when(
    lambda name, **_: name in {"fixed_endpoint.py", "march.py", "own_scene.py"},
    why="processes")
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_example_runs(name, tmp_path):
    done = subprocess.run([sys.executable, str(EXAMPLES / name)], capture_output=True, text=True,
                          cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert EXPECTED[name] in done.stdout, done.stdout
