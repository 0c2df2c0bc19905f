"""A failed solve's verdict is on the nodes it kept, and says so (`Verdict.partial`): a script
that read only the verdict of a march stopped by ``max_steps`` had seen "accurate" with nothing
to tell it that the span asked for was not covered."""

from __future__ import annotations

import json

from ddvp_nlp import StepControl, Verdict, load_scene
from ddvp_nlp.cli import main


def test_a_march_stopped_early_has_a_partial_verdict_and_a_whole_one_none():
    scene = load_scene("pendulum")
    whole = scene.march(2.0)
    cut = scene.march(2.0, steps=StepControl(max_steps=20))
    assert whole.success and not whole.verdict.partial
    assert "partial" not in whole.verdict.as_dict()
    assert not cut.success and cut.steps == 20
    assert cut.verdict.partial and cut.verdict.steps == 20
    assert Verdict.of(cut.verdict.as_dict()) == cut.verdict  # as meta.json writes it


def test_the_run_folder_of_a_march_stopped_early_says_partial(tmp_path, capsys):
    assert main(["march", "pendulum", "--t-end", "2", "--max-steps", "20", "--no-plot",
                 "--out", str(tmp_path / "run")]) == 1
    accuracy = json.loads((tmp_path / "run" / "meta.json").read_text())["accuracy"]
    assert accuracy["partial"] is True and accuracy["steps"] == 20
    assert "no verdict on the whole run" in capsys.readouterr().out
