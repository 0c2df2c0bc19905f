"""The journal of a run of many tasks: one CSV row per finished task, appended as it arrives
(so an interrupted run keeps every finished row) and checked when read back (a checksum per
row and a fingerprint of the settings and the scene file it was computed with), so that a second
call with the same tasks runs only the missing ones (resume) and never reuses a torn, edited or
foreign row. At the end the file is rewritten in task order, holding exactly the rows of this
run; a `RowSchema` types the rows read back.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from ..solution import Status
from .tasks import Task, run_tasks

__all__ = ["JournalInterrupted", "JournalWarning", "RowSchema", "commit_journal", "journal_path",
           "read_csv", "read_rows_back", "row_checksum", "row_lines", "run_journalled", "signed"]


@dataclass(frozen=True)
class RowSchema:
    """A task table's columns and which of them hold numbers or flags. `parse` is
    the one place a row read back from the result file gets its types again."""

    columns: tuple[str, ...]
    floats: tuple[str, ...] = ()
    integers: tuple[str, ...] = ()
    flags: tuple[str, ...] = ()

    def parse(self, row: dict) -> dict:
        """``row`` with numbers as numbers and flags as ``True``/``False`` (``""`` if unset)."""
        row = dict(row)
        for key in self.floats:
            row[key] = float(row[key])
        for key in self.integers:
            row[key] = int(row[key])
        for key in self.flags:
            row[key] = {"True": True, "False": False}.get(row[key], "")
        return row

    def read(self, path) -> list[dict]:
        """The typed rows of a result file written with this schema."""
        return [self.parse(row) for row in read_csv(path, missing_ok=False)]


class JournalWarning(UserWarning):
    """A row of a table file that is not reused (and why): shown even where the runs'
    numerical warnings are silenced."""


class JournalInterrupted(KeyboardInterrupt):
    """A task table stopped by Ctrl-C or SIGTERM; the message says what was kept and where."""


def run_journalled(tasks: Sequence[Task], path: str | os.PathLike, columns: Sequence[str], *,
             failure_row: Callable[[Task, str], dict], parse: Callable[[dict], dict],
             resume: bool = True, workers: int | None = None, scheduler: str | None = None,
             progress: bool = False, commit: bool = True,
             finite: Sequence[str] = ()) -> tuple[list[dict], int]:
    """Run the tasks that have no valid row yet and journal each row as it arrives; return all
    rows of this table in task order and how many tasks ran.

    The result file ``path`` (``NAME.csv``) holds the last complete table; rows of a table under
    way go to the journal ``NAME.partial.csv`` beside it, appended and flushed one by one (an
    interrupt or a kill keeps every finished row there). With ``commit`` the rows are then
    written to ``NAME.csv`` (through the output layer, with a manifest) and the journal is
    removed; without, the caller commits them with the other files of its set
    (`commit_journal`).

    Each task returns a row (a dict over ``columns``, ``key`` included); a task that fails
    gives ``failure_row(task, error)`` instead. Every row carries the task's ``fingerprint``
    and a checksum of its own values. ``resume``: rows already in ``NAME.csv`` or the journal
    are reused after they are checked (`read_rows_back`: checksum, this table's key and
    fingerprint, a known status, ``finite`` columns finite on a success); rows of another
    table are refused, not overwritten (``InputError``); ``resume=False`` ignores them (they
    are replaced when this table commits).
    """
    from ..io import atomic

    keys = [task.key for task in tasks]
    if len(set(keys)) != len(keys):
        raise InputError("the table has two tasks with the same key")
    columns = _with_checks(columns)
    path = Path(path)
    journal = journal_path(path)
    with atomic.output_folder(path.parent) as folder:
        done = read_rows_back(path, tasks, columns, parse, finite) if resume else {}
        todo = [task for task in tasks if task.key not in done]
        # the journal starts with the rows kept, so a row is never read twice
        folder.replace(journal.name, atomic.text(row_lines(columns, done.values(),
                                                            header=True)))
        try:
            with folder.journal(journal.name) as handle:
                for task, result, error in run_tasks(todo, workers=workers,
                                                     scheduler=scheduler, progress=progress):
                    row = result if error is None else failure_row(task, error)
                    row = signed({**row, "key": task.key, "fingerprint": task.fingerprint()},
                                 columns)
                    handle.write(row_lines(columns, [row]))
                    handle.flush()  # a row on disk survives an interrupt or a dying process
                    done[task.key] = parse({k: str(v) for k, v in row.items()})
        except KeyboardInterrupt:
            raise JournalInterrupted(
                f"interrupted; {len(done)} of {len(tasks)} rows are finished and kept in "
                f"{journal} (running the same table again goes on from them); {path} still "
                "holds the last complete table, if there was one") from None
        rows = [done[key] for key in keys]
        if commit:
            commit_journal(path, columns, rows)
    return rows, len(todo)


def journal_path(path) -> Path:
    """``NAME.partial.csv`` beside ``NAME.csv``: the rows of a table under way."""
    path = Path(path)
    return path.with_name(path.stem + ".partial" + path.suffix)


def commit_journal(path, columns: Sequence[str], rows: list[dict], files: dict | None = None,
                meta: dict | None = None) -> dict:
    """Write ``NAME.csv`` (``rows`` in order), the other ``files`` of the set (name ->
    writer) and the manifest ``meta.json`` as one set through the output layer, then drop the
    journal. Returns the manifest."""
    from ..io import atomic

    path = Path(path)
    columns = _with_checks(columns)
    rows = [signed(row, columns) for row in rows]
    with atomic.output_folder(path.parent) as folder:
        written = folder.commit({path.name: atomic.text(row_lines(columns, rows, header=True)),
                                 **(files or {})},
                                {"rows": len(rows), **(meta or {})})
        folder.remove(journal_path(path).name)
    return written


RETRIED = ("task_failed", "worker_died", "not_run")  # statuses a resumed table runs again


CHECKSUM = "row_sha256"


# Statuses a row may have: a solver's, or how its task ended.
STATUSES = frozenset([status.code for status in Status] + list(RETRIED))


def _with_checks(columns) -> list[str]:
    columns = [c for c in columns if c not in ("fingerprint", CHECKSUM)]
    return [*columns, "fingerprint", CHECKSUM]


def row_checksum(row: dict, columns: Sequence[str]) -> str:
    """16 hex digits of the SHA-256 of the row's values as the file holds them (strings), in
    column order: a row edited by hand, cut short or written by another tool does not match.
    (Not a signature: whoever recomputes it can forge a row.)"""
    text = json.dumps([_cell(row.get(c)) for c in columns if c != CHECKSUM])
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _cell(value) -> str:
    return "" if value is None else str(value)


def signed(row: dict, columns: Sequence[str]) -> dict:
    """``row`` with its checksum (over the values as they will be written)."""
    row = {c: _cell(row.get(c)) for c in columns if c != CHECKSUM}
    row[CHECKSUM] = row_checksum(row, columns)
    return row


def row_lines(columns: Sequence[str], rows, *, header: bool = False) -> str:
    """CSV text of ``rows`` (and the header)."""
    import csv
    import io

    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, columns, extrasaction="ignore", lineterminator="\n")
    if header:
        writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue()


def read_rows_back(path, tasks, columns, parse, finite=()) -> dict:
    """The rows of ``NAME.csv`` and of its journal that a resumed table keeps, by key.

    ``NAME.csv`` is read only as the manifest ``meta.json`` beside it vouches for it (its
    SHA-256 recorded when the table was committed, `ddvp_nlp.io.atomic.vouched`): a file
    edited since, cut, or without a manifest gives no row (one warning; its tasks run again).
    The journal ``NAME.partial.csv`` (rows of a table under way, appended by the writer that
    held the folder) is read row by row. A file that is not a table file ddvp wrote (not UTF-8
    text, another header, a field past the CSV limit, a link, a folder, bigger than the memory
    allows) is refused, naming it and the reason (``InputError``); so is a row of another table
    (a key this table does not have: other points, methods or cases): it is not overwritten;
    so is a key given twice in one file (which of the two is meant cannot be told). A row cut
    short by a kill, whose checksum does not match, computed with other settings (its task's
    fingerprint changed), with an unknown status, or a success with a number that is not
    finite, is dropped with a warning and its task runs again; so is a failed task's row
    (``RETRIED``). A journal row replaces ``NAME.csv``'s of the same key (it is newer)."""
    fingerprints = {task.key: task.fingerprint() for task in tasks}
    kept, foreign = {}, 0
    complete, reused = _vouched_table(Path(path))
    for source, reuse in ((complete, reused), (journal_path(path), True)):
        seen: dict[str, int] = {}
        for number, row in _file_rows(source, columns):
            reason = _row_problem(row, columns, fingerprints, finite)
            if reason == "foreign":
                foreign += 1
                continue
            if not reuse:
                continue
            if reason is None and row["key"] in seen:
                raise InputError(
                    f"table file {str(source)!r} gives the key {row['key'][:80]!r} twice (lines "
                    f"{seen[row['key']]} and {number}): not a file ddvp wrote; start the table "
                    "afresh to replace it")
            seen[row["key"]] = number
            if reason is None:
                try:
                    parsed = parse(row)
                except (KeyError, ValueError, TypeError) as exc:
                    reason = f"does not parse ({exc})"
            if reason is not None:
                warnings.warn(f"{source}: line {number} {reason}; its task runs again",
                              JournalWarning, stacklevel=3)
                continue
            if row.get("status") not in RETRIED:
                kept[row["key"]] = parsed
    if foreign:
        raise InputError(f"{path} holds {foreign} rows of another table (points, methods or "
                         "cases this table does not have); they are not overwritten: start this "
                         "table afresh to replace them (sweep --fresh, stress without --resume) "
                         "or give another --out")
    return kept


def _vouched_table(path: Path) -> tuple[Path, bool]:
    """``(file to read, whether its rows may be reused)`` for a table's ``NAME.csv``: the file
    the manifest vouches for; one that it does not vouch for is still read (for the rows of
    another table, which are not overwritten) but gives no row, with one warning."""
    from ..io import atomic

    if not os.path.lexists(path):
        return path, False
    try:
        return atomic.vouched(path.parent, path.name), True
    except InputError as exc:
        warnings.warn(f"{path} is not reused: it is not the file its manifest describes "
                      f"({exc}); its tasks run again", JournalWarning, stacklevel=4)
        return path, False


def _row_problem(row: dict, columns, fingerprints: dict, finite) -> str | None:
    """Why a row read back cannot be reused (``"foreign"``: another table's), or ``None``."""
    if None in row or any(row.get(c) is None for c in columns):
        return "is incomplete (a run cut short?)"
    if row[CHECKSUM] != row_checksum(row, columns):
        return "does not match its checksum (edited, or written by another tool)"
    if row["key"] not in fingerprints:
        return "foreign"
    if fingerprints[row["key"]] != row["fingerprint"]:
        return "was computed with other settings or another scene file"
    if "status" not in row:  # a table whose rows have no status (a plain table of results)
        return None
    if row["status"] not in STATUSES:
        return f"has an unknown status {row['status'][:40]!r}"
    if row["status"] == "success":
        for name in finite:
            try:
                value = float(row[name])
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                return f"claims success with {name} = {row[name][:40]!r}"
    return None


# Largest table file read back: a row is a few hundred bytes; a table has at most a million.
JOURNAL_LIMIT = 1 << 30


def _file_rows(path: Path, columns) -> Iterator[tuple[int, dict]]:
    """``(line number, row)`` of a table file (none if it does not exist); ``InputError`` for a
    file that is not one (module docstring of `read_rows_back`)."""
    import csv
    import io

    from ..validation import check_file_size, read_limited

    if not os.path.lexists(path):
        return
    if path.is_symlink():  # never followed; the table's commit replaces the link itself
        warnings.warn(f"{path} is a symbolic link: not read (ddvp follows no link); its rows, "
                      "if any, run again", JournalWarning, stacklevel=4)
        return
    data = read_limited(path, JOURNAL_LIMIT, what="table file")
    check_file_size(str(path), len(data))
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"table file {str(path)!r} is not UTF-8 text (byte {exc.start}): not a "
                         "file ddvp wrote; start the table afresh to replace it") from None
    if "\0" in text:
        raise InputError(f"table file {str(path)!r} holds NUL bytes: not a file ddvp wrote; "
                         "start the table afresh to replace it")
    reader = csv.DictReader(io.StringIO(text, newline=""))
    try:
        header = reader.fieldnames or []
        if text.strip() and list(header) != list(columns):
            raise InputError(f"table file {str(path)!r} has other columns than this table's "
                             f"({', '.join(header[:4])}...): not written for it; start the table "
                             "afresh to replace it")
        yield from enumerate(reader, start=2)
    except csv.Error as exc:
        raise InputError(f"table file {str(path)!r} is not a CSV ddvp wrote ({exc}); start the "
                         "table afresh to replace it") from None


def read_csv(path: str | os.PathLike, *, missing_ok: bool = True) -> list[dict]:
    """The rows of a CSV as dicts of strings; ``[]`` for a missing file if ``missing_ok``."""
    path = Path(path)
    if missing_ok and not path.exists():
        return []
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))
