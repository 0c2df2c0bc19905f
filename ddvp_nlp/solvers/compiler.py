"""Finding a C compiler and compiling CasADi functions once per content hash.

Compiled libraries are cached in ``cache_dir`` (argument, else ``$DDVP_NLP_CACHE``, else
``~/.cache/ddvp_nlp``) under a hash of the generated code, the compiler and its flags. Each build
compiles in a scratch folder of its own and renames the library into place, so two processes
building the same entry at once both end with a complete library.

The cache is trusted the way ccache's, pip's or ``~/.ssh`` are, because loading a library runs
its code:

- **the folder** must be this user's, not writable by group or others, not a symbolic link,
  and no folder above it may be writable by others (without the sticky bit) or belong to
  another user: otherwise `CompileUnavailable` says which and why (one warning, and the
  virtual machine runs instead); a missing folder is made private (``0700``);
- **a library is loaded** only from a regular file of that folder that this user owns, with one
  link and no write permission for others, whose bytes match the stamp written beside it at
  build time (``chunk_KEY.so.sha256``: an HMAC-SHA256 of the name and the bytes under a key
  kept in the folder, ``.ddvp-cache-key``, ``0600``, made on first use): a library copied in
  or planted with a checksum beside it, a link, another user's file, a truncated or empty file
  is never loaded; it is removed and rebuilt. A library that passes and still fails to load
  (a damaged file with a matching stamp) is removed and rebuilt once, never a crash;
- **scratch** folders (``.build-HOST-PID-TOKEN``) are locked (``flock``) by their build; the
  scratch of a killed build, unlocked and older than a minute, is removed by the next
  process that uses the cache.

When the folder cannot be used or the compiler fails, `CompileUnavailable` says why, and the
callers run CasADi's virtual machine instead, with one warning (`warn_once`).
"""

from __future__ import annotations

import errno
import functools
import hashlib
import hmac
import os
import re
import secrets
import shutil
import stat
import subprocess
import tempfile
import threading
import time
import warnings
import weakref
from pathlib import Path

import casadi as ca
import numpy as np

from .. import safe_files
from ..cache import cached
from ..errors import InputError

# -ffp-contract=off: no contraction to FMA, the virtual machine's arithmetic bit for bit.
# -fno-math-errno: sin, cos, sqrt do not set errno (nothing reads it), so gcc may merge a sin
# and a cos of one argument into one sincos and inline sqrt; the same values (glibc's sincos is
# its sin and cos; sqrt is correctly rounded either way). CasADi's C writes sin and cos apart:
# the march's chunk 7-9% cheaper per step (paper_pendulum, a spherical pendulum in angles; the
# same nodes to the bit, compared; issue 49).
# -fno-plt, -fno-semantic-interposition: sin and cos called through the GOT rather than the PLT,
# and the library's own functions bound at link time: the paper pendulum's chunk 0.448 -> 0.403
# us per step, the same outputs to the bit (side by side, issue 49).
COMPILE_FLAGS = ("-O2", "-fPIC", "-shared", "-ffp-contract=off", "-fno-math-errno", "-fno-plt",
                 "-fno-semantic-interposition")


def find_compiler(compiler: str | None = "auto") -> str | None:
    """The C compiler to use: ``"auto"`` looks for ``$CC``, ``gcc``, ``cc``; ``None`` means none
    (the virtual machine); anything else is a command that must exist."""
    if compiler is None:
        return None
    if compiler == "auto":
        for candidate in (os.environ.get("CC"), "gcc", "cc"):
            found = _which(candidate, os.environ.get("PATH")) if candidate else None
            if found:
                return found
        return None
    found = _which(compiler, os.environ.get("PATH"))
    if found is None:
        raise InputError(f"compiler {compiler!r} was not found")
    return found


@functools.lru_cache(maxsize=64)
def _which(command: str, path: str | None) -> str | None:
    """``shutil.which``, remembered per command and ``PATH`` (a march looked the compiler up on
    every call: 0.5 ms of a 2.9 ms short march)."""
    return shutil.which(command, path=path)


def cache_folder(cache_dir: str | os.PathLike | None = None) -> Path:
    if cache_dir is not None:
        return Path(cache_dir)
    if os.environ.get("DDVP_NLP_CACHE"):
        return Path(os.environ["DDVP_NLP_CACHE"])
    return Path.home() / ".cache" / "ddvp_nlp"


class CompileUnavailable(RuntimeError):
    """The compiled path cannot be used here (cache folder or compiler); the message says why."""


_WARNED: set[str] = set()


def forget_warnings() -> None:
    """Warn again about reasons already warned of in this process (a long-lived process whose
    setup changed, or a test that wants to see the warning)."""
    _WARNED.clear()


def warn_once(reason: Exception) -> None:
    """One warning per distinct reason in this process: the virtual machine takes over."""
    text = f"{reason}; running on CasADi's virtual machine instead (slower, same steps)"
    if text not in _WARNED:
        _WARNED.add(text)
        warnings.warn(text, RuntimeWarning, stacklevel=3)


def compile_function(function: ca.Function, compiler: str, folder: Path, *,
                     prefix: str = "chunk", build: bool = True,
                     steps: int | None = None) -> ca.Function | None:
    """Generate, compile (once per hash; again if the cached library fails its checks) and
    load ``function`` as ``PREFIX_HASH.so``; with ``build=False`` only a library already in
    the cache is loaded, else ``None``. ``steps``: ``function`` is a step ``(state, p) ->
    (state, out)`` repeated ``steps`` times by ``mapaccum``, generated as a loop
    (`looped_mapaccum`). Raises `CompileUnavailable` if the folder or compiler fails."""
    code = generated_code(function)
    if steps is not None:
        code = looped_mapaccum(code, function, steps)
    return _compile_code(function, code, compiler, folder, prefix=prefix, build=build)


def looped_mapaccum(code: str, function: ca.Function, steps: int) -> str:
    """The generated ``code`` of ``function = step.mapaccum(name, steps)`` (``step: (state,
    p) -> (state, out)``, dense columns) with its exported entry calling a loop over ``step``
    in place of mapaccum's tree: step ``k`` reads the state step ``k - 1`` wrote into column
    ``k - 1`` of output 0 (the initial state for ``k = 0``) and column ``k`` of input 1, and
    writes column ``k`` of both outputs. The same calls of the same step function, so the
    same outputs to the bit; what goes is mapaccum's copying of the states and outputs
    between the levels of its tree (about 5% of the march's chunk, perf). Where CasADi's code
    does not have the expected shape (an entry ``return casadi_fN(arg, res, iw, w, mem);``
    whose function first calls the step as ``casadi_fM(arg1, res1, iw, w, 0)``), or where
    any argument or result is absent, mapaccum's own code runs."""
    name = function.name()
    entry = re.search(r"CASADI_SYMBOL_EXPORT int " + re.escape(name) + r"\(const casadi_real\*\* "
                      r"arg, casadi_real\*\* res, casadi_int\* iw, casadi_real\* w, int mem\)"
                      r"\{\n  return (casadi_f\d+)\(arg, res, iw, w, mem\);\n\}", code)
    if entry is None:
        return code
    top = entry.group(1)
    body = re.search(r"\nstatic int " + top + r"\(.*?\n\}\n", code, re.S)
    step = re.search(r"if \((casadi_f\d+)\(arg1, res1, iw, w, 0\)\) return 1;",
                     body.group(0)) if body is not None else None
    if step is None or function.n_in() != 2 or function.n_out() != 2:
        return code
    state, parameters = function.size1_in(0), function.size1_in(1)
    outputs = function.size1_out(1)
    loop = LOOP.format(top=top, step=step.group(1), steps=steps, state=state,
                       parameters=parameters, outputs=outputs)
    return (code[:entry.start()] + loop + code[entry.start():entry.end()].replace(
        f"return {top}(", "return ddvp_looped(") + code[entry.end():])


LOOP = """/* mapaccum's steps as one loop (ddvp_nlp.solvers.compiler.looped_mapaccum) */
static int ddvp_looped(const casadi_real** arg, casadi_real** res, casadi_int* iw,
                       casadi_real* w, int mem) {{
  const casadi_real **arg1 = arg + 2;
  casadi_real **res1 = res + 2;
  casadi_int k;
  if (!arg[0] || !arg[1] || !res[0] || !res[1]) return {top}(arg, res, iw, w, mem);
  for (k = 0; k < {steps}; ++k) {{
    arg1[0] = k ? res[0] + {state} * (k - 1) : arg[0];
    arg1[1] = arg[1] + {parameters} * k;
    res1[0] = res[0] + {state} * k;
    res1[1] = res[1] + {outputs} * k;
    if ({step}(arg1, res1, iw, w, 0)) return 1;
  }}
  return 0;
}}

"""


def generated_code(function: ca.Function) -> str:
    """The C code CasADi generates for ``function`` (what the cache is keyed by), its
    ``casadi_fmax`` written without the call to libm (`INLINE_FMAX`)."""
    source = ca.CodeGenerator("ddvp_chunk.c", {"with_header": False})
    source.add(function)
    return source.dump().replace(CASADI_FMAX, INLINE_FMAX)


# CasADi's fmax helper as it generates it (3.8), and what replaces it. gcc keeps fmax a call
# into libm without -ffinite-math-only (about 5 ns each, 40-70 per march step: 5-8% of the
# chunk's time, perf). The replacement is branch-free (maxsd, then a blend where y is NaN) and
# returns what glibc's x86-64 fmax returns for every pair of doubles, signed zeros and NaNs
# included (tests/library/test_compiled_code_cache.py); a C library whose fmax returns x for
# fmax(0, -0) differs only in the sign of a zero, which no comparison sees. If CasADi writes
# its helper differently, the text is not found and the call stays.
CASADI_FMAX = """casadi_real casadi_fmax(casadi_real x, casadi_real y) {
/* Pre-c99 compatibility */
#if __STDC_VERSION__ < 199901L
  return x>y ? x : y;
#else
  return fmax(x, y);
#endif
}"""
INLINE_FMAX = """casadi_real casadi_fmax(casadi_real x, casadi_real y) {
  /* fmax(x, y) inline: the larger (y where x > y is false), x where y is NaN */
  casadi_real larger = x > y ? x : y;
  return y != y ? x : larger;
}"""


def _compile_code(function: ca.Function, code: str, compiler: str, folder: Path, *,
                  prefix: str, build: bool = True) -> ca.Function | None:
    """`compile_function` from ``function``'s generated ``code``."""
    return compile_source(code, function.name(), compiler, folder, prefix=prefix,
                          salt=(ca.__version__,), build=build,
                          load=lambda library: ca.external(function.name(), str(library)))


def library_name(code: str, compiler: str, *, prefix: str, salt=()) -> str:
    """``PREFIX_HASH.so``: the cache's name of the library compiled from ``code`` (a hash of
    the code, the compiler, its flags and ``salt``)."""
    key = hashlib.sha256("\0".join([code, compiler, *COMPILE_FLAGS, *salt])
                         .encode()).hexdigest()[:24]
    return f"{prefix}_{key}.so"


def compile_source(code: str, name: str, compiler: str, folder, *, prefix: str,
                   salt=(), load=None, build: bool = True):
    """``PREFIX_HASH.so`` in ``folder``, compiled from the C ``code`` (once per hash of the
    code, the compiler, its flags and ``salt``; again if the cached library fails its
    checks), renamed into place complete; ``load(path)`` of it if ``load`` is given (a
    library that fails to load is removed and rebuilt once). Raises `CompileUnavailable` if
    the folder (module docstring) or the compiler fails; ``name`` is what a compiler error
    names. With ``build=False`` a library not in the cache is not built: ``None``."""
    library = Path(folder) / library_name(code, compiler, prefix=prefix, salt=salt)
    try:
        cache = open_cache(folder)
    except OSError as exc:
        raise CompileUnavailable(f"the compiled-code cache {str(folder)!r} cannot be used: "
                                 f"{exc.strerror or exc}") from None
    with cache:
        for attempt in range(2):
            try:
                if not cache.intact(library.name):
                    if not build:
                        return None
                    _build(code, name, compiler, cache, library.name)
            except OSError as exc:
                raise CompileUnavailable(f"the compiled-code cache {str(folder)!r} cannot be "
                                         f"used: {exc.strerror or exc}") from None
            if load is None:
                return library
            try:
                return load(library)
            except (RuntimeError, OSError) as exc:  # CasADi's or ctypes' refusal of the file
                cache.discard(library.name)
                if attempt:
                    raise CompileUnavailable(f"the library {library.name} built in "
                                             f"{str(folder)!r} does not load: "
                                             f"{str(exc).strip()[:200]}") from None
    raise AssertionError("unreachable")


_BUILDS = [0]  # C compiles run by this process (a list: one mutable count, lock-free reads)
_BUILDS_LOCK = threading.Lock()


def build_count() -> int:
    """How many C compiles this process has run (cache hits are not compiles): what the tests
    count to show that a scene compiles once and that ensemble workers compile nothing."""
    return _BUILDS[0]


KEY_NAME = ".ddvp-cache-key"
SCRATCH_PREFIX = ".build-"
# A scratch folder younger than this is never taken for a killed build's (its build may be
# about to lock it).
SCRATCH_GRACE_S = 60.0
# A library larger than this is damaged (the largest compiled chunks are a few MB): rebuilt.
LIBRARY_LIMIT = 512 * 2 ** 20
_CLEANED: set[tuple] = set()  # cache folders whose stale scratch this process has removed
_CLEAN_LOCK = threading.Lock()


class CacheFolder:
    """The compiled-code cache folder, opened without following a link and checked
    (`open_cache`); every file is reached through its descriptor."""

    def __init__(self, path: Path, descriptor: int):
        self.path, self.fd = path, descriptor
        self.key = _private_key(descriptor, path)

    def __enter__(self) -> CacheFolder:
        return self

    def __exit__(self, *exc) -> None:
        os.close(self.fd)

    def intact(self, name: str) -> bool:
        """``name`` is a library this cache may load (module docstring): a regular file of
        this user, one link, not writable by others, its stamp matching its bytes. Anything
        else found under the name (or its stamp's) is removed, to be rebuilt."""
        stamp = name + ".sha256"
        try:
            expected = _read_own(self.fd, stamp, 256).decode("ascii").strip()
            found = self._file_stamp(name)
        except FileNotFoundError:  # not built yet (or a build is renaming it into place)
            return False
        except (OSError, UnicodeDecodeError):
            self.discard(name)  # a link, another user's file, a folder, too large, ...: rebuilt
            return False
        if not hmac.compare_digest(expected, found):
            self.discard(name)
            return False
        return True

    def stamp(self, name: str, data: bytes) -> str:
        return hmac.new(self.key, name.encode() + b"\0" + data, hashlib.sha256).hexdigest()

    def _file_stamp(self, name: str) -> str:
        """`stamp` of the library ``name``'s bytes, read a block at a time (never the whole
        file in memory: a damaged library may be a 10 GB sparse file); ``OSError`` where it is
        not a private regular file of this user or is larger than ``LIBRARY_LIMIT``."""
        mac = hmac.new(self.key, name.encode() + b"\0", hashlib.sha256)
        with _open_own(self.fd, name, LIBRARY_LIMIT) as handle:
            for block in iter(lambda: handle.read(1 << 20), b""):
                mac.update(block)
        return mac.hexdigest()

    def discard(self, name: str) -> None:
        """The library ``name`` and its stamp removed (a link is removed, not followed)."""
        for entry in (name + ".sha256", name):
            _remove(self.fd, self.path, entry)

    def clean_scratch(self) -> None:
        """Remove the scratch folders of builds that were killed: unlocked, and older than
        `SCRATCH_GRACE_S` (once per process and folder)."""
        import fcntl
        import time

        identity = os.fstat(self.fd)[1:3]
        with _CLEAN_LOCK:
            if identity in _CLEANED:
                return
            _CLEANED.add(identity)
        try:  # this version's scratch, and the tmpXXXXXXXX folders of the versions before it
            entries = [e.name for e in os.scandir(self.fd)
                       if e.name.startswith((SCRATCH_PREFIX, "tmp"))]
        except OSError:
            entries = []
        for entry in entries:
            try:
                descriptor = safe_files.open_folder(entry, dir_fd=self.fd)
            except OSError:
                continue
            try:
                if time.time() - os.fstat(descriptor).st_mtime < SCRATCH_GRACE_S:
                    continue
                fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)  # its build is gone
                shutil.rmtree(entry, dir_fd=self.fd, ignore_errors=True)
            except OSError:
                continue  # a build holds it
            finally:
                os.close(descriptor)


def open_cache(folder) -> CacheFolder:
    """The cache folder made (private) if missing, opened without following a link and
    checked (module docstring); `CompileUnavailable` naming the folder and the reason, an
    ``OSError`` if it cannot be made or opened."""
    path = Path(folder)
    if not os.path.lexists(path):
        _make_parents(path.parent)
        safe_files.make_folder(path, 0o700)
    try:
        descriptor = safe_files.open_folder(path)
    except OSError as exc:
        if exc.errno in (errno.ELOOP, errno.ENOTDIR) and os.path.islink(path):
            raise CompileUnavailable(_unsafe(path, "it is a symbolic link, which the cache does "
                                                   "not follow")) from None
        raise
    try:
        _check_private(os.fstat(descriptor), path, "it")
        _check_above(path)
        cache = CacheFolder(path, descriptor)
    except BaseException:
        os.close(descriptor)
        raise
    cache.clean_scratch()
    return cache


def _make_parents(folder: Path) -> None:
    """The missing folders above the cache made private (``0700``), whatever the umask: made
    with the umask's mode they could be writable by others (``umask 000``), and the cache below
    them would then be refused as unsafe (`_check_above`) by the very command that made them."""
    missing = []
    while not os.path.lexists(folder) and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    for made in reversed(missing):
        safe_files.make_folder(made, 0o700)  # the umask only takes bits away


def _unsafe(path: Path, reason: str) -> str:
    return (f"the compiled-code cache {str(path)!r} is not safe to load libraries from: "
            f"{reason}")


def _check_private(info: os.stat_result, path: Path, what: str) -> None:
    """The cache folder: this user's and not writable by group or others."""
    if info.st_uid != os.geteuid():
        raise CompileUnavailable(_unsafe(path, f"{what} belongs to user {info.st_uid}, not to "
                                               f"you (user {os.geteuid()})"))
    if info.st_mode & 0o022:
        raise CompileUnavailable(_unsafe(path, f"{what} is writable by "
                                               f"{_who(info.st_mode)} (mode "
                                               f"{stat.S_IMODE(info.st_mode):04o}); "
                                               f"chmod go-w {str(path)!r}"))


def _who(mode: int) -> str:
    return " and ".join(w for w, bit in (("its group", 0o020), ("others", 0o002)) if mode & bit)


@functools.lru_cache(maxsize=16)
def _check_above(path: Path) -> None:
    """No folder above the cache lets another user replace it: each belongs to root or to
    this user, and none is writable by others unless sticky (``/tmp``)."""
    for parent in Path(os.path.realpath(path.parent)).joinpath("x").parents:
        try:
            info = os.stat(parent)
        except OSError:
            continue
        if info.st_uid not in (0, os.geteuid()):
            raise CompileUnavailable(_unsafe(path, f"the folder above it, {str(parent)!r}, "
                                                   f"belongs to user {info.st_uid}"))
        if info.st_mode & 0o002 and not info.st_mode & stat.S_ISVTX:
            raise CompileUnavailable(_unsafe(path, f"the folder above it, {str(parent)!r}, is "
                                                   "writable by others (and not sticky): "
                                                   "anyone could replace the cache"))


def _open_own(folder_fd: int, name: str, limit: int):
    """``name`` in the cache opened for reading (binary): a regular file of this user with one
    link, not writable by group or others, at most ``limit`` bytes, opened without following a
    link; ``OSError`` otherwise."""
    descriptor = safe_files.open_reading(name, dir_fd=folder_fd)
    handle = os.fdopen(descriptor, "rb")
    try:
        info = os.fstat(descriptor)
        if not stat.S_ISREG(info.st_mode) or info.st_uid != os.geteuid() or \
                info.st_nlink != 1 or info.st_mode & 0o022:
            raise OSError(errno.EPERM, f"{name} is not a private regular file of this user")
        if info.st_size > limit:
            raise OSError(errno.EFBIG, f"{name} is too large")
    except BaseException:
        handle.close()
        raise
    return handle


def _read_own(folder_fd: int, name: str, limit: int) -> bytes:
    """The bytes of ``name`` in the cache (`_open_own`)."""
    with _open_own(folder_fd, name, limit) as handle:
        return handle.read()


def _private_key(folder_fd: int, path: Path) -> bytes:
    """The cache's secret stamp key: read from ``.ddvp-cache-key`` (a private regular file of
    this user, 32 bytes), or made; a key file that is anything else is replaced (the libraries
    stamped with it are then rebuilt)."""
    for _ in range(3):
        try:
            key = _read_own(folder_fd, KEY_NAME, 64)
            info = os.stat(KEY_NAME, dir_fd=folder_fd, follow_symlinks=False)
            if len(key) == 32 and not info.st_mode & 0o077:
                return key
        except FileNotFoundError:
            pass
        except OSError:
            pass
        _remove(folder_fd, path, KEY_NAME)
        try:
            safe_files.write_new(KEY_NAME, lambda handle: handle.write(secrets.token_bytes(32)),
                                 mode=0o600, dir_fd=folder_fd)
        except FileExistsError:
            continue  # another process made it meanwhile: read theirs
    raise CompileUnavailable(_unsafe(path, f"its key file {KEY_NAME} keeps changing"))


def _remove(folder_fd: int, path: Path, name: str) -> None:
    """``name`` removed from the cache, whatever it is (a folder with what it holds; a link
    itself, not its target)."""
    try:
        os.unlink(name, dir_fd=folder_fd)
    except IsADirectoryError:
        shutil.rmtree(path / name, ignore_errors=True)  # fd-based: follows no link inside
    except OSError:
        pass


def _build(code: str, name: str, compiler: str, cache: CacheFolder, library: str) -> None:
    """Compile ``code`` to ``library`` in the cache and stamp it, each renamed into place
    complete, from a scratch folder locked for the build's length."""
    import fcntl
    import socket

    scratch = Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{socket.gethostname()[:20]}-"
                                           f"{os.getpid()}-", dir=cache.path))
    lock = safe_files.open_folder(scratch)
    try:
        fcntl.flock(lock, fcntl.LOCK_EX)  # a live build: the cleaning of others leaves it
        c_file = scratch / "chunk.c"
        c_file.write_text(code)
        built = scratch / "chunk.so"
        try:
            result = subprocess.run([compiler, *COMPILE_FLAGS, str(c_file), "-o", str(built)],
                                    capture_output=True, text=True)
        except OSError as exc:
            raise CompileUnavailable(f"the C compiler {compiler!r} cannot run: "
                                     f"{exc.strerror or exc}") from None
        with _BUILDS_LOCK:
            _BUILDS[0] += 1
        if result.returncode != 0 or not built.exists():
            raise CompileUnavailable(f"the C compiler {compiler!r} failed on {name} "
                                     f"(exit {result.returncode}): "
                                     f"{result.stderr.strip()[-300:] or 'no message'}")
        os.chmod(built, 0o755)
        stamp = scratch / "chunk.sha256"
        stamp.write_text(cache.stamp(library, built.read_bytes()) + "\n")
        os.chmod(stamp, 0o644)
        scratch_fd = lock
        # atomic: a concurrent build leaves a complete file too; the stamp lands last, so a
        # library is never taken for intact before its bytes are all there
        os.replace("chunk.so", library, src_dir_fd=scratch_fd, dst_dir_fd=cache.fd)
        os.replace("chunk.sha256", library + ".sha256", src_dir_fd=scratch_fd,
                   dst_dir_fd=cache.fd)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
        os.close(lock)


class FunctionBuffer:
    """Calls of ``function`` through ``Function.buffer``: CasADi reads and writes numpy arrays
    in place, without the conversions of a call with DM arguments (about 1 us per column of a
    mapped call, more than a compiled march step).

    Each dense input or output of shape ``(rows, columns)`` is a C-ordered array of shape
    ``(columns, rows)`` (CasADi's column-major order): a mapped function's columns are its rows.
    `__call__` copies the inputs in and returns the output arrays, which the next call of
    the same thread overwrites (one set of arrays per thread: cached functions are shared)."""

    def __init__(self, function: ca.Function):
        self.function = function
        self._local = threading.local()

    def _arrays(self):
        arrays = getattr(self._local, "arrays", None)
        if arrays is None:
            f = self.function
            buffer, trigger = f.buffer()
            inputs = [np.zeros((f.sparsity_in(i).size2(), f.sparsity_in(i).size1()))
                      for i in range(f.n_in())]
            outputs = [np.zeros((f.sparsity_out(i).size2(), f.sparsity_out(i).size1()))
                       for i in range(f.n_out())]
            for i, array in enumerate(inputs):
                buffer.set_arg(i, memoryview(array.reshape(-1)))
            for i, array in enumerate(outputs):
                buffer.set_res(i, memoryview(array.reshape(-1)))
            arrays = self._local.arrays = (buffer, trigger, inputs, outputs)
        return arrays

    @property
    def inputs(self) -> list[np.ndarray]:
        """This thread's input arrays: an input set here stays for every later call that
        passes ``None`` for it (a run's constant parameters, written once)."""
        return self._arrays()[2]

    def __call__(self, *values) -> list[np.ndarray]:
        _, trigger, inputs, outputs = self._arrays()
        for array, value in zip(inputs, values, strict=False):
            if value is not None:  # None: keep what the previous call put there
                array.reshape(-1)[:] = np.ravel(value)
        trigger()
        return outputs


# CPU seconds a function not yet in the cache is evaluated by CasADi's virtual machine before it
# is compiled (`RentedBuffer`): about half of what compiling one of the exact flow's or the
# accuracy check's functions costs (gcc, 0.3-0.6 s), so a short check never pays for a compile
# and a long one pays at most about twice the least it could (the rent-or-buy rule).
COMPILE_AFTER_S = 0.25
# Rent not yet written to the ledger is written once it reaches this (and when the buffer is
# collected or the process exits): a write for about every 10 ms of virtual machine.
LEDGER_EVERY_S = 0.01
LEDGER_LIMIT = 64  # bytes: a ledger is one number


class RentLedger:
    """The CPU seconds the virtual machine has spent on one function, summed over the
    processes that used it, kept in the compiled-code cache beside where its library would be
    (``PREFIX_HASH.so.rent``): a short march spends milliseconds of rent per process and never
    reached `COMPILE_AFTER_S` in one, so its check ran on the virtual machine on every run;
    summed over runs, the rent buys the compile as it would in one long process. The file only
    decides when to compile (nothing is loaded from it): one that cannot be read or holds no
    finite number counts as no rent; concurrent processes may lose each other's last
    increments (later, not never)."""

    def __init__(self, folder: Path, library: str):
        self.folder, self.name = Path(folder), library + ".rent"
        self.unsaved = 0.0
        self.saved = self._read()  # what the ledger held (plus what this process wrote)

    def _read(self) -> float:
        try:
            with open_cache(self.folder) as cache:
                return self._value(cache)
        except (OSError, CompileUnavailable):
            return 0.0

    def _value(self, cache: CacheFolder) -> float:
        try:
            value = float(_read_own(cache.fd, self.name, LEDGER_LIMIT).decode("ascii"))
        except (OSError, ValueError, UnicodeDecodeError):
            return 0.0
        return value if np.isfinite(value) and value > 0 else 0.0

    @property
    def spent(self) -> float:
        return self.saved + self.unsaved

    def close(self) -> None:
        """The rent is paid (the library is built): the ledger removed."""
        self.unsaved = 0.0
        try:
            with open_cache(self.folder) as cache:
                _remove(cache.fd, cache.path, self.name)
        except (OSError, CompileUnavailable):
            pass

    def add(self, seconds: float) -> None:
        self.unsaved += seconds
        if self.unsaved >= LEDGER_EVERY_S:
            self.save()

    def save(self) -> None:
        """The unsaved rent added to the ledger's (read again: another process may have
        added to it); a write that fails is dropped (rent only decides when to compile)."""
        if self.unsaved <= 0:
            return
        unsaved, self.unsaved = self.unsaved, 0.0
        try:
            with open_cache(self.folder) as cache:
                total = self._value(cache) + unsaved
                scratch = safe_files.scratch_name(self.name)
                descriptor = safe_files.open_no_follow(
                    scratch, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600, dir_fd=cache.fd)
                with os.fdopen(descriptor, "w") as handle:
                    handle.write(f"{total!r}\n")
                os.rename(scratch, self.name, src_dir_fd=cache.fd, dst_dir_fd=cache.fd)
                self.saved = total
        except (OSError, CompileUnavailable):
            pass


class RentedBuffer(FunctionBuffer):
    """A `FunctionBuffer` of ``function`` compiled only when that pays: loaded at once if the
    compiled-code cache holds its library; otherwise evaluated by CasADi's virtual machine
    (the same arithmetic, bit for bit: the library is built without contraction to FMA) until
    its calls have taken `COMPILE_AFTER_S` of CPU, summed over the processes that ran it
    (`RentLedger`), then compiled and called compiled from the next call on. Inputs set once
    (a run's parameters) carry over to the compiled function, per thread. ``compiler=None``:
    the virtual machine always."""

    def __init__(self, function: ca.Function, compiler: str | None, cache_dir=None, *,
                 prefix: str = "chunk", compile_after: float = COMPILE_AFTER_S):
        self.symbolic = function
        self.compile_after = float(compile_after)
        self._rent = None  # (code, compiler, folder, prefix) while not compiled
        self.ledger: RentLedger | None = None  # the rent of every process, while not compiled
        self._lock = threading.Lock()
        found = None
        compiler = find_compiler(compiler) if compiler is not None else None
        if compiler is not None:
            try:
                folder, code = cache_folder(cache_dir), generated_code(function)
                found = _compile_code(function, code, compiler, folder, prefix=prefix,
                                      build=False)
                if found is None:  # the code is kept: generated once, compiled if it pays
                    self._rent = (code, compiler, folder, prefix)
                    self.ledger = RentLedger(folder, library_name(
                        code, compiler, prefix=prefix, salt=(ca.__version__,)))
                    weakref.finalize(self, self.ledger.save)
            except CompileUnavailable as reason:  # the virtual machine computes the same
                warn_once(reason)
        super().__init__(found if found is not None else function)
        if self.ledger is not None and self.ledger.saved > 0 and \
                self.ledger.saved >= self.compile_after:
            self._buy()  # earlier processes have paid the rent

    @property
    def compiled(self) -> bool:
        return self.function is not self.symbolic

    def _arrays(self):
        arrays = getattr(self._local, "arrays", None)
        if arrays is not None and getattr(self._local, "function", None) is not self.function:
            del self._local.arrays  # this thread's arrays belong to the function before
            fresh = super()._arrays()
            for new, old in zip(fresh[2], arrays[2], strict=True):
                new[:] = old
            arrays = fresh
        elif arrays is None:
            arrays = super()._arrays()
        self._local.function = self.function
        return arrays

    def __call__(self, *values) -> list[np.ndarray]:
        if self._rent is None:
            return super().__call__(*values)
        started = time.process_time()
        outputs = super().__call__(*values)
        self.ledger.add(time.process_time() - started)
        if self.ledger.spent >= self.compile_after:
            self._buy()
        return outputs

    def buy(self) -> None:
        """Compile now: the rent was paid by another function of the same work (the exact
        flow's first-piece chunk, once its full chunk is compiled)."""
        self._buy()

    def _buy(self) -> None:
        with self._lock:
            if self._rent is None:
                return
            code, compiler, folder, prefix = self._rent
            self._rent = None
            try:
                self.function = _compile_code(self.symbolic, code, compiler, folder,
                                              prefix=prefix)
            except CompileUnavailable as reason:
                warn_once(reason)
                return
            if self.ledger is not None:
                self.ledger.close()


def buffered(function: ca.Function, *key, owner) -> FunctionBuffer:
    """``function`` called through a `FunctionBuffer` kept per ``owner`` (held weakly,
    as cached functions are) and ``key``: the same evaluation as a call with DM arguments,
    without their conversions (about 80-100 us a call). A new buffer where the cache holds
    one of another function under the same key."""
    buffer = cached(owner, ("buffer", *key), lambda: FunctionBuffer(function))
    return buffer if buffer.function is function else FunctionBuffer(function)
