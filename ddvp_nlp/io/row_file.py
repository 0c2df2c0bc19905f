"""A grid's result file: a CSV with one row per finished task.

Rows are appended and flushed one by one as they arrive, so an interrupted grid keeps every
finished row (that is what resume reads back); at the end the file is rewritten atomically in
task order. Reading gives the rows as strings; a :class:`ddvp_nlp.studies.grid.RowSchema`
types them again.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path


def read_csv(path: str | os.PathLike, *, missing_ok: bool = True) -> list[dict]:
    """The rows of a CSV as dicts of strings; ``[]`` for a missing file if ``missing_ok``."""
    path = Path(path)
    if missing_ok and not path.exists():
        return []
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


@contextmanager
def appending(path: str | os.PathLike, columns: Sequence[str], *,
              fresh: bool) -> Iterator[Callable[[dict], None]]:
    """``append(row)`` writing one row and flushing it; ``fresh`` starts the file with its
    header, else the rows go after the ones already there."""
    with open(path, "w" if fresh else "a", newline="") as handle:
        writer = csv.DictWriter(handle, columns, extrasaction="ignore")
        if fresh:
            writer.writeheader()
            handle.flush()

        def append(row: dict) -> None:
            writer.writerow(row)
            handle.flush()  # a row on disk survives an interrupt or a dying process

        yield append


def rewrite_csv(path: str | os.PathLike, columns: Sequence[str], rows: Iterable[dict]) -> None:
    """Replace the file, atomically, by ``rows`` in the order given."""
    path = Path(path)
    scratch = path.with_suffix(path.suffix + ".tmp")
    with open(scratch, "w", newline="") as handle:
        writer = csv.DictWriter(handle, columns, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow(row)
    os.replace(scratch, path)
