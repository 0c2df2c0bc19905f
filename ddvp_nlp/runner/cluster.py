"""From one machine to a batch-scheduled cluster: a Dask cluster described on the command line
or in a file, started here, its scheduler's address handed to the grid and ensemble runners
(``grid.run_tasks``), which already run on any Dask scheduler.

A description is ``KIND`` with ``NAME=VALUE`` settings, given as ``--cluster
"slurm:cores=8,memory=16GB,walltime=01:00:00,jobs=4"`` or ``--cluster FILE.toml`` with a table
``[cluster]`` holding ``kind = "slurm"`` and the same names. Kinds: ``local``
(``dask.distributed.LocalCluster``: ``workers``, ``threads``) and ``slurm``
(``dask_jobqueue.SLURMCluster``, the optional extra ``pip install ddvp-nlp[cluster]``:
``cores``, ``memory``, ``processes``, ``queue``, ``account``, ``walltime``, ``job_extra``
(sbatch lines, ``;``-separated), and ``jobs``, the batch jobs to submit). Each SLURM job runs
``processes`` Dask workers; every worker loads the scene by name or file and its compiled chunk
from its own compile cache (``docs/guide.md``, section 10; ``docs/from-scipy.md``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError

KINDS = {"local": {"workers": int, "threads": int},
         "slurm": {"cores": int, "memory": str, "processes": int, "queue": str,
                   "account": str, "walltime": str, "job_extra": str, "jobs": int}}


@dataclass(frozen=True)
class ClusterSpec:
    """A checked cluster description: ``kind`` and its ``settings`` (typed)."""

    kind: str
    settings: dict = field(default_factory=dict)

    def keywords(self) -> dict:
        """The cluster class's keyword arguments (``jobs`` and ``workers`` scale it instead)."""
        s = dict(self.settings)
        if self.kind == "local":
            return {"n_workers": s.get("workers", 2), "threads_per_worker": s.get("threads", 1),
                    "processes": True}
        s.pop("jobs", None)
        if "job_extra" in s:
            s["job_extra_directives"] = [line.strip() for line in s.pop("job_extra").split(";")
                                         if line.strip()]
        s.setdefault("cores", 1)
        s.setdefault("memory", "2GB")
        return s


def parse_cluster(text: str) -> ClusterSpec:
    """``KIND[:NAME=VALUE,...]`` or a ``.toml`` file's ``[cluster]`` table, checked: an
    `InputError` names the setting and the value."""
    if text.endswith(".toml") or Path(text).is_file():
        return _from_file(Path(text))
    kind, _, rest = text.partition(":")
    pairs = {}
    for item in filter(None, (part.strip() for part in rest.split(","))):
        name, sep, value = item.partition("=")
        if not sep:
            raise InputError(f"--cluster: settings are NAME=VALUE, got {item!r}")
        pairs[name.strip()] = value.strip()
    return _checked(kind.strip(), pairs, "--cluster")


def _from_file(path: Path) -> ClusterSpec:
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    try:
        table = tomllib.loads(path.read_text()).get("cluster")
    except (OSError, ValueError) as exc:
        raise InputError(f"--cluster {path}: {exc}") from None
    if not isinstance(table, dict) or "kind" not in table:
        raise InputError(f"--cluster {path}: needs a [cluster] table with kind = \"slurm\" or "
                         "\"local\"")
    table = dict(table)
    return _checked(str(table.pop("kind")), table, f"--cluster {path}")


def _checked(kind: str, pairs: dict, where: str) -> ClusterSpec:
    if kind not in KINDS:
        raise InputError(f"{where}: the kind must be one of {', '.join(KINDS)}, got {kind!r}")
    settings = {}
    for name, value in pairs.items():
        kind_of = KINDS[kind].get(name)
        if kind_of is None:
            raise InputError(f"{where}: a {kind} cluster has no setting {name!r} (it has: "
                             f"{', '.join(KINDS[kind])})")
        try:
            settings[name] = kind_of(value)
        except (TypeError, ValueError):
            raise InputError(f"{where}: {name} must be {kind_of.__name__}, got {value!r}") \
                from None
        if kind_of is int and settings[name] < 1:
            raise InputError(f"{where}: {name} must be at least 1, got {value!r}")
    return ClusterSpec(kind, settings)


def start_cluster(spec: ClusterSpec):
    """The cluster started (SLURM: ``jobs`` batch jobs submitted); use it as a context
    manager, its ``scheduler_address`` goes to ``scheduler=``."""
    if spec.kind == "local":
        from dask.distributed import LocalCluster

        return LocalCluster(**spec.keywords())
    try:
        from dask_jobqueue import SLURMCluster
    except ImportError:
        raise InputError("a slurm cluster needs dask-jobqueue: pip install "
                         "'ddvp-nlp[cluster]'") from None
    cluster = SLURMCluster(**spec.keywords())
    cluster.scale(jobs=spec.settings.get("jobs", 1))
    return cluster
