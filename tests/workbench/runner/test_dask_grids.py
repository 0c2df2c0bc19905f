"""Grids of independent runs on a Dask cluster: same rows as in-process, failures recorded,
nothing lost when a worker dies, resume without redoing finished rows."""

import csv
from pathlib import Path

import dask
import numpy as np
import pytest

from ddvp_nlp import Compilation, InputError
from ddvp_nlp.cli import main
from ddvp_nlp.runner.journal import JournalWarning, journal_path, run_journalled
from ddvp_nlp.runner.tasks import Task, Workers, describe_error, run_tasks
from ddvp_nlp.solvers.compiler import find_compiler
from ddvp_nlp.studies.stress_report import stress
from ddvp_nlp.studies.sweep import SweepSpec, parse_axis, sweep_cases
from ddvp_nlp.studies.sweep_file import load_grid_file

CLUSTER_CONFIG = {"distributed.scheduler.allowed-failures": 1,
                  "distributed.scheduler.worker-saturation": 1.0}


@pytest.fixture(scope="module")
def cluster():
    from distributed import LocalCluster

    with dask.config.set(CLUSTER_CONFIG):
        local = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                             dashboard_address=None)
    yield local
    local.close()


def _without_timing(rows):
    # the row's checksum covers its run time too
    return [{k: v for k, v in r.items() if k not in ("seconds", "row_sha256")} for r in rows]


def _harmonic_cases():
    return sweep_cases(SweepSpec(scene="harmonic", axes={"w": [1.0, 2.0]},
                                 methods=("vddvp", "midpoint", "rk4", "dop853"),
                                 settings={"t_end": 5.0}))


@pytest.mark.slow(why="processes")
def test_the_same_grid_gives_the_same_rows_wherever_it_runs(tmp_path, cluster):
    cases = _harmonic_cases()
    vm = Compilation(compiler=None)
    here = stress(tmp_path / "here", cases=cases, compilation=vm, name="sweep")
    remote = stress(tmp_path / "remote", cases=cases, compilation=vm,
                    workers=Workers(scheduler=cluster.scheduler_address), name="sweep")
    embedded = stress(tmp_path / "embedded", cases=cases, compilation=vm, workers=Workers(2),
                      name="sweep")
    assert len(here) == 8 and all(r["status"] == "success" for r in here)
    np.testing.assert_equal(_without_timing(remote), _without_timing(here))  # NaN == NaN
    np.testing.assert_equal(_without_timing(embedded), _without_timing(here))
    with open(tmp_path / "remote" / "sweep.csv", newline="") as handle:
        assert [r["key"] for r in csv.DictReader(handle)] == [r["key"] for r in here]


def test_a_task_that_raises_is_retried_once_and_recorded(tmp_path, cluster):
    tasks = [Task("a", "builtins:dict", kwargs={"x": "1"}),
             Task("bad", "math:sqrt", args=(-1.0,)),
             Task("b", "builtins:dict", kwargs={"x": "2"})]
    for where in ({"workers": 1}, {"scheduler": cluster.scheduler_address}):
        rows, ran = run_journalled(tasks, tmp_path / "grid.csv", ["key", "x", "error"],
                             failure_row=lambda task, error: {"x": "", "error": error},
                             parse=dict, resume=False, **where)
        assert ran == 3
        assert [r["x"] for r in rows] == ["1", "", "2"]
        assert rows[1]["error"] == "task_failed: ValueError: math domain error"
        assert describe_error(rows[1]["error"]) == ("task_failed", "ValueError: math domain "
                                                    "error")


def test_killing_a_worker_loses_no_finished_row(tmp_path, cluster):
    path = tmp_path / "grid.csv"
    tasks = [Task(f"t{i}", "builtins:dict", kwargs={"x": str(i)}) for i in range(6)]
    tasks.insert(3, Task("kill", "os:_exit", args=(3,)))  # the worker process dies
    rows, ran = run_journalled(tasks, path, ["key", "x", "error"],
                         failure_row=lambda task, error: {"x": "", "error": error},
                         parse=dict, resume=False, scheduler=cluster.scheduler_address)
    assert ran == 7
    killed = [r for r in rows if r["key"] == "kill"]
    assert killed[0]["error"].startswith("worker_died")
    with open(path, newline="") as handle:
        written = {r["key"]: r for r in csv.DictReader(handle)}
    assert set(written) == {t.key for t in tasks}
    assert [written[f"t{i}"]["x"] for i in range(6)] == [str(i) for i in range(6)]


def test_resume_skips_finished_rows(tmp_path):
    path = tmp_path / "grid.csv"
    calls = []
    tasks = [Task(f"t{i}", "builtins:dict", kwargs={"x": str(i)}) for i in range(4)]
    kwargs = {"failure_row": lambda task, error: {"x": error}, "parse": dict, "workers": 1}
    first, ran = run_journalled(tasks, path, ["key", "x"], **kwargs)
    assert ran == 4
    again, ran = run_journalled(tasks, path, ["key", "x"], **kwargs)
    assert ran == 0 and again == first
    # an interrupted grid: only two rows made it to its journal, no complete grid yet
    with open(path, newline="") as handle:
        kept = list(csv.DictReader(handle))[:2]
    path.unlink()
    (tmp_path / "meta.json").unlink()
    with open(journal_path(path), "w", newline="") as handle:  # its own columns (checks too)
        writer = csv.DictWriter(handle, list(kept[0]))
        writer.writeheader()
        writer.writerows(kept)
    resumed, ran = run_journalled(tasks, path, ["key", "x"], **kwargs)
    assert ran == 2 and resumed == first
    del calls


@pytest.mark.slow(why="processes")
def test_workers_share_the_compiled_cache(tmp_path, cluster):
    """Two workers compiling the same march chunk into one empty cache folder at once."""
    # both runs use the same chunk of 64 steps, so both need the same library
    cases = sweep_cases(SweepSpec(scene="pendulum", axes={"t_end": [3.0, 3.1]},
                                  methods=("vddvp",)))
    cache = tmp_path / "cache"
    rows = stress(tmp_path / "out", cases=cases, compilation=Compilation(cache_dir=str(cache)),
                  workers=Workers(scheduler=cluster.scheduler_address), name="sweep")
    assert [r["status"] for r in rows] == ["success", "success"]
    if find_compiler("auto"):
        libraries = list(cache.glob("chunk_*.so"))  # the march's (accuracy_*.so: the check's)
        assert len(libraries) == 1 and not list(cache.glob("tmp*"))


def test_grid_axes_from_the_command_line():
    assert parse_axis("e", "0.5:0.9:5") == pytest.approx([0.5, 0.6, 0.7, 0.8, 0.9])
    assert parse_axis("tau0", "0.01,0.005") == [0.01, 0.005]
    with pytest.raises(InputError, match=r"^grid e: expected FROM:TO:COUNT or V1,V2,..., "
                                         r"got '0.5:x'$") as refused:  # the study's field
        parse_axis("e", "0.5:x")
    from ddvp_nlp.cli.flags import in_flags  # the command line's words for it

    assert in_flags(str(refused.value), "parse_axis").startswith("--grid e: expected")


GRID = """
scene = "kepler"
methods = ["vddvp", "rk4"]
[settings]
t_end = 6.0
[grid]
e = { from = 0.5, to = 0.6, count = 2 }
tau0 = [0.01]
[bounds]
max_steps = 100000
"""


def test_grid_file(tmp_path):
    path = tmp_path / "grid.toml"
    path.write_text(GRID)
    spec = load_grid_file(path)
    assert spec.axes == {"e": [0.5, 0.6], "tau0": [0.01]} and spec.max_steps == 100000
    cases = sweep_cases(spec)
    assert [c.name for c in cases] == ["e=0.5, tau0=0.01", "e=0.6, tau0=0.01"]
    assert cases[0].settings == {"t_end": 6.0, "e": 0.5} and cases[0].tau == 0.01


@pytest.mark.parametrize("text, message", [
    (GRID.replace("max_steps", "max_step"),
     "unknown key 'bounds.max_step' (known: max_steps, time_limit)"),
    (GRID.replace("count = 2", "count = 2, step = 1"),
     "unknown key 'grid.e.step' (known: from, to, count)"),
    ("seed = 3\n" + GRID, "unknown key 'seed' (known: scene, methods, settings, grid, "
                          "bounds)"),
    (GRID.replace("tau0 = [0.01]", "tau0 = 'fast'"),
     "'grid.tau0' must be a list of numbers or {from, to, count}, got 'fast'"),
    (GRID.replace('"rk4"', '"euler"'), "unknown method 'euler'"),
    (GRID.replace("e = {", "eccentricity = {"), "scene 'kepler' has no parameter "
                                                "'eccentricity'"),
])
def test_bad_grid_files_name_the_key(tmp_path, text, message):
    path = tmp_path / "grid.toml"
    path.write_text(text)
    with pytest.raises(InputError) as error:
        sweep_cases(load_grid_file(path))
    assert message in str(error.value)


def test_sweep_command_resumes(tmp_path, capsys, monkeypatch):
    from ddvp_nlp.studies import stress_report as stress_report

    titles = []
    drawn = stress_report.plot_stress
    monkeypatch.setattr(stress_report, "plot_stress",
                        lambda *a, **k: (titles.append(k["title"]), drawn(*a, **k)))
    out = tmp_path / "sweep"
    command = ["sweep", "harmonic", "--grid", "w=1,2", "--methods", "rk4,dop853", "--set",
               "t_end=3", "--workers", "1", "--no-compile", "--no-progress", "--out", str(out)]
    assert main(command) == 0
    assert capsys.readouterr().out.startswith("sweep: 4 runs")
    # the sweep's figure and report speak of the sweep, not of the stress cases
    assert titles == ["Sweep of harmonic over w"]
    assert (out / "sweep.md").read_text().startswith("# Sweep of harmonic over w\n")
    first = (out / "sweep.csv").read_text()
    assert main(command) == 0
    assert (out / "sweep.csv").read_text().splitlines()[1:] == first.splitlines()[1:]
    assert main(["sweep", "harmonic"]) == 2
    assert "sweep needs SCENE and at least one --grid" in capsys.readouterr().err


def test_run_tasks_in_process_yields_each_outcome():
    outcomes = list(run_tasks([Task("a", "math:sqrt", args=(4.0,)),
                               Task("b", "math:sqrt", args=(-4.0,))], workers=1))
    assert outcomes[0][1:] == (2.0, None)
    assert outcomes[1][1] is None and outcomes[1][2].startswith("task_failed: ValueError")


def test_bad_scheduler_and_workers():
    with pytest.raises(InputError, match="^scheduler must be an address like tcp://host:8786, "
                                         "got 'localhost'$"):
        list(run_tasks([], scheduler="localhost"))
    with pytest.raises(InputError, match="^workers must be a positive integer, got 0$"):
        list(run_tasks([], workers=0))


def _grid(path, tasks, **kwargs):
    return run_journalled(tasks, path, ["key", "x", "status"], parse=dict, workers=1,
                    failure_row=lambda task, error: {"x": "", "status": "task_failed"}, **kwargs)


def test_resume_reruns_a_row_whose_settings_changed(tmp_path):
    path = tmp_path / "grid.csv"
    _grid(path, [Task("a", "builtins:dict", kwargs={"x": "1", "status": "success"})])
    rows, ran = _grid(path, [Task("a", "builtins:dict", kwargs={"x": "2", "status": "success"})])
    assert ran == 1 and rows[0]["x"] == "2"  # same key, other settings: not reused


def test_resume_retries_failed_rows_and_skips_a_torn_line(tmp_path):
    path = tmp_path / "grid.csv"
    tasks = [Task(f"t{i}", "builtins:dict", kwargs={"x": str(i), "status": "success"})
             for i in range(3)]
    _grid(path, tasks)
    text = path.read_text().splitlines()
    text[1] = text[1].replace("success", "task_failed")  # edited by hand: its checksum fails
    # the journal of a first grid killed while appending: a torn last line
    journal_path(path).write_text("\n".join(text[:-1]) + "\n" + text[-1][:4])
    path.unlink()
    (tmp_path / "meta.json").unlink()
    with pytest.warns(JournalWarning, match="line 4 is incomplete"):
        rows, ran = _grid(path, tasks)
    assert ran == 2 and [r["status"] for r in rows] == ["success"] * 3


def test_a_worker_refuses_a_scene_file_other_than_the_planned_one(tmp_path):
    from ddvp_nlp.scenes import load_scene, scene_digest

    scene = tmp_path / "mine.py"
    scene.write_text((Path(__file__).resolve().parents[3] / "problems" / "harmonic.py").read_text())
    digest = scene_digest(str(scene))
    load_scene(str(scene), digest=digest)
    scene.write_text(scene.read_text().replace("w**2", "2 * w**2"))
    with pytest.raises(InputError, match="is not the one this grid was planned with"):
        load_scene(str(scene), digest=digest)


def test_an_unreachable_scheduler_is_refused_quickly():
    from ddvp_nlp.runner.tasks import resolve_scheduler

    with pytest.raises(InputError, match="no Dask scheduler answers at 'tcp://127.0.0.1:9'"):
        resolve_scheduler("tcp://127.0.0.1:9")


def test_a_complete_grid_the_manifest_does_not_vouch_for_gives_no_row(tmp_path):
    """A rerun had reused sweep.csv rows whose file no longer matched its meta.json (rows
    edited and re-signed: a row's checksum is not a signature); the manifest's SHA-256 of the
    whole file decides now."""
    from ddvp_nlp.runner.journal import row_checksum

    path = tmp_path / "grid.csv"
    tasks = [Task(f"t{i}", "builtins:dict", kwargs={"x": str(i), "status": "success"})
             for i in range(3)]
    _grid(path, tasks)
    with open(path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    columns = list(rows[0])
    rows[0]["x"] = "forged"
    rows[0]["row_sha256"] = row_checksum(rows[0], columns)  # a valid row, a changed file
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, columns, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    with pytest.warns(JournalWarning, match="is not the file its manifest describes"):
        again, ran = _grid(path, tasks)
    assert ran == 3 and [r["x"] for r in again] == ["0", "1", "2"]


def test_a_key_twice_in_a_grid_file_is_refused(tmp_path):
    """Of two valid rows with one key the last had silently won."""
    path = tmp_path / "grid.csv"
    tasks = [Task(f"t{i}", "builtins:dict", kwargs={"x": str(i), "status": "success"})
             for i in range(2)]
    _grid(path, tasks)
    lines = path.read_text().splitlines()
    journal_path(path).write_text("\n".join([lines[0], lines[1], lines[2], lines[1]]) + "\n")
    with pytest.raises(InputError, match="gives the key 't0' twice \\(lines 2 and 4\\)"):
        _grid(path, tasks)
