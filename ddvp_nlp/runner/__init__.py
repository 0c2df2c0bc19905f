"""The runner: many independent tasks, here, on local worker processes or on a Dask cluster
(``tasks.py``, ``cluster.py``), their rows journalled to a CSV file as they finish, each with a
checksum and a fingerprint of what it was computed from, so that a killed run resumes from it
and a torn or foreign row is never reused (``journal.py``).

Rules: the runner imports the library's public names and ``io``; never ``scenes``, ``studies``
or ``cli``. A task names its function by ``"module:function"``: it pickles small and every
worker imports it by itself.
"""

from typing import TYPE_CHECKING

from ..cache import lazy_exports

# name -> module (relative to this package) that defines it
PUBLIC = {
    "Task": "tasks", "Workers": "tasks", "run_tasks": "tasks",
    "ClusterSpec": "cluster", "parse_cluster": "cluster", "start_cluster": "cluster",
    "run_journalled": "journal", "read_csv": "journal",
}

if TYPE_CHECKING:  # for readers and static tools; loaded on first use below
    from .cluster import ClusterSpec, parse_cluster, start_cluster
    from .journal import read_csv, run_journalled
    from .tasks import Task, Workers, run_tasks

__getattr__, __dir__ = lazy_exports(__name__, PUBLIC)

__all__ = ["ClusterSpec", "Task", "Workers", "parse_cluster", "read_csv", "run_journalled",
           "run_tasks", "start_cluster"]
