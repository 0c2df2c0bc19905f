"""From one machine to a batch-scheduled cluster: a Dask cluster described on the command line
or in a file, started here, its scheduler's address handed to the table and ensemble runners
(``tasks.run_tasks``), which already run on any Dask scheduler.

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

import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError

KINDS = {"local": {"workers": int, "threads": int},
         "slurm": {"cores": int, "memory": str, "processes": int, "queue": str,
                   "account": str, "walltime": str, "job_extra": str, "jobs": int}}
# The most of each count a description may ask for (workers: as many as fit in memory, the
# check of --workers).
MAXIMA = {"threads": 1024, "cores": 4096, "processes": 4096, "jobs": 10_000}
# What a text setting must look like: it ends up in a batch script, so no line breaks, no
# shell; memory as Dask reads it, walltime as sbatch does.
PATTERNS = {"memory": r"[0-9]+(\.[0-9]+)?\s*([kKMGTP]i?B|B)",
            "walltime": r"([0-9]+-)?[0-9]{1,4}(:[0-9]{2}){0,2}",
            "queue": r"[A-Za-z0-9_.,+-]{1,128}", "account": r"[A-Za-z0-9_.+-]{1,128}",
            "job_extra": r"[A-Za-z0-9_.,:;=+/@ -]{1,2000}"}
# Largest cluster file read: a description is a few lines (/dev/zero, a FIFO or a 3 GB file
# had been read without a bound).
CLUSTER_FILE_LIMIT = 64 << 10


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
    """``KIND[:NAME=VALUE,...]`` or a ``.toml`` file's ``[cluster]`` table, checked as the
    command line's options are: an `InputError` names the setting and the value. A file is
    read only if it is a regular file of at most `CLUSTER_FILE_LIMIT` bytes."""
    if not isinstance(text, str) or not text.strip():
        raise InputError(f"--cluster must be KIND[:NAME=VALUE,...] or a .toml file, got "
                         f"{text!r}")
    kind, _, rest = text.partition(":")
    if kind.strip() not in KINDS and (text.endswith(".toml") or "/" in text
                                      or Path(text).exists() or Path(text).is_symlink()):
        return _from_file(Path(text))
    pairs = {}
    for item in filter(None, (part.strip() for part in rest.split(","))):
        name, sep, value = item.partition("=")
        if not sep:
            raise InputError(f"--cluster: settings are NAME=VALUE, got {item!r}")
        if name.strip() in pairs:
            raise InputError(f"--cluster: {name.strip()} is given twice; give each setting once")
        pairs[name.strip()] = value.strip()
    return _checked(kind.strip(), pairs, "--cluster")


def _from_file(path: Path) -> ClusterSpec:
    from ..validation import read_limited

    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    try:
        data = read_limited(path, CLUSTER_FILE_LIMIT, what="the file")
    except InputError as exc:
        raise InputError(f"--cluster {path}: {exc}") from None
    try:
        table = tomllib.loads(data.decode("utf-8")).get("cluster")
    except UnicodeDecodeError as exc:
        raise InputError(f"--cluster {path}: not UTF-8 text (byte {exc.start})") from None
    except (ValueError, RecursionError) as exc:
        raise InputError(f"--cluster {path}: not a TOML file: {str(exc)[:200]}") from None
    if not isinstance(table, dict) or "kind" not in table:
        raise InputError(f"--cluster {path}: needs a [cluster] table with kind = \"slurm\" or "
                         "\"local\"")
    table = dict(table)
    kind = table.pop("kind")
    if not isinstance(kind, str):
        raise InputError(f"--cluster {path}: kind must be \"slurm\" or \"local\", got "
                         f"{kind!r:.80}")
    return _checked(kind, table, f"--cluster {path}")


def _checked(kind: str, pairs: dict, where: str) -> ClusterSpec:
    if kind not in KINDS:
        raise InputError(f"{where}: the kind must be one of {', '.join(KINDS)}, got {kind!r:.80}")
    settings = {}
    for name, value in pairs.items():
        kind_of = KINDS[kind].get(name)
        if kind_of is None:
            raise InputError(f"{where}: a {kind} cluster has no setting {name!r:.80} (it has: "
                             f"{', '.join(KINDS[kind])})")
        settings[name] = (_count if kind_of is int else _text)(where, name, value)
    return ClusterSpec(kind, settings)


def _count(where: str, name: str, value) -> int:
    """A whole number, from the command line's digits or a TOML integer (``2.9`` had become 2
    and ``workers=100000`` passed where ``--workers 100000`` is refused)."""
    from .tasks import check_workers

    if isinstance(value, str) and re.fullmatch(r"[0-9]{1,18}", value.strip()):
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{where}: {name} must be int (a whole number), got {value!r:.80}")
    if value < 1:
        raise InputError(f"{where}: {name} must be at least 1, got {value!r}")
    if name == "workers":
        try:
            check_workers(value)
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None
    elif value > MAXIMA[name]:
        raise InputError(f"{where}: {name} must be at most {MAXIMA[name]}, got {value!r}")
    return value


def _text(where: str, name: str, value) -> str:
    """A text setting of the shape `PATTERNS` gives it."""
    if not isinstance(value, str) or not re.fullmatch(PATTERNS[name], value.strip()):
        raise InputError(f"{where}: {name} must be {_SHAPES[name]}, got {value!r:.80}")
    return value.strip()


_SHAPES = {"memory": "an amount such as 16GB", "walltime": "a time such as 01:00:00",
           "queue": "a partition name", "account": "an account name",
           "job_extra": "sbatch options separated by ';' (no line breaks or shell)"}


def start_cluster(spec: ClusterSpec):
    """The cluster started (SLURM: ``jobs`` batch jobs submitted); use it as a context
    manager, its ``scheduler_address`` goes to ``scheduler=``."""
    if spec.kind == "local":
        from dask.distributed import LocalCluster

        return LocalCluster(**spec.keywords())
    check_available(spec)
    from dask_jobqueue import SLURMCluster

    cluster = SLURMCluster(**spec.keywords())
    cluster.scale(jobs=spec.settings.get("jobs", 1))
    return cluster


def check_available(spec: ClusterSpec) -> None:
    """What a cluster of this kind needs here, before anything starts: a slurm cluster needs
    dask-jobqueue and ``sbatch`` on the ``PATH`` (without it the command had printed the
    error and hung); an `InputError` says what is missing."""
    if spec.kind != "slurm":
        return
    try:
        import dask_jobqueue  # noqa: F401
    except ImportError:
        raise InputError("a slurm cluster needs dask-jobqueue: pip install "
                         "'ddvp-nlp[cluster]'") from None
    if shutil.which("sbatch") is None:
        raise InputError("--cluster slurm: sbatch was not found on the PATH (a slurm cluster "
                         "submits its workers with sbatch): run on the cluster's login node, "
                         "or use --cluster local")
