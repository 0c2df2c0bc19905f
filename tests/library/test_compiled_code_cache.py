"""The compiled-code cache trusted as ccache's, pip's or ~/.ssh are (issue 39): a private
folder of this user, nothing followed through a link, a library loaded only from a private
regular file whose keyed stamp matches its bytes; anything else found in the cache is rebuilt,
never loaded and never a crash; the scratch of a killed build is removed by the next user."""

import hashlib
import os
import shutil
import subprocess
import time
import warnings

import casadi as ca
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from ddvp_nlp import Compilation, load_scene, march
from ddvp_nlp.solvers import compiler
from ddvp_nlp.solvers.compiler import (
    SCRATCH_GRACE_S,
    CompileUnavailable,
    build_count,
    compile_function,
    find_compiler,
    open_cache,
)

COMPILER = find_compiler()
pytestmark = pytest.mark.skipif(COMPILER is None, reason="no C compiler on this machine")

# A library whose start-up code leaves a mark: what a planted library would run on load.
PLANTED = """#include <stdio.h>
__attribute__((constructor)) static void planted(void) {
    FILE *f = fopen("%s", "w"); if (f) { fputs("ran", f); fclose(f); }
}
"""


def square():
    x = ca.SX.sym("x")
    return ca.Function("trust_square", [x], [x * x])


def entry_name(cache) -> str:
    """The cache's library of `square`, built once."""
    compile_function(square(), COMPILER, cache)
    (library,) = [p.name for p in cache.glob("chunk_*.so")]
    return library


def planted_library(tmp_path, marker) -> bytes:
    source = tmp_path / "planted.c"
    source.write_text(PLANTED % marker)
    subprocess.run([COMPILER, "-shared", "-fPIC", str(source), "-o", str(tmp_path / "p.so")],
                   check=True)
    return (tmp_path / "p.so").read_bytes()


def loads_and_works(cache) -> bool:
    return float(compile_function(square(), COMPILER, cache)(3.0)) == 9.0


def test_a_planted_library_with_a_checksum_beside_it_is_rebuilt_not_loaded(tmp_path):
    """The old cache loaded any library whose plain SHA-256 stood beside it: planted code ran.
    The stamp is keyed by the cache's private key, so a copied-in pair is rebuilt."""
    cache, marker = tmp_path / "cache", tmp_path / "marker"
    name = entry_name(cache)
    data = planted_library(tmp_path, marker)
    (cache / name).write_bytes(data)
    (cache / (name + ".sha256")).write_text(hashlib.sha256(data).hexdigest() + "\n")
    before = build_count()
    assert loads_and_works(cache)
    assert build_count() == before + 1 and not marker.exists()


def test_a_damaged_library_with_a_matching_stamp_is_rebuilt_never_a_crash(tmp_path):
    """Even a stamp made with the cache's own key (a damaged file, or a planter who could read
    the key) only gets the file to the loader, whose refusal is a rebuild, not an error."""
    cache = tmp_path / "cache"
    name = entry_name(cache)
    garbage = b"\x7fELF" + bytes(range(256)) * 4
    with open_cache(cache) as opened:
        (cache / name).write_bytes(garbage)
        (cache / (name + ".sha256")).write_text(opened.stamp(name, garbage) + "\n")
        assert opened.intact(name)
    before = build_count()
    assert loads_and_works(cache)
    assert build_count() == before + 1


@pytest.mark.parametrize("kind", ["symlink", "hardlink", "other-writable", "other-user"])
def test_a_library_that_is_not_a_private_file_of_this_user_is_rebuilt(tmp_path, kind):
    cache, marker = tmp_path / "cache", tmp_path / "marker"
    name = entry_name(cache)
    outside = tmp_path / "outside.so"
    outside.write_bytes(planted_library(tmp_path, marker))
    library = cache / name
    with open_cache(cache) as opened:
        stamp = opened.stamp(name, outside.read_bytes())
    library.unlink()
    if kind == "symlink":
        os.symlink(outside, library)
    elif kind == "hardlink":
        os.link(outside, library)
    else:
        shutil.copy(outside, library)
        if kind == "other-writable":
            library.chmod(0o777)
        elif os.geteuid() == 0:
            os.chown(library, 12345, 12345)
        else:
            pytest.skip("only root can give a file to another user")
    (cache / (name + ".sha256")).write_text(stamp + "\n")
    before = build_count()
    assert loads_and_works(cache)
    assert build_count() == before + 1 and not marker.exists()
    assert not library.is_symlink() and library.stat().st_nlink == 1
    assert outside.read_bytes()[:4] == b"\x7fELF"  # the link's target is untouched


@pytest.mark.parametrize("state, reason", [
    ("group-writable", "is writable by its group (mode 0770)"),
    ("other-writable", "is writable by its group and others (mode 0777)"),
    ("other-user", "belongs to user 12345"),
    ("symlink", "it is a symbolic link, which the cache does not follow"),
    ("open-parent", "is writable by others (and not sticky)"),
])
def test_a_cache_folder_others_could_write_is_refused_naming_why(tmp_path, state, reason):
    cache = tmp_path / "cache"
    cache.mkdir(mode=0o700)
    if state == "group-writable":
        cache.chmod(0o770)
    elif state == "other-writable":
        cache.chmod(0o777)
    elif state == "other-user":
        if os.geteuid() != 0:
            pytest.skip("only root can give a folder to another user")
        os.chown(cache, 12345, 12345)
    elif state == "symlink":
        (tmp_path / "real").mkdir(mode=0o700)
        cache.rmdir()
        os.symlink(tmp_path / "real", cache)
    else:
        parent = tmp_path / "open"
        parent.mkdir()
        parent.chmod(0o777)
        cache = parent / "cache"
    with pytest.raises(CompileUnavailable) as info:
        compile_function(square(), COMPILER, cache)
    assert str(cache) in str(info.value) and reason in str(info.value)
    assert not list((tmp_path / "real").glob("*")) if state == "symlink" else True


def test_a_refused_cache_runs_the_march_on_the_virtual_machine_with_one_warning(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir()
    cache.chmod(0o777)
    compiler.forget_warnings()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        solution = march(load_scene("harmonic").system, [1.0], [0.0], (0.0, 1.0), tau0=0.1,
                         compilation=Compilation(cache_dir=cache))
    assert solution.success and solution.stats["path"] == "vm"
    told = [str(w.message) for w in caught if "not safe to load libraries" in str(w.message)]
    assert len(told) == 1 and "chmod go-w" in told[0]
    assert not list(cache.iterdir())


def test_a_missing_cache_folder_is_made_private(tmp_path):
    cache = tmp_path / "a" / "cache"
    assert loads_and_works(cache)
    assert (cache.stat().st_mode & 0o777) == 0o700
    assert ((cache / ".ddvp-cache-key").stat().st_mode & 0o777) == 0o600


def test_a_cache_made_under_umask_000_is_private_and_used(tmp_path):
    """Under ``umask 000`` the folders made above a new cache came out ``0777`` and the cache
    was then refused as unsafe by the command that made them (issue 45)."""
    cache = tmp_path / "made" / "under" / "cache"
    old = os.umask(0)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a refused cache would warn and fall back
            assert loads_and_works(cache)
    finally:
        os.umask(old)
    for folder in (tmp_path / "made", tmp_path / "made" / "under", cache):
        assert folder.stat().st_mode & 0o022 == 0, folder
    assert build_count() >= 1


def test_a_huge_sparse_library_is_rebuilt_without_reading_it_into_memory(tmp_path):
    """A damaged library the size of 10 GB (sparse: it takes no disk) was read whole into
    memory to check its stamp (issue 45): it is now measured first and rebuilt."""
    import tracemalloc

    cache = tmp_path / "cache"
    name = entry_name(cache)
    with open(cache / name, "r+b") as handle:
        handle.truncate(10 * 2 ** 30)
    before = build_count()
    tracemalloc.start()
    try:
        assert loads_and_works(cache)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert build_count() == before + 1
    assert peak < 64 * 2 ** 20  # the library's size was never read into memory
    assert (cache / name).stat().st_size < compiler.LIBRARY_LIMIT


def test_the_stamp_read_a_block_at_a_time_is_the_stamp_of_the_bytes(tmp_path):
    cache = tmp_path / "cache"
    name = entry_name(cache)
    with open_cache(cache) as opened:
        assert opened._file_stamp(name) == opened.stamp(name, (cache / name).read_bytes())


def test_the_scratch_of_a_killed_build_is_removed_by_the_next_run(tmp_path):
    """A build killed mid-compile left its scratch folder for good. Scratch folders are
    locked by their build; one that is unlocked and older than the grace is a dead build's."""
    import fcntl

    cache = tmp_path / "cache"
    entry_name(cache)
    old = time.time() - 2 * SCRATCH_GRACE_S
    dead, fresh, live, legacy = (cache / name for name in (
        ".build-host-1-dead", ".build-host-2-fresh", ".build-host-3-live", "tmpab12cd34"))
    for folder in (dead, fresh, live, legacy):
        folder.mkdir()
        (folder / "chunk.c").write_text("int x;\n")
    for folder in (dead, live, legacy):
        os.utime(folder, (old, old))
    held = os.open(live, os.O_RDONLY | os.O_DIRECTORY)
    fcntl.flock(held, fcntl.LOCK_EX)  # a build still running in another process
    try:
        compiler._CLEANED.clear()  # a new process: it cleans on its first use of the cache
        assert loads_and_works(cache)
        assert not dead.exists() and not legacy.exists()
        assert fresh.exists() and live.exists()
    finally:
        os.close(held)


ENTRY_STATES = ["missing", "intact", "garbage", "truncated", "empty", "symlink", "hardlink",
                "folder", "fifo", "writable"]


@pytest.mark.slow(why="processes")
@given(library=st.sampled_from(ENTRY_STATES), stamp=st.sampled_from(
    ["ok", "missing", "garbage", "folder", "symlink", "huge", "plain-sha256"]),
    key=st.sampled_from(["ok", "missing", "short", "public", "folder", "symlink"]))
@example(library="intact", stamp="ok", key="ok")
@example(library="intact", stamp="plain-sha256", key="ok")  # the old cache's stamp
@settings(max_examples=20, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_any_state_of_a_cache_entry_loads_a_working_library_and_runs_nothing_planted(
        tmp_path_factory, library, stamp, key):
    root = tmp_path_factory.mktemp("entry")
    cache, marker = root / "cache", root / "marker"
    name = entry_name(cache)
    planted = planted_library(root, marker)
    path, stamp_path, key_path = cache / name, cache / (name + ".sha256"), cache / ".ddvp-cache-key"
    with open_cache(cache) as opened:
        good_stamp = opened.stamp(name, planted)
    _set_entry(path, library, planted, root)
    _set_stamp(stamp_path, stamp, good_stamp, planted, root)
    _set_key(key_path, key, root)
    assert loads_and_works(cache)
    # only a stamp made with the cache's own private key gets planted bytes to the loader (a
    # planter who can read a 0600 file of this user is this user); everything else is rebuilt
    signed = library == "intact" and stamp == "ok" and key == "ok"
    assert marker.exists() == signed


def _set_entry(path, state, planted, root):
    if state == "missing":
        path.unlink()
    elif state in ("intact", "writable"):
        path.write_bytes(planted)
        path.chmod(0o777 if state == "writable" else 0o755)
    elif state in ("garbage", "truncated", "empty"):
        path.write_bytes({"garbage": b"\0" * 999, "truncated": planted[:100],
                          "empty": b""}[state])
    elif state in ("symlink", "hardlink"):
        (root / "elsewhere.so").write_bytes(planted)
        path.unlink()
        (os.symlink if state == "symlink" else os.link)(root / "elsewhere.so", path)
    elif state == "folder":
        path.unlink()
        path.mkdir()
    elif state == "fifo":
        path.unlink()
        os.mkfifo(path)


def _set_stamp(path, state, good, planted, root):
    path.unlink(missing_ok=True)
    if state == "ok":
        path.write_text(good + "\n")
    elif state == "garbage":
        path.write_bytes(b"\xff\xfe not a stamp")
    elif state == "folder":
        path.mkdir()
    elif state == "symlink":
        (root / "stamp").write_text(good + "\n")
        os.symlink(root / "stamp", path)
    elif state == "huge":
        path.write_text("0" * 100_000)
    elif state == "plain-sha256":
        path.write_text(hashlib.sha256(planted).hexdigest() + "\n")


def _set_key(path, state, root):
    if state == "ok":
        return
    path.unlink()
    if state == "short":
        path.write_bytes(b"abc")
        path.chmod(0o600)
    elif state == "public":
        path.write_bytes(os.urandom(32))
        path.chmod(0o644)
    elif state == "folder":
        path.mkdir()
    elif state == "symlink":
        (root / "key").write_bytes(os.urandom(32))
        os.symlink(root / "key", path)


def test_a_fifo_in_the_cache_does_not_hang_the_check(tmp_path):
    cache = tmp_path / "cache"
    name = entry_name(cache)
    (cache / name).unlink()
    os.mkfifo(cache / name)
    assert loads_and_works(cache)


def test_a_function_not_in_the_cache_is_compiled_only_once_its_calls_cost_a_compile(tmp_path):
    """RentedBuffer: the virtual machine until the calls have taken ``compile_after`` of CPU,
    then the compiled library, with the inputs set once carried over; a second buffer of the
    same function loads the library at once; without a compiler, never compiled."""

    from ddvp_nlp.solvers.compiler import RentedBuffer, find_compiler

    if find_compiler("auto") is None:
        pytest.skip("no C compiler")
    x, a = ca.SX.sym("x", 3), ca.SX.sym("a")
    function = ca.Function("rented", [x, a], [ca.sin(a * x) + x ** 3])
    cache = tmp_path / "cache"
    values = np.array([0.1, -0.7, 2.0])
    for compile_after, compiled_after_call in ((1e9, False), (0.0, True)):
        rented = RentedBuffer(function, "auto", cache, compile_after=compile_after)
        assert not rented.compiled
        rented.inputs[1][:] = 0.3  # set once, as a run's parameters are
        first = rented(values, None)[0].copy()
        assert rented.compiled is compiled_after_call
        second = rented(values, None)[0].copy()  # the compiled call keeps the parameter
        np.testing.assert_allclose(second, first, rtol=4 * np.finfo(float).eps, atol=0)
    again = RentedBuffer(function, "auto", cache)
    assert again.compiled  # in the cache now: loaded at once
    assert not RentedBuffer(function, None, cache).compiled
