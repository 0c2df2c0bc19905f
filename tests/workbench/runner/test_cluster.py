"""The route to a cluster: descriptions parsed and checked, a SLURM job script made from one,
and the same ensemble on a multi-worker LocalCluster giving the crossings of one process."""

import numpy as np
import pytest

from ddvp_nlp import InputError, load_scene
from ddvp_nlp.runner.cluster import parse_cluster, start_cluster
from ddvp_nlp.studies.poincare import poincare_section


def test_descriptions_from_the_command_line_and_a_file(tmp_path):
    spec = parse_cluster("slurm:cores=8,memory=16GB,walltime=01:00:00,jobs=4,"
                         "job_extra=--exclusive;--constraint=cpu")
    assert spec.settings["cores"] == 8 and spec.settings["jobs"] == 4
    assert spec.keywords()["job_extra_directives"] == ["--exclusive", "--constraint=cpu"]
    path = tmp_path / "cluster.toml"
    path.write_text('[cluster]\nkind = "slurm"\ncores = 4\nmemory = "8GB"\nqueue = "short"\n')
    assert parse_cluster(str(path)).keywords() == {"cores": 4, "memory": "8GB",
                                                     "queue": "short"}
    for bad, match in (("pbs:cores=2", "kind must be"), ("slurm:cpus=2", "no setting 'cpus'"),
                       ("slurm:cores=two", "cores must be int"), ("slurm:jobs=0", "at least 1"),
                       ("slurm:cores", "NAME=VALUE")):
        with pytest.raises(InputError, match=match):
            parse_cluster(bad)


def test_a_slurm_job_script_is_made_from_a_description():
    pytest.importorskip("dask_jobqueue")
    from dask_jobqueue import SLURMCluster

    spec = parse_cluster("slurm:cores=8,memory=16GB,walltime=02:00:00,queue=long")
    with SLURMCluster(**spec.keywords()) as cluster:
        script = cluster.job_script()
    assert "#SBATCH -p long" in script and "#SBATCH -t 02:00:00" in script
    assert "--nthreads" in script or "--nworkers" in script


@pytest.mark.slow(why="processes")
def test_the_same_ensemble_on_a_local_cluster_gives_the_same_crossings():
    """Two worker processes of a LocalCluster (each loads the scene and its compiled chunk)
    against one process: the same crossings, bit for bit (the same compiled arithmetic)."""
    system = load_scene("henon_heiles").system
    options = dict(section="q1=0", orbits=6, tau0=0.05, t_end=300.0, seed=3)
    alone = poincare_section(system, 0.125, workers=1, **options)
    with start_cluster(parse_cluster("local:workers=3,threads=1")) as cluster:
        spread = poincare_section(system, 0.125, scene="henon_heiles",
                                  scheduler=cluster.scheduler_address, **options)
    assert alone.points.shape[0] > 50
    for name in ("points", "times", "orbit", "energy_errors", "steps"):
        assert np.array_equal(getattr(alone, name), getattr(spread, name)), name
    assert alone.statuses == spread.statuses


@pytest.mark.slow(why="processes")
def test_the_command_line_runs_the_section_on_a_cluster_it_starts(tmp_path, capsys):
    """``ddvp poincare --cluster local:workers=2``: the cluster started for the run, the
    orbits marched on its workers, the crossings those of one process (``--workers 1``)."""
    from ddvp_nlp.cli import main

    common = ["poincare", "henon_heiles", "--energy", "0.125", "--orbits", "6", "--t-end",
              "300", "--tau0", "0.05", "--seed", "3", "--no-plot"]
    assert main([*common, "--workers", "1", "--out", str(tmp_path / "one")]) == 0
    assert main([*common, "--cluster", "local:workers=2", "--out", str(tmp_path / "two")]) == 0
    one, two = (np.load(tmp_path / name / "section.npz") for name in ("one", "two"))
    assert one["points"].shape[0] > 50
    for name in one.files:
        assert np.array_equal(one[name], two[name]), name


@pytest.mark.parametrize("argv, message", [
    (["poincare", "henon_heiles", "--energy", "0.1", "--cluster", "pbs:cores=2"],
     "--cluster: the kind must be one of local, slurm"),
    (["sweep", "kepler", "--grid", "e=0.1,0.2", "--cluster", "local:workers=0"],
     "workers must be at least 1"),
    (["stress", "--quick", "--cluster", "local:workers=2", "--scheduler", "tcp://h:1"],
     "give --cluster"),
    (["compare", "harmonic", "--cluster", "nowhere.toml"], "--cluster nowhere.toml"),
])
def test_a_bad_cluster_option_exits_2_naming_it(argv, message, capsys):
    from ddvp_nlp.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_every_command_running_on_dask_takes_cluster():
    from ddvp_nlp.cli.parser import build_parser, parse_arguments

    parser = build_parser()
    for argv in (["poincare", "henon_heiles", "--energy", "0.1"], ["sweep", "kepler"],
                 ["stress"], ["compare", "harmonic"], ["reproduce"]):
        assert parse_arguments(parser, [*argv, "--cluster", "local"]).cluster == "local"
