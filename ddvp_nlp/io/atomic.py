"""Writing a set of files into a folder so that a crash, a kill or a second writer never leaves a
torn or mixed set.

Each file is first written in full to a temporary name in the same folder
(``.STEM.PID.TOKEN.tmp.SUFFIX``),
flushed to disk, and only then renamed into place; a rename within one folder is atomic, so a
reader sees either the old file or the new one, never a part. The renames of one set happen
under an exclusive lock on ``FOLDER/.ddvp.lock`` (``fcntl.flock``), so of several processes
writing the same folder at once the last one to rename wins with all of its files. The last file
of a set (``meta.json`` of a run) records the checksum of the others, which is how a reader tells
a set that a kill cut between two renames from a whole one (:mod:`ddvp_nlp.io.runs`).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import secrets
from collections.abc import Callable, Iterator
from pathlib import Path

from ..errors import OutputError

LOCK_NAME = ".ddvp.lock"


def sha256_of(path: str | os.PathLike) -> str:
    """The SHA-256 of a file's bytes, in hex."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def scratch_name(folder: Path, name: str) -> Path:
    """A temporary name beside ``folder/name`` that no other writer uses (hidden, same suffix,
    so writers that choose a format by the suffix still do)."""
    path = Path(name)
    return folder / f".{path.stem}.{os.getpid()}.{secrets.token_hex(4)}.tmp{path.suffix}"


def write_scratch(folder: Path, name: str, write: Callable[[Path], None]) -> Path:
    """Write ``folder/name``'s new content to a scratch file with ``write(path)``, flushed to
    disk; return the scratch path. A failed write leaves no scratch file behind and raises
    :class:`OutputError` naming ``folder/name``."""
    scratch = scratch_name(folder, name)
    try:
        write(scratch)
        with open(scratch, "rb+") as handle:
            os.fsync(handle.fileno())  # the bytes are on disk before the name points at them
    except OSError as exc:
        _discard([scratch])
        raise OutputError(folder / name, exc) from None
    return scratch


def commit(folder: Path, scratches: dict[str, Path | None]) -> None:
    """Rename each scratch file to its name, in the order given, under the folder's lock; a name
    whose scratch is ``None`` is removed (so no file of an earlier run stays beside this one's).
    On failure every scratch file not yet renamed is removed and :class:`OutputError` names the
    file that failed."""
    pending = [s for s in scratches.values() if s is not None]
    with _locked(folder):
        for name, scratch in scratches.items():
            target = folder / name
            try:
                if scratch is None:
                    with contextlib.suppress(FileNotFoundError):
                        target.unlink()
                else:
                    os.replace(scratch, target)
                    pending.remove(scratch)
            except OSError as exc:
                _discard(pending)
                raise OutputError(target, exc) from None
        _sync_folder(folder)


def discard(scratches) -> None:
    """Remove scratch files of a set that will not be committed."""
    _discard([s for s in scratches if s is not None])


def _discard(paths) -> None:
    for path in paths:
        with contextlib.suppress(OSError):
            Path(path).unlink()


@contextlib.contextmanager
def _locked(folder: Path) -> Iterator[None]:
    """An exclusive lock on the folder's lock file (a no-op where locks are unavailable)."""
    try:
        import fcntl
    except ImportError:  # not POSIX: renames stay atomic, concurrent sets may mix
        yield
        return
    try:
        handle = open(folder / LOCK_NAME, "a")
    except OSError as exc:
        raise OutputError(folder / LOCK_NAME, exc) from None
    with handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _sync_folder(folder: Path) -> None:
    """Flush the folder's entries (the renames) to disk, where the system allows it."""
    with contextlib.suppress(OSError):
        descriptor = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(descriptor)
        finally:
            os.close(descriptor)
