"""Every ``ddvp periodic`` line of the docs' command blocks, run as written, with what the docs
say of it checked: orbit counts, energies, indices, the bifurcation (issue 46: the guide's CR3BP
family command had failed to find its first orbit since the accuracy verdicts of issue 27 were
merged, while the docs only parsed it)."""

import json
import re
import shlex
from pathlib import Path

import pytest

from ddvp_nlp.cli import main

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def documented_lines() -> list[str]:
    """The ``ddvp periodic`` lines of the pages' ``bash`` blocks (the comment after ``#``
    dropped); a placeholder such as ``SCENE`` is a synopsis, not a command."""
    found = []
    for page in PAGES:
        for block in re.findall(r"```bash\n(.*?)```", page.read_text(), flags=re.S):
            for line in block.splitlines():
                command = line.split("#")[0].strip()
                if command.startswith("ddvp periodic ") and "SCENE" not in command:
                    found.append(command)
    return found


def bifurcation_row(nodes: int) -> dict:
    """The CR3BP row of ``docs/periodic/bifurcations.md``'s table at ``N = nodes``."""
    text = (ROOT / "docs" / "periodic" / "bifurcations.md").read_text()
    cells = re.search(rf"^\| {nodes} \| (\d+) \| (-[\d.]+) \|", text, flags=re.M)
    return {"orbits": int(cells.group(1)), "energy": float(cells.group(2))}


def _stability(folder: Path) -> dict:
    [path] = folder.glob("runs/*/stability.json")
    return json.loads(path.read_text())


def _figure_eight(out: str, folder: Path) -> None:
    """The guide: "stable: indices -0.5952, 1.99720" (the exact flow's)."""
    data = _stability(folder)
    assert data["verdict"] == "stable" and data["exact"]["verdict"] == "stable"
    exact = sorted(k[0] for k in data["exact"]["indices"])
    assert exact == pytest.approx([-0.5952, 1.99720], abs=6e-5)


def _henon_heiles_stability(out: str, folder: Path) -> None:
    """The guide: "multipliers, indices, verdict, exact check"."""
    assert "stability: stable" in out and "exact flow: stable" in out
    assert len(_stability(folder)["indices"]) == 1


def _halo_birth(out: str, folder: Path) -> None:
    """The guide: "the L1 Lyapunov family to the halo birth"; bifurcations.md's N = 200 row
    (the scene's 201 nodes): its orbit count and branch point."""
    row = bifurcation_row(200)
    assert f"left the energy range after {row['orbits']} orbits" in out
    found = re.search(r"branch point at E = (-[\d.]+)", out)
    assert found and abs(float(found.group(1)) - row["energy"]) < 1e-9


def _halo_switch(out: str, folder: Path) -> None:
    """switching.md: bifurcations.md's N = 200 row's branch point,
    both halves of 20 orbits, mirror images (equal energies and periods, to 1e-8)."""
    row = bifurcation_row(200)
    found = re.search(r"switched at bifurcation 1 \(branch point at E = (-[\d.]+); kernel "
                      r"residual ([\d.e+-]+)\): ([+-]q3): 20 orbits, ([+-]q3): 20 orbits", out)
    assert found and abs(float(found.group(1)) - row["energy"]) < 1e-9
    assert float(found.group(2)) < 1e-6 and {found.group(3), found.group(4)} == {"+q3", "-q3"}
    # each half on the grid its period target asks for (switching.md: 380 intervals)
    assert out.count("orbits = 20 reached; 380 intervals for relative period error 3e-05 "
                     "(estimated 8.2e-05 on 200; largest along the half 2.3e-05); 20 orbits "
                     "in") == 2
    halves = out.split("\nbranch ")[1:]
    first = [re.search(r"^  E = (-[\d.]+) +T = ([\d.]+)", h, flags=re.M) for h in halves]
    assert abs(float(first[0].group(1)) - -1.587129814) < 1e-8
    assert abs(float(first[0].group(2)) - 2.743130274) < 1e-8
    assert abs(float(first[0].group(1)) - float(first[1].group(1))) < 1e-8
    assert (folder / "runs").is_dir()


def _doubling_switch(out: str, folder: Path) -> None:
    """switching.md: the period doubling at E = 0.135339915726, one branch of 20 orbits (the two
    signs one orbit shifted by half its period), its first orbit's energy and period."""
    assert "period doubling at E = 0.135339915726" in out
    assert "the two signs give one orbit shifted by half its period" in out
    assert "+-q1: 20 orbits of twice the period" in out
    assert out.count("orbits = 20 reached; 20 orbits in") == 1
    first = re.search(r"^  E = ([\d.]+) +T = ([\d.]+)", out.split("\nbranch 1 ")[1], flags=re.M)
    assert abs(float(first.group(1)) - 0.1356536225) < 1e-8
    assert abs(float(first.group(2)) - 15.62564765) < 1e-6
    assert list(folder.glob("runs/*/branch-1")) and not list(folder.glob("runs/*/branch-2"))


def _henon_heiles_follow(out: str, folder: Path) -> None:
    """The README: the family followed from E = 0.02 to 0.1 (its orbits stable)."""
    assert re.search(r"left the energy range after \d+ orbits", out)
    energies = [float(e) for e in re.findall(r"^E = ([\d.]+)", out, flags=re.M)]
    assert energies[0] == 0.02 and 0.09 < energies[-1] <= 0.1
    assert "unstable" not in out


def _hill_family(out: str, folder: Path) -> None:
    """The guide: "Hill's Lyapunov family: 44 orbits, index ~1970" (N = 400, the scene's)."""
    assert "left the energy range after 44 orbits" in out
    first = re.search(r"^E = -2.14 +T = ([\d.]+) +unstable +indices ([\d.]+)", out, flags=re.M)
    assert first and abs(float(first.group(1)) - 3.0396555) < 1e-4
    assert abs(float(first.group(2)) - 1970.3) < 2
    assert out.count("(exact flow: unstable") == 44


def _hill_search(out: str, folder: Path) -> None:
    """docs/periodic/search.md: 6 orbits of one return at E = -2.14 (since the returns' bound;
    13 before), the Lyapunov pair (T = 3.039655464, index 1970.295: the two differ in the
    eighth digit, 1970.2952 and 1970.2953, the round-off of an index of 2000) refined on the
    grid, the retrograde orbit (T = 0.4993825627)."""
    assert "6 periodic orbit(s) found" in out
    assert out.count("T = 3.039655464  index 1970.295") == 2
    assert "T = 0.4993825627  index 1.7424598" in out
    assert out.count("grid accurate: T = 3.0397") == 2


def _hill_search_none(out: str, folder: Path) -> None:
    """docs/periodic/search.md step 5: without the symmetry, 5 orbits, the Lyapunov pair among
    them from the libration points' linearised orbits."""
    assert "5 periodic orbit(s) found" in out
    assert "the linearised orbits about 3 critical points of the line" in out
    assert out.count("T = 3.039655464  index 1970.295") == 2
    assert "T = 0.4993825627  index 1.7424598" in out


CLAIMS = {
    "ddvp periodic henon_heiles --stability": _henon_heiles_stability,
    "ddvp periodic figure_eight --stability": _figure_eight,
    "ddvp periodic cr3bp --energy -1.5935 --follow -1.585 --step 0.0005": _halo_birth,
    "ddvp periodic cr3bp --energy -1.5935 --follow -1.585 --step 0.0005 --switch": _halo_switch,
    "ddvp periodic henon_heiles --energy 0.02 --follow 0.1 --step 0.01": _henon_heiles_follow,
    "ddvp periodic henon_heiles --energy 0.13 --follow 0.14 --step 0.005 --switch":
        _doubling_switch,
    "ddvp periodic hill --energy -2.14 --follow -1.90": _hill_family,
    "ddvp periodic hill --search --energy -2.14 --section q2=0": _hill_search,
    "ddvp periodic hill --search --energy -2.14 --section q2=0 --reversing none":
        _hill_search_none,
}


def test_every_documented_line_has_its_claims_here():
    assert set(documented_lines()) == set(CLAIMS)


@pytest.mark.slow(why="study")
@pytest.mark.parametrize("line", sorted(CLAIMS))
def test_the_documented_periodic_command_runs_and_does_what_the_docs_say(line, tmp_path,
                                                                         monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    argv = shlex.split(line)
    assert main(argv[1:] + ["--no-plot"]) == 0, line
    CLAIMS[line](capsys.readouterr().out, tmp_path)
