"""The guide's section 10 run as it stands: its Python blocks in one namespace, in order, and
its commands through ``main`` (in a scratch folder); what each prints is checked."""

import re
import shlex
from pathlib import Path

import numpy as np
import pytest

from ddvp_nlp.cli import main

GUIDE = Path(__file__).resolve().parents[2] / "docs" / "guide.md"


def section() -> str:
    text = GUIDE.read_text()
    start = text.index("## 10. Output times, events")
    end = text.find("\n## ", start + 1)
    return text[start:end if end > 0 else None]


def blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", section(), flags=re.S)


def test_the_section_has_each_item_of_issue_31():
    text = section()
    for item in ("t_eval", "events", "Scene.march", "--resume", "Collect", "--cluster",
                 "--progress", "--keep-every"):
        assert item in text, item
    assert len(blocks("python")) == 2 and len(blocks("bash")) == 4


def test_the_python_examples_run_and_print_what_they_say(capsys):
    namespace = {}
    for code in blocks("python"):
        exec(compile(code, str(GUIDE), "exec"), namespace)  # noqa: S102 - the guide's own code
    out = capsys.readouterr().out.splitlines()
    sol = namespace["sol"]
    assert out[0].startswith("EVENT") and sol.t_events[0].size == 2
    assert np.all(np.abs(sol.z_events[0][:, 0]) < 1e-12)
    assert out[1] == "(6, 2)"
    assert int(out[2].split()[0]) == sol.t.size - 1
    worst = namespace["worst"]
    assert isinstance(worst, float) and 0 <= worst < 1e-2  # one number, the largest drift


def commands(cluster: bool) -> list[list[str]]:
    """The section's command lines that start a cluster (``--cluster``), or the others."""
    lines = (shlex.split(line) for block in blocks("bash") for line in block.splitlines())
    return [argv for argv in lines if ("--cluster" in argv) == cluster]


def test_the_commands_run(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    for argv in commands(cluster=False):
        assert argv[0] == "ddvp"
        assert main(argv[1:]) == 0, shlex.join(argv)
    out = capsys.readouterr().out
    assert "event 0 'q1' (up): 2 crossings" in out and "ended the march" in out
    resumed = np.load(tmp_path / "runs" / "resume-demo" / "result.npz")
    assert resumed["t"][-1] == pytest.approx(20.0)
    kept = np.load(tmp_path / "runs" / "kept-demo" / "result.npz")
    assert kept["t"][-1] >= 2e4 and 3900 <= kept["t"].size <= 4100  # every 100th of about 4e5


# The section's two cluster lines start a local Dask cluster each (15 s of CPU of the 17 s the
# section's commands took); the default run parses them with the real parser
# (tests/docs/test_doc_blocks.py), and runs grids on a local cluster
# (tests/workbench/runner/test_dask_grids.py).
@pytest.mark.slow(why="processes")
def test_the_cluster_commands_run(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    lines = commands(cluster=True)
    assert len(lines) == 2
    for argv in lines:
        assert main(argv[1:]) == 0, shlex.join(argv)
    out = capsys.readouterr().out
    assert "6 orbits" in out and "0 orbits failed" in out
