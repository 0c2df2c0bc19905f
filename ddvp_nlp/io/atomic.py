"""The one output layer: every file any command writes goes through an `OutputFolder`.

What it promises, and how:

- **No link is followed.** The folder is opened component by component without following a
  link (the components ddvp chose: the last one of a folder the user named, ``runs/NAME`` of
  a default one), and every file is created or opened relative to that descriptor the same
  way (``safe_files.py``: a planted symbolic link is refused by name, never written through);
  a new file lands by ``rename``, which replaces a link itself rather than its target.
- **One writer at a time, and no reader while one writes.** Opening a folder takes an
  exclusive, non-blocking ``flock`` on ``FOLDER/.ddvp.lock`` (opened without following links)
  for as long as the command runs; a second ddvp process writing the same folder is refused
  (`OutputError`, exit 1) instead of replacing the first one's result in silence. The lock
  file is removed when the writer is done. A reader (`reading`, which `read_set` and
  ``read_run`` take) holds a shared ``flock`` on the same file while it reads, so no writer
  swaps a set under it; a folder being written is refused as busy (`FolderBusy`, an
  `InputError`: exit 2), never read half-swapped.
- **All of a set or none, and the previous set readable until the new one is whole.** A set of
  files (`OutputFolder.commit`) is written in full to scratch names with a random token
  (``.NAME.PID.TOKEN.tmp``, created with ``O_EXCL``), flushed and ``fsync``-ed; the manifest
  ``meta.json`` names each file of the set with its SHA-256, size and inode and is renamed
  last. Before a file of the previous set is replaced, it is renamed to ``.NAME.previous``;
  those are removed once the new manifest is in place. A kill at any moment therefore leaves,
  for each name, either the file the manifest describes or its ``.previous`` twin, and
  `read_set` (which checks every checksum) finds the last complete set, or says that
  there is none.
- **Disk full, read-only, not a folder, a name too long**: an `OutputError` naming the
  path (the command exits 1); the scratch files of the failed set are removed, and so are the
  folders this writer created, if nothing was committed in them.

Rows of a grid that arrive one by one go to a journal (`OutputFolder.journal`), appended
and flushed line by line beside the last complete set, which stays untouched until the new one
is committed.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import stat
import threading
from collections.abc import Iterator
from pathlib import Path

from .. import safe_files
from ..errors import InputError, OutputError
from ..safe_files import Writer
from ..validation import read_limited

LOCK_NAME = ".ddvp.lock"
MANIFEST = "meta.json"
# Largest manifest read back: a meta.json is a few kilobytes; a bigger one is not ours.
MANIFEST_LIMIT = 16 << 20



class Written(str):
    """The name of a scratch file already written (`OutputFolder.scratch`): a set can
    take it in place of a writer, so large files are written once."""


def sha256_of(path: str | os.PathLike, *, dir_fd: int | None = None) -> str:
    """The SHA-256 of a file's bytes, in hex (the file opened without following a link)."""
    descriptor = safe_files.open_no_follow(path, os.O_RDONLY, dir_fd=dir_fd)
    digest = hashlib.sha256()
    with os.fdopen(descriptor, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def text(content: str) -> Writer:
    """A writer of ``content`` as UTF-8."""
    data = content.encode("utf-8")
    return lambda handle: handle.write(data)


def previous_name(name: str) -> str:
    return f".{name}.previous"


def _refusal(path, exc: OSError) -> OutputError:
    """The error of a folder component that is a link or not a folder, in words."""
    if exc.errno == errno.ELOOP:
        return OutputError(path, OSError(exc.errno, "it is a symbolic link; ddvp does not write "
                                                    "through links"))
    if exc.errno == errno.ENOTDIR:
        return OutputError(path, OSError(exc.errno, "it is not a folder"))
    return OutputError(path, exc)


class FolderBusy(InputError):
    """A folder another ddvp process is writing: it cannot be read (or resumed) now."""


def busy_message(path, holder: str) -> str:
    return (f"{path} is busy: another ddvp process{f' (pid {holder})' if holder else ''} is "
            "writing it; wait for it to end (or stop it) and try again")


class _Lock:
    """The exclusive ``flock`` on ``.ddvp.lock`` of one folder, for this process."""

    def __init__(self, folder_fd: int, path: Path):
        import fcntl

        self.path, self.folder_fd = path / LOCK_NAME, folder_fd
        for _ in range(100):  # the name may be removed by the holder between open and flock
            try:
                descriptor = safe_files.open_no_follow(LOCK_NAME, os.O_RDWR | os.O_CREAT,
                                                       0o644, dir_fd=folder_fd)
            except OSError as exc:
                raise _refusal(self.path, exc) from None
            if not stat.S_ISREG(os.fstat(descriptor).st_mode):
                os.close(descriptor)
                raise OutputError(self.path, OSError(errno.EEXIST, "it is not a regular file"))
            if not _flock(descriptor, fcntl.LOCK_EX):
                holder = _read_pid(descriptor)
                os.close(descriptor)
                raise OutputError(path, OSError(errno.EBUSY, (
                    f"another ddvp process (pid {holder}) is writing this folder" if holder
                    else "another ddvp process is writing this folder (or reading it)") + (
                    "; two writers would replace each other's results: wait for it to end or "
                    "choose another output folder"))) from None
            if self._still_named(descriptor):
                break
            os.close(descriptor)
        else:
            raise OutputError(self.path, OSError(errno.EBUSY, "the lock file keeps changing"))
        self.descriptor, self.owner = descriptor, os.getpid()
        with contextlib.suppress(OSError):
            os.ftruncate(descriptor, 0)
            os.pwrite(descriptor, f"{os.getpid()}\n".encode(), 0)

    def _still_named(self, descriptor: int) -> bool:
        try:
            named = os.stat(LOCK_NAME, dir_fd=self.folder_fd, follow_symlinks=False)
        except OSError:
            return False
        held = os.fstat(descriptor)
        return (named.st_dev, named.st_ino) == (held.st_dev, held.st_ino)

    def release(self) -> None:
        if self.descriptor < 0 or os.getpid() != self.owner:  # a forked child holds nothing
            return
        with contextlib.suppress(OSError):
            os.unlink(LOCK_NAME, dir_fd=self.folder_fd)
        os.close(self.descriptor)
        self.descriptor = -1


# Tries, 5 ms apart, to take a lock whose holder is being killed (it lets go as it dies).
DYING_HOLDER_TRIES = 2000


def _flock(descriptor: int, mode: int) -> bool:
    """``flock(mode)`` without blocking: ``True`` if taken, ``False`` if another process
    holds the lock. A holder that is being killed is waited for (a bounded count of tries):
    the ``ddvp`` command runs in a child of the process a user kills (``cli/supervisor.py``),
    and the child, killed with it, may take a moment to let go."""
    import fcntl
    import time

    for _ in range(DYING_HOLDER_TRIES):
        try:
            fcntl.flock(descriptor, mode | fcntl.LOCK_NB)
            return True
        except OSError:
            holder = _read_pid(descriptor)
            if not holder or not _exiting(int(holder)):
                return False
        time.sleep(0.005)
    return False


def _exiting(pid: int) -> bool:
    """Whether process ``pid`` is gone or on its way out: a SIGKILL pending, exiting, or a
    zombie (Linux's ``/proc``; elsewhere only a process that is gone)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as handle:
            fields = handle.read().rsplit(b")", 1)[1].split()
        if fields[0] in (b"Z", b"X", b"x") or int(fields[6]) & 0x4:  # PF_EXITING
            return True
        with open(f"/proc/{pid}/status", "rb") as handle:
            for line in handle:
                if line.startswith((b"SigPnd:", b"ShdPnd:")) and \
                        int(line.split()[1], 16) & (1 << 8):  # SIGKILL pending
                    return True
        return False
    except FileNotFoundError:
        return True
    except (OSError, ValueError, IndexError):
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        except OSError:
            pass
        return False


def _read_pid(descriptor: int) -> str:
    with contextlib.suppress(OSError, ValueError):
        value = os.pread(descriptor, 32, 0).decode().strip()
        if value.isdigit():
            return value
    return ""


class OutputFolder:
    """A folder opened for writing: its descriptor (no link followed), its lock, the folders
    this writer created. Use `output_folder` (a context) or `open_folder`."""

    def __init__(self, path: Path, descriptor: int, created: list[tuple[int, str]],
                 parents: list[int]):
        self.path, self.fd, self.created, self.parents = path, descriptor, created, parents
        self.committed = False
        self.users = 1
        self.guard = threading.RLock()  # a checkpoint thread and the main thread take turns
        try:
            self.lock = _Lock(descriptor, path)
            self._remove_stale_scratch()
        except BaseException:
            self._forget_created()
            os.close(descriptor)
            raise
        self.key = (os.fstat(descriptor).st_dev, os.fstat(descriptor).st_ino)

    def __repr__(self) -> str:
        return f"OutputFolder({str(self.path)!r})"

    def __enter__(self) -> OutputFolder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __fspath__(self) -> str:
        return str(self.path)

    def __truediv__(self, name: str) -> Path:
        return self.path / name

    # -- writing ---------------------------------------------------------------------------

    def scratch(self, name: str, write: Writer) -> Written:
        """Write ``name``'s new content to a fresh scratch file, flushed to disk; its name."""
        scratch = safe_files.scratch_name(name)
        try:
            safe_files.write_new(scratch, write, mode=0o644, dir_fd=self.fd)  # removed if it fails
        except OutputError:
            raise
        except OSError as exc:
            raise OutputError(self.path / name, exc) from None
        return Written(scratch)

    def commit(self, files: dict[str, Writer | None], meta: dict | None = None, *,
               manifest: str = MANIFEST, digests: dict[str, str] | None = None) -> dict:
        """Write ``files`` (name -> writer, or a `Written` scratch file; ``None``: remove
        that name) and the manifest
        ``meta`` (with ``files``: each file's SHA-256, size and inode) as one set: every file
        first to a scratch name, then renamed, the manifest last (module docstring). Returns
        the manifest written; ``digests`` copies a file's SHA-256 to a key of its own
        (``{"result_sha256": "result.npz"}``). A failure removes every scratch file and raises
        `OutputError` naming the file; the previous set stays readable."""
        with self.guard:
            scratches: dict[str, str] = {}
            try:
                for name, write in files.items():
                    if isinstance(write, Written):
                        scratches[name] = write
                    elif write is not None:
                        scratches[name] = self.scratch(name, write)
                entries = {name: self._entry(scratch) for name, scratch in scratches.items()}
                written = {**(meta or {}),
                           **{key: entries[name]["sha256"] for key, name in
                              (digests or {}).items() if name in entries},
                           "files": entries}
                body = json.dumps(written, indent=2, default=_json_default) + "\n"
                manifest_scratch = self.scratch(manifest, text(body))
            except BaseException:
                for scratch in scratches.values():
                    self.unlink(scratch)
                raise
            _swap(self, scratches, manifest, manifest_scratch,
                       removed=[name for name, write in files.items() if write is None])
            self.committed = True
            return written

    def _entry(self, scratch: str) -> dict:
        try:
            info = os.stat(scratch, dir_fd=self.fd, follow_symlinks=False)
            digest = sha256_of(scratch, dir_fd=self.fd)
        except OSError as exc:
            raise OutputError(self.path / scratch, exc) from None
        return {"sha256": digest, "bytes": info.st_size, "inode": info.st_ino}

    def replace(self, name: str, write: Writer) -> None:
        """Replace one file on its own (no manifest): scratch, flush, rename."""
        with self.guard:
            try:
                safe_files.replace_file(name, write, mode=0o644, dir_fd=self.fd)
            except OutputError:
                raise
            except OSError as exc:
                raise OutputError(self.path / name, exc) from None
            self.committed = True

    @contextlib.contextmanager
    def journal(self, name: str) -> Iterator[object]:
        """A text file opened for appending (``O_APPEND``, no link followed)."""
        try:
            descriptor = safe_files.open_no_follow(name, os.O_WRONLY | os.O_APPEND, dir_fd=self.fd)
        except OSError as exc:
            raise _refusal(self.path / name, exc) from None
        try:
            with os.fdopen(descriptor, "a", encoding="utf-8", newline="") as handle:
                yield handle
        except OSError as exc:
            if isinstance(exc, OutputError):
                raise
            raise OutputError(self.path / name, exc) from None

    def remove(self, name: str) -> None:
        with self.guard:
            self.unlink(name)

    def subfolder(self, name: str) -> OutputFolder:
        """A folder inside this one, opened (and created) the same way."""
        return _open_below(os.dup(self.fd), self.path, [name])

    # -- housekeeping ----------------------------------------------------------------------

    def unlink(self, name: str) -> None:
        safe_files.remove(name, dir_fd=self.fd)

    def sync(self) -> None:
        with contextlib.suppress(OSError):
            os.fsync(self.fd)

    def _remove_stale_scratch(self) -> None:
        """Scratch files of writers that were killed (only one writer holds the lock)."""
        with contextlib.suppress(OSError):
            for entry in os.scandir(self.fd):
                if entry.name.startswith(".") and entry.name.endswith(".tmp"):
                    self.unlink(entry.name)

    def _forget_created(self) -> None:
        """Remove the folders this writer created (innermost first), if they are empty."""
        for parent, name in reversed(self.created):
            with contextlib.suppress(OSError):
                os.rmdir(name, dir_fd=parent)
        self.created = []
        for parent in self.parents:
            with contextlib.suppress(OSError):
                os.close(parent)
        self.parents = []

    def close(self) -> None:
        """Release the lock; folders created for a set that never landed are removed."""
        with _REGISTRY_GUARD:
            self.users -= 1
            if self.users > 0:
                return
            _REGISTRY.pop(self.key, None)
        self.lock.release()
        with contextlib.suppress(OSError):
            os.close(self.fd)
        if self.committed:
            self.created = []
        self._forget_created()  # rmdir: only folders that stayed empty go


def _swap(folder: OutputFolder, scratches: dict[str, str], manifest: str, manifest_scratch: str, *,
          removed: list[str]) -> None:
    """The renames of a set: each replaced file of the last complete set kept as
    ``.NAME.previous``, the new files, the manifest, then the old ones dropped."""
    current = _current_files(folder, manifest)
    pending = dict(scratches)
    try:
        for name, scratch in scratches.items():
            if current.get(name) == name:  # the file the manifest names: keep it aside
                os.rename(name, previous_name(name), src_dir_fd=folder.fd,
                          dst_dir_fd=folder.fd)
            os.rename(scratch, name, src_dir_fd=folder.fd, dst_dir_fd=folder.fd)
            del pending[name]
        os.rename(manifest_scratch, manifest, src_dir_fd=folder.fd, dst_dir_fd=folder.fd)
    except OSError as exc:
        for scratch in [*pending.values(), manifest_scratch]:
            folder.unlink(scratch)
        raise OutputError(folder.path / manifest, exc) from None
    folder.sync()
    stale = set(current) - set(scratches)
    for name in {*scratches, *current, *removed}:
        folder.unlink(previous_name(name))
    for name in stale | set(removed):
        if name not in scratches:
            folder.unlink(name)

def _current_files(folder: OutputFolder, manifest: str) -> dict[str, str]:
    """For each file of the set the manifest describes: which name holds it now (itself,
    or its ``.previous`` twin after a kill in the middle of a swap). Matched by inode and
    size, the cheap identity a rename keeps (readers check the checksums)."""
    try:
        described = _load_manifest(folder.fd, manifest, folder.path).get("files", {})
    except (InputError, OSError):
        return {}
    found = {}
    for name, entry in described.items() if isinstance(described, dict) else ():
        for candidate in (name, previous_name(name)):
            try:
                info = os.stat(candidate, dir_fd=folder.fd, follow_symlinks=False)
            except (OSError, ValueError):
                continue
            if isinstance(entry, dict) and (info.st_ino, info.st_size) == (
                    entry.get("inode"), entry.get("bytes")):
                found[name] = candidate
                break
    return found


_REGISTRY: dict[tuple, OutputFolder] = {}  # folders this process holds, by (device, inode)
_REGISTRY_GUARD = threading.RLock()


def open_folder(path: str | os.PathLike | OutputFolder, *, owned: int = 1) -> OutputFolder:
    """``path`` opened for writing (created if missing) and locked for this process; a folder
    this process already holds is shared (`OutputFolder.close` once per open).
    ``owned``: how many trailing components ddvp chose (``runs/NAME``: 2), opened without
    following links; the ones before are the user's and resolve as the system does."""
    if isinstance(path, OutputFolder):
        with _REGISTRY_GUARD:
            path.users += 1
        return path
    if not isinstance(path, (str, os.PathLike)) or not str(path).strip():
        raise InputError(f"output folder must be a non-empty path, got {path!r}")
    path = Path(path)
    parts = path.parts
    tail: list[str] = []
    # the components ddvp chose, and every one that does not exist yet (what this writer
    # creates, it removes again if nothing lands in it)
    while parts and parts[-1] not in ("/", "..") and (
            len(tail) < owned or not os.path.lexists(Path(*parts))):
        tail.insert(0, parts[-1])
        parts = parts[:-1]
    head = Path(*parts) if parts else Path(".")
    try:
        head.mkdir(parents=True, exist_ok=True)
        base = os.open(head, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    except FileExistsError:  # mkdir's word for a file where a folder should be
        raise _refusal(head, OSError(errno.ENOTDIR, "Not a directory")) from None
    except OSError as exc:
        raise _refusal(head, exc) from None
    return _open_below(base, head, tail)


def _open_below(base: int, head: Path, names: list[str]) -> OutputFolder:
    """Open (creating) ``head/names...`` from the descriptor ``base`` (which is taken over),
    no link followed."""
    created, opened, where = [], [base], head
    try:
        for name in names:
            where = where / name
            try:
                if safe_files.make_folder(name, 0o777, dir_fd=opened[-1]):
                    created.append((opened[-1], name))
            except OSError as exc:
                raise _refusal(where, exc) from None
            try:
                opened.append(safe_files.open_folder(name, dir_fd=opened[-1]))
            except OSError as exc:
                if safe_files.is_link(name, dir_fd=opened[-1]):
                    exc = OSError(errno.ELOOP, exc.strerror)
                raise _refusal(where, exc) from None
    except BaseException:
        for parent, name in reversed(created):
            with contextlib.suppress(OSError):
                os.rmdir(name, dir_fd=parent)
        for descriptor in opened:
            with contextlib.suppress(OSError):
                os.close(descriptor)
        raise
    descriptor = opened.pop()
    with _REGISTRY_GUARD:
        info = os.fstat(descriptor)
        held = _REGISTRY.get((info.st_dev, info.st_ino))
        if held is not None and held.lock.owner == os.getpid():
            held.users += 1
            for fd in [*opened, descriptor]:
                with contextlib.suppress(OSError):
                    os.close(fd)
            return held
        folder = OutputFolder(where, descriptor, created, opened)
        _REGISTRY[folder.key] = folder
        return folder


@contextlib.contextmanager
def output_folder(path, *, owned: int = 1) -> Iterator[OutputFolder]:
    """`open_folder` as a context: the lock is released at the end."""
    folder = open_folder(path, owned=owned)
    try:
        yield folder
    finally:
        folder.close()


# -- reading back ------------------------------------------------------------------------------

_READING: dict[tuple, int] = {}  # folders this process reads under a shared lock, by identity


@contextlib.contextmanager
def reading(folder: str | os.PathLike) -> Iterator[None]:
    """Hold a shared ``flock`` on ``FOLDER/.ddvp.lock`` while the folder is read, so that no
    ddvp writer swaps a set under the reader; `FolderBusy` naming the folder (and the
    writer's pid) if one is writing it now. Nothing to hold in a folder this process writes or
    already reads, or that does not exist (the read then says what is missing); in a folder the
    reader may not write, the lock file cannot be made, and the folder is read as it is."""
    import fcntl

    try:
        descriptor = safe_files.open_folder(folder)
    except OSError:
        yield
        return
    try:
        info = os.fstat(descriptor)
        key = (info.st_dev, info.st_ino)
        with _REGISTRY_GUARD:
            held = _REGISTRY.get(key)
            mine = (held is not None and held.lock.owner == os.getpid()) or key in _READING
        if mine:
            yield
            return
        lock = _shared_lock(descriptor, Path(folder), fcntl)
        with _REGISTRY_GUARD:
            _READING[key] = 1
        try:
            yield
        finally:
            with _REGISTRY_GUARD:
                _READING.pop(key, None)
            if lock is not None:
                _release_shared(lock, descriptor, fcntl)
    finally:
        os.close(descriptor)


def _shared_lock(folder_fd: int, path: Path, fcntl) -> int | None:
    """The lock file opened (made if missing) and locked shared; ``None`` where it cannot be
    made (a folder the reader may not write: no ddvp process of this user writes there
    either). `FolderBusy` when a writer holds it."""
    for _ in range(100):  # the holder may remove the name between open and flock
        try:
            descriptor = safe_files.open_no_follow(LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644,
                                                   dir_fd=folder_fd)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise InputError(f"{path / LOCK_NAME} is a symbolic link; ddvp does not follow "
                                 "links") from None
            return None
        if not stat.S_ISREG(os.fstat(descriptor).st_mode):
            os.close(descriptor)
            raise InputError(f"{path / LOCK_NAME} is not a regular file")
        if not _flock(descriptor, fcntl.LOCK_SH):
            holder = _read_pid(descriptor)
            os.close(descriptor)
            raise FolderBusy(busy_message(path, holder)) from None
        try:
            named = os.stat(LOCK_NAME, dir_fd=folder_fd, follow_symlinks=False)
            held = os.fstat(descriptor)
            if (named.st_dev, named.st_ino) == (held.st_dev, held.st_ino):
                return descriptor
        except OSError:
            pass
        os.close(descriptor)
    raise FolderBusy(f"{path} is busy: its lock file keeps changing")


def _release_shared(descriptor: int, folder_fd: int, fcntl) -> None:
    """The reader's lock given up; the lock file removed when no one else holds it (the
    reader made it, or shares it with another reader, who removes it in turn)."""
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with contextlib.suppress(OSError):
            os.unlink(LOCK_NAME, dir_fd=folder_fd)
    except OSError:
        pass
    os.close(descriptor)


def _load_manifest(folder_fd: int | None, manifest: str, folder: Path) -> dict:
    where = manifest if folder_fd is not None else folder / manifest
    data = read_limited(where, MANIFEST_LIMIT, what="manifest", dir_fd=folder_fd)
    try:
        meta = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise InputError(f"{folder / manifest} is not a manifest ddvp wrote: {exc}") from None
    if not isinstance(meta, dict):
        raise InputError(f"{folder / manifest} is not a manifest ddvp wrote (not an object)")
    return meta


def read_set(folder: str | os.PathLike, *, manifest: str = MANIFEST,
             required: tuple[str, ...] = ()) -> tuple[dict, dict[str, Path]]:
    """``(meta, {name: path})`` of the last complete set in ``folder``: the manifest, and for
    each file it names the path whose SHA-256 is the one recorded (the file itself, or its
    ``.previous`` twin after a kill between two renames). `InputError` (naming the
    folder and the reason) if there is no manifest, a file of ``required`` is not in it, or a
    file matches neither name; `FolderBusy` if another ddvp process is writing it
    (`reading`)."""
    folder = Path(folder)
    with reading(folder):
        return _read_set(folder, manifest, required)


def _read_set(folder: Path, manifest: str, required: tuple[str, ...]):
    try:
        descriptor = safe_files.open_folder(folder)
    except OSError as exc:
        raise InputError(f"{folder} holds no readable run: {safe_files.reason(exc)}") from None
    try:
        try:
            meta = _load_manifest(descriptor, manifest, folder)
        except InputError as exc:
            raise InputError(f"{folder} holds no readable run: {exc}") from None
        entries = meta.get("files")
        if not isinstance(entries, dict):
            raise InputError(f"{folder / manifest} lists no files (written by another tool, or "
                             "an older ddvp)")
        missing = [name for name in required if name not in entries]
        if missing:
            raise InputError(f"{folder / manifest} does not describe {missing[0]}")
        found = {}
        for name, entry in entries.items():
            found[name] = folder / _matching(descriptor, folder, name, entry)
        return meta, found
    finally:
        os.close(descriptor)


def vouched(folder: str | os.PathLike, name: str, *, manifest: str = MANIFEST) -> Path:
    """The path of ``name`` in ``folder`` as the manifest vouches for it: the file whose
    SHA-256 is the one the manifest records (itself, or its ``.previous`` twin after a kill
    between two renames), read under the folder's lock (`reading`). `InputError` naming the
    reason if there is no readable manifest, it does not list ``name``, or neither file
    matches: the file is not one ddvp wrote whole (cut, edited, or from another tool)."""
    folder = Path(folder)
    with reading(folder):
        try:
            descriptor = safe_files.open_folder(folder)
        except OSError as exc:
            raise InputError(f"{folder} cannot be read: {safe_files.reason(exc)}") from None
        try:
            meta = _load_manifest(descriptor, manifest, folder)
            entries = meta.get("files")
            if not isinstance(entries, dict) or name not in entries:
                raise InputError(f"{folder / manifest} does not list {name}")
            return folder / _matching(descriptor, folder, name, entries[name])
        finally:
            os.close(descriptor)


def _matching(descriptor: int, folder: Path, name, entry) -> str:
    if not isinstance(name, str) or "/" in name or not isinstance(entry, dict):
        raise InputError(f"{folder / MANIFEST} names a file {name!r} ddvp did not write")
    reasons = []
    for candidate in (name, previous_name(name)):
        try:
            digest = sha256_of(candidate, dir_fd=descriptor)
        except OSError as exc:
            reasons.append(f"{candidate}: {safe_files.reason(exc)}")
            continue
        if digest == entry.get("sha256"):
            return candidate
        reasons.append(f"{candidate}: its checksum differs")
    raise InputError(f"{folder / name} is not the file {folder / MANIFEST} describes "
                     f"({'; '.join(reasons)}): the set was cut while writing, or changed by "
                     "another tool")


def _json_default(value):
    import numpy as np

    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if hasattr(value, "code"):  # a Status
        return value.code
    raise TypeError(f"cannot write {type(value).__name__} to JSON")


def describe(folder: str | os.PathLike) -> str:
    """What ``folder`` holds now, in words: the last complete set's status, or nothing."""
    try:
        meta, _ = read_set(folder)
    except InputError:
        return f"{folder}/ holds no complete result"
    status = meta.get("status", "complete")
    if status == "running":
        return (f"{folder}/ holds the checkpoint of step {meta.get('steps')} (t = "
                f"{meta.get('t_reached')})")
    return f"{folder}/ holds an earlier complete result (status {status})"
