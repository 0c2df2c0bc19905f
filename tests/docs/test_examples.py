"""Every script in examples/ runs to the end, in a process of its own, and prints what it
promises: run as ``python FILE`` runs it (``__main__``, its folder first on the path), in a
scratch folder, in a fork of the warm interpreter of tests/docs/conftest.py (one that imported
numpy, scipy, CasADi and the package once: tests/helpers/forked.py)."""

from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
# A line each script's output must hold: it ran its solve, not only its imports.
EXPECTED = {"march.py": "accuracy check: drifted from t = 2", "own_scene.py": "status=success",
            "fit_parameters.py": "kepler: mu = ", "orbit_design.py": "arrival mismatch",
            "fixed_endpoint.py": "status=success", "compare.py": "fixed ",
            "dense_output.py": "at t_end:"}
# CPU seconds a script may take (RLIMIT_CPU; the longest takes a few on a 2-core machine)
CPU_SECONDS = 300


def test_every_example_is_listed():
    assert sorted(path.name for path in EXAMPLES.glob("*.py")) == sorted(EXPECTED)


@pytest.mark.slow_when(
    lambda name, **_: name in {"fixed_endpoint.py", "march.py", "own_scene.py"},
    why="processes")
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_example_runs(name, tmp_path, warm_python):
    code, out, err = warm_python.run("script", tmp_path, cpu=CPU_SECONDS,
                                     path=str(EXAMPLES / name), env={"HOME": str(tmp_path)})
    assert code == 0, err
    assert EXPECTED[name] in out, out
