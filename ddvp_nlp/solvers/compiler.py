"""Finding a C compiler and compiling CasADi functions once per content hash.

Compiled libraries are cached in ``cache_dir`` (argument, else ``$DDVP_NLP_CACHE``, else
``~/.cache/ddvp_nlp``) under a hash of the generated code, the compiler and its flags. Each build
compiles to a temporary file and renames it into place, so two processes building the same entry
at once both end with a complete library.

The cache heals: beside each library ``chunk_KEY.so`` its SHA-256 is written at build time
(``chunk_KEY.so.sha256``), and a library is loaded only when its bytes match; a truncated,
empty or foreign file (which crashed every later run with a bus error) is rebuilt. When the cache
folder cannot be used or the compiler fails, `CompileUnavailable` says why, and the
callers run CasADi's virtual machine instead, with one warning (`warn_once`).
"""

from __future__ import annotations

import functools
import hashlib
import os
import shutil
import subprocess
import tempfile
import threading
import warnings
from pathlib import Path

import casadi as ca
import numpy as np

from ..cache import cached
from ..errors import InputError

COMPILE_FLAGS = ("-O2", "-fPIC", "-shared", "-ffp-contract=off")


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
                     prefix: str = "chunk") -> ca.Function:
    """Generate, compile (once per hash; again if the cached library fails its checksum) and
    load ``function`` as ``PREFIX_HASH.so``. Raises `CompileUnavailable` if the folder or
    compiler fails."""
    source = ca.CodeGenerator("ddvp_chunk.c", {"with_header": False})
    source.add(function)
    library = compile_source(source.dump(), function.name(), compiler, folder, prefix=prefix,
                             salt=(ca.__version__,))
    return ca.external(function.name(), str(library))


def compile_source(code: str, name: str, compiler: str, folder, *, prefix: str,
                   salt=()) -> Path:
    """``PREFIX_HASH.so`` in ``folder``, compiled from the C ``code`` (once per hash of the
    code, the compiler, its flags and ``salt``; again if the cached library fails its
    checksum), each file renamed into place complete. Raises `CompileUnavailable` if the
    folder or the compiler fails; ``name`` is what a compiler error names."""
    key = hashlib.sha256("\0".join([code, compiler, *COMPILE_FLAGS, *salt])
                         .encode()).hexdigest()[:24]
    library = Path(folder) / f"{prefix}_{key}.so"
    try:
        Path(folder).mkdir(parents=True, exist_ok=True)
        if not _intact(library):
            _build(code, name, compiler, library)
    except OSError as exc:
        raise CompileUnavailable(f"the compiled-code cache {str(folder)!r} cannot be used: "
                                 f"{exc.strerror or exc}") from None
    return library


_BUILDS = [0]  # C compiles run by this process (a list: one mutable count, lock-free reads)
_BUILDS_LOCK = threading.Lock()


def build_count() -> int:
    """How many C compiles this process has run (cache hits are not compiles): what the tests
    count to show that a scene compiles once and that ensemble workers compile nothing."""
    return _BUILDS[0]


def _intact(library: Path) -> bool:
    """The library exists and its bytes match the checksum written when it was built."""
    stamp = library.with_name(library.name + ".sha256")
    try:
        return stamp.read_text().strip() == _sha256(library)
    except OSError:
        return False


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _build(code: str, name: str, compiler: str, library: Path) -> None:
    """Compile ``code`` to ``library`` and its checksum, each renamed into place complete."""
    folder = library.parent
    with tempfile.TemporaryDirectory(dir=folder) as scratch:
        c_file = Path(scratch) / "chunk.c"
        c_file.write_text(code)
        built = Path(scratch) / "chunk.so"
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
        stamp = Path(scratch) / "chunk.sha256"
        stamp.write_text(_sha256(built) + "\n")
        os.replace(built, library)  # atomic: a concurrent build leaves a complete file too
        os.replace(stamp, library.with_name(library.name + ".sha256"))


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


def buffered(function: ca.Function, *key, owner) -> FunctionBuffer:
    """``function`` called through a `FunctionBuffer` kept per ``owner`` (held weakly,
    as cached functions are) and ``key``: the same evaluation as a call with DM arguments,
    without their conversions (about 80-100 us a call). A new buffer where the cache holds
    one of another function under the same key."""
    buffer = cached(owner, ("buffer", *key), lambda: FunctionBuffer(function))
    return buffer if buffer.function is function else FunctionBuffer(function)
