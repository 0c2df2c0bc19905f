"""What a study builds once per process. A comparison judges every run's verdict against one
exact flow per shape (each run loads its scene anew, and judged with that system it had built
the flows again: 13 times in a constrained comparison, half of its CPU); a sweep's rows share
their scene's system (every row had loaded the scene, and built the march and the check,
again: 4.2 s of CPU for six Kepler rows, 2.3 s shared). Counted in builds, not seconds."""

from __future__ import annotations

import importlib
import traceback

import pytest

from ddvp_nlp import compare
from ddvp_nlp.cli import main
from ddvp_nlp.scenes import scene_file
from ddvp_nlp.studies.work_precision import CompareOptions

flow_module = importlib.import_module("ddvp_nlp.solvers.exact.flow")


@pytest.mark.parametrize("scene", ["pendulum", "cartesian_pendulum"])
def test_the_verdicts_of_a_comparison_build_each_exact_flow_once(scene, monkeypatch, tmp_path):
    # a copy of the scene's file: content no earlier test loaded, so nothing is built for it yet
    copy = tmp_path / f"{scene}.py"
    copy.write_text(scene_file(scene).read_text() + "\n# a copy\n")
    scene = str(copy)
    built = []
    original = flow_module.AdaptiveFlow.__init__

    def counted(self, field, **options):
        if any(frame.name == "accuracy_columns" for frame in traceback.extract_stack()):
            built.append((options.get("tangent", 0), options.get("dense", True),
                          options.get("slots")))
        original(self, field, **options)

    monkeypatch.setattr(flow_module.AdaptiveFlow, "__init__", counted)
    result = compare(scene, t_span=(0, 2), options=CompareOptions(halvings=1, repeats=1))
    assert sum(1 for row in result.rows if row["accuracy"]) >= 4
    assert built and len(built) == len(set(built)), built


def test_the_rows_of_a_sweep_load_their_scene_once(tmp_path):
    runs = tmp_path / "runs.txt"  # the scene file writes a line each time it runs
    path = tmp_path / "osc.py"
    path.write_text("from ddvp_nlp import Scene\n"
                    f"open({str(runs)!r}, 'a').write('ran\\n')\n"
                    "def hamiltonian(q, p, t):\n    return p[0]**2 / 2 + q[0]**2 / 2\n"
                    "scene = Scene(hamiltonian, n=1, q0=[1.0], p0=[0.0], tau0=0.1, t_end=5)\n")
    assert main(["sweep", str(path), "--allow-scene", str(path), "--grid",
                 "tau0=0.1,0.05,0.02", "--methods", "vddvp", "--workers", "1",
                 "--no-progress", "--out", str(tmp_path / "sweep")]) == 0
    rows = (tmp_path / "sweep" / "sweep.csv").read_text().splitlines()[1:]
    assert len(rows) == 3 and runs.read_text() == "ran\n"
