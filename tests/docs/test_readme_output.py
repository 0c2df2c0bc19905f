"""The README's "What the main job prints" is what the main job prints: every line but the last
(timings and the folder), word for word (a user found its reference step count stale)."""

from __future__ import annotations

from pathlib import Path

from ddvp_nlp.cli import main

README = Path(__file__).resolve().parents[2] / "README.md"


def test_the_readme_shows_the_main_jobs_output(tmp_path, capsys):
    block = README.read_text().split("```text\n$ ddvp march paper_pendulum\n")[1]
    shown = block.split("```")[0].splitlines()
    assert main(["march", "paper_pendulum", "--no-plot", "--no-progress",
                 "--out", str(tmp_path / "run")]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert len(printed) == len(shown)
    assert printed[:-1] == shown[:-1]
    assert printed[-1].startswith("  build ") and shown[-1].startswith("  build ")
