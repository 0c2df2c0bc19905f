"""The runner: many independent tasks, here, on local worker processes or on a Dask cluster
(``tasks.py``, ``cluster.py``), their rows journalled to a CSV file as they finish, each with a
checksum and a fingerprint of what it was computed from, so that a killed run resumes from it
and a torn or foreign row is never reused (``journal.py``).

Rules: the runner imports the library's public names and ``io``; never ``scenes``, ``studies``
or ``cli``. A task names its function by ``"module:function"``: it pickles small and every
worker imports it by itself.
"""
