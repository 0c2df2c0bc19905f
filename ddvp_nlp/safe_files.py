"""Files and folders opened, written and replaced without following a symbolic link.

Two parts of the package write where a planted link could send their bytes elsewhere: the
compiled-code cache (``solvers/compiler.py``, whose libraries are loaded and run) and every
output folder (``io/atomic.py``); and every file a user hands in is read the same way
(``validation.read_limited``). Each reaches a file through the descriptor of its folder, opened
here:

- every open adds ``O_NOFOLLOW | O_CLOEXEC`` (`open_no_follow`): a link as the last component
  is refused (``ELOOP``), never followed, and no descriptor leaks into a child process; a
  folder is opened with ``O_DIRECTORY`` (`open_folder`), a file to read with ``O_NONBLOCK``
  (`open_reading`: a planted FIFO does not hang its reader);
- a new file is created exclusively (``O_EXCL``), written whole, flushed and ``fsync``-ed
  (`write_new`), and removed again if the writing fails;
- a file is replaced by its new content written to a scratch name (`scratch_name`) and renamed
  over it (`replace_file`): a reader finds the old file or the new one, never part of one, and
  the rename replaces a link itself, not its target;
- a folder is made where missing (`make_folder`); ``mkdir`` never follows a link.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
from collections.abc import Callable

NO_FOLLOW = os.O_NOFOLLOW | os.O_CLOEXEC

Writer = Callable[[object], None]  # writer(binary file object)


def open_no_follow(path, flags: int = os.O_RDONLY, mode: int = 0o777, *,
                   dir_fd: int | None = None) -> int:
    """``os.open(path, flags | O_NOFOLLOW | O_CLOEXEC, mode, dir_fd=dir_fd)``: ``OSError``
    (``ELOOP``) if ``path`` is a symbolic link."""
    return os.open(path, flags | NO_FOLLOW, mode, dir_fd=dir_fd)


def open_folder(path, *, dir_fd: int | None = None) -> int:
    """The descriptor of the folder ``path``, no link followed."""
    return open_no_follow(path, os.O_RDONLY | os.O_DIRECTORY, dir_fd=dir_fd)


def open_reading(path, *, dir_fd: int | None = None) -> int:
    """``path`` opened to read, no link followed and without waiting for a writer (a FIFO)."""
    return open_no_follow(path, os.O_RDONLY | os.O_NONBLOCK, dir_fd=dir_fd)


def reason(exc: OSError) -> str:
    """Why ``path`` could not be opened, in words (a link named as one)."""
    if exc.errno == errno.ELOOP:
        return "it is a symbolic link, which ddvp does not follow"
    return exc.strerror or str(exc)


def is_link(name, *, dir_fd: int | None = None) -> bool:
    """Whether ``name`` is a symbolic link (``False`` if it cannot be looked at)."""
    try:
        return stat.S_ISLNK(os.stat(name, dir_fd=dir_fd, follow_symlinks=False).st_mode)
    except OSError:
        return False


def remove(name, *, dir_fd: int | None = None) -> None:
    """``name`` unlinked if it can be (a link itself, not its target); nothing otherwise."""
    with contextlib.suppress(OSError):
        os.unlink(name, dir_fd=dir_fd)


def make_folder(path, mode: int = 0o777, *, dir_fd: int | None = None) -> bool:
    """The folder ``path`` made: ``True``, or ``False`` if the name exists (a folder, or
    anything else: the opening that follows says what)."""
    try:
        os.mkdir(path, mode, dir_fd=dir_fd)
    except FileExistsError:
        return False
    return True


def write_new(name, write: Writer, *, mode: int = 0o644, dir_fd: int | None = None) -> None:
    """Create ``name`` (it must not exist: ``FileExistsError``; no link followed), ``write``
    its bytes, flush them to disk; removed again if the writing fails."""
    descriptor = open_no_follow(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode, dir_fd=dir_fd)
    try:
        with os.fdopen(descriptor, "wb") as handle:
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())  # the bytes are on disk before a name points at them
    except BaseException:
        remove(name, dir_fd=dir_fd)
        raise


def scratch_name(name: str) -> str:
    """A fresh hidden name beside ``name`` for its next content (``.NAME.PID.TOKEN.tmp``)."""
    return f".{name}.{os.getpid()}.{os.urandom(6).hex()}.tmp"  # secrets.token_hex(6)


def replace_file(name: str, write: Writer, *, mode: int = 0o644,
                 dir_fd: int | None = None) -> None:
    """Replace ``name`` whole: ``write`` to a scratch name (`write_new`), renamed over
    ``name``; until the rename the old file stays, after it the new one is complete. A
    failure removes the scratch file and raises."""
    scratch = scratch_name(name)
    write_new(scratch, write, mode=mode, dir_fd=dir_fd)
    try:
        os.rename(scratch, name, src_dir_fd=dir_fd, dst_dir_fd=dir_fd)
    except BaseException:
        remove(scratch, dir_fd=dir_fd)
        raise


__all__ = ["NO_FOLLOW", "Writer", "is_link", "make_folder", "open_folder", "open_no_follow",
           "open_reading", "reason", "remove", "replace_file", "scratch_name", "write_new"]
