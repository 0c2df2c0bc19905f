"""Reading a grid's result file: a CSV with one row per finished task, as strings (a
`ddvp_nlp.studies.grid.RowSchema` types them again; ``studies/grid.py`` writes them
through the output layer and checks every row it reuses)."""

from __future__ import annotations

import csv
import os
from pathlib import Path


def read_csv(path: str | os.PathLike, *, missing_ok: bool = True) -> list[dict]:
    """The rows of a CSV as dicts of strings; ``[]`` for a missing file if ``missing_ok``."""
    path = Path(path)
    if missing_ok and not path.exists():
        return []
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))
