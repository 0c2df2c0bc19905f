"""`ddvp periodic --search` on Hill's problem (tests/library/periodic/hill_scene.py): the orbit
list written and printed; a failed orbit of `ddvp periodic` prints no period."""

import json
from pathlib import Path

from ddvp_nlp.cli.main import main


def test_the_command_writes_the_orbit_list(tmp_path, capsys):
    scene = Path(__file__).resolve().parents[2] / "library" / "periodic" / "hill_scene.py"
    code = main(["periodic", str(scene), "--search", "--energy", "-1.663", "--section", "q2=0",
                 "--seeds", "120", "--max-returns", "1", "--no-plot", "--out",
                 str(tmp_path / "out")])
    printed = capsys.readouterr().out
    assert code == 0, printed
    rows = (tmp_path / "out" / "orbits.csv").read_text().splitlines()
    assert rows[0].startswith("period,index,verdict")
    assert any(abs(float(row.split(",")[0]) - 0.6471579) < 1e-6 for row in rows[1:]), rows
    assert "T = 0.6471579313" in printed
    # the session-56 trial: a count that contradicts the option given is a defect
    header = rows[0].split(",")
    returns = [int(row.split(",")[header.index("returns")]) for row in rows[1:]]
    assert max(returns) <= 1, returns
    assert "orbits of up to 1 upward crossings per period" in printed
    assert "on the symmetric line (" in printed
    meta = json.loads((tmp_path / "out" / "meta.json").read_text())
    assert sum(way["seeds"] for way in meta["seeds_by_way"]) == meta["seeds"]
    assert len(meta["grid_verdicts"]) == len(rows) - 1
    assert meta["verdicts"] == [row.split(",")[2] for row in rows[1:]]
    assert "grid accurate: T = 0.647" in printed
    # a reported duplicate: T = 3.21023318 listed twice. They are the Lyapunov orbits about the
    # two libration points, mirror images under (q, p) -> (-q, -p) (test_search.py), so two
    # orbits; the list printed both lines alike, told apart only in orbits.csv. Each line now
    # says where the orbit crosses the section upwards.
    pair = [line for line in printed.splitlines() if "T = 3.21023318 " in line]
    assert len(pair) == 2, printed
    assert all("up through " in line for line in pair), pair
    assert sorted(line.split("up through ")[1].split(";")[0] for line in pair) == [
        "q1 = -0.8217168, p1 = 0", "q1 = 0.4704912, p1 = 0"], pair


def test_periodic_stability_prints_its_accuracy_check(tmp_path, capsys):
    """The trial: `ddvp periodic --stability` printed no accuracy verdict (march and bvp do)."""
    code = main(["periodic", "pendulum", "--energy", "0.5", "--nodes", "41", "--stability",
                 "--no-plot", "--out", str(tmp_path / "out")])
    printed = capsys.readouterr().out
    assert code == 0, printed
    meta = json.loads((tmp_path / "out" / "meta.json").read_text())
    verdict = meta["accuracy"]["verdict"] if isinstance(meta["accuracy"], dict) else None
    assert f"  accuracy check: {verdict or 'accurate'} (" in printed, printed


def test_an_orbit_not_found_prints_no_period(tmp_path, capsys):
    """Henon-Heiles below its well's bottom on the section x = 0: the default start escapes,
    no orbit is found, and no period is printed (issue 46: one was)."""
    code = main(["periodic", "henon_heiles", "--energy", "-0.01", "--section", "q1=0",
                 "--nodes", "41", "--solver", "newton", "--no-plot", "--out",
                 str(tmp_path / "out")])
    printed = capsys.readouterr().out
    assert code == 1
    assert "no period: no orbit was found at E = -0.01" in printed


def test_the_searchs_flags_without_search_are_refused_by_name(tmp_path, capsys):
    """--seeds, --max-returns, --reversing, --jitter and --workers are read by the search only;
    without --search they had been ignored unsaid. Refused (exit 2) before the scene is
    loaded."""
    for flag, value in (("--seeds", "5"), ("--max-returns", "2"), ("--reversing", "none"),
                        ("--jitter", "0"), ("--workers", "2")):
        code = main(["periodic", "no_such_scene", "--energy", "0.5", flag, value, "--out",
                     str(tmp_path / "out")])
        err = capsys.readouterr().err
        assert code == 2 and f"{flag} {value}: read with --search only" in err, err
        assert not (tmp_path / "out").exists()
