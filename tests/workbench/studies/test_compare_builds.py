"""What a comparison builds once: every run's verdict is judged against one exact flow per
process and shape (each run loads its scene anew, and judged with that system it had built the
flows again: 13 times in a constrained comparison, half of its CPU). Counted in builds, not
seconds."""

from __future__ import annotations

import importlib
import traceback

import pytest

from ddvp_nlp import compare
from ddvp_nlp.studies.work_precision import CompareOptions

flow_module = importlib.import_module("ddvp_nlp.solvers.exact.flow")


@pytest.mark.parametrize("scene", ["pendulum", "cartesian_pendulum"])
def test_the_verdicts_of_a_comparison_build_each_exact_flow_once(scene, monkeypatch):
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
