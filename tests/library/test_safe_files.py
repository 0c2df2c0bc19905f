"""Files opened, written and replaced without following a link (ddvp_nlp/safe_files.py): a
planted symbolic link is refused, never followed; a replaced file is the old one or the new one,
never part of either, even when its writer is killed in the middle."""

import errno
import os
import signal
import subprocess
import sys
import time

import pytest

from ddvp_nlp import safe_files


@pytest.fixture
def planted(tmp_path):
    """A folder holding ``secret`` and a link ``link -> secret``."""
    (tmp_path / "secret").write_bytes(b"not yours")
    os.symlink(tmp_path / "secret", tmp_path / "link")
    (tmp_path / "sub").mkdir()
    os.symlink(tmp_path / "sub", tmp_path / "sublink")
    return tmp_path


@pytest.mark.parametrize("opener", [
    lambda name, fd: safe_files.open_no_follow(name, dir_fd=fd),
    lambda name, fd: safe_files.open_reading(name, dir_fd=fd),
    lambda name, fd: safe_files.open_no_follow(name, os.O_WRONLY | os.O_APPEND, dir_fd=fd),
    lambda name, fd: safe_files.open_no_follow(name, os.O_RDWR | os.O_CREAT, 0o644, dir_fd=fd),
])
def test_every_open_refuses_a_link(planted, opener):
    folder = safe_files.open_folder(planted)
    try:
        with pytest.raises(OSError) as refused:
            opener("link", folder)
        assert refused.value.errno == errno.ELOOP
        assert safe_files.reason(refused.value) == \
            "it is a symbolic link, which ddvp does not follow"
    finally:
        os.close(folder)
    assert (planted / "secret").read_bytes() == b"not yours"


def test_a_folder_link_is_refused_and_named(planted):
    with pytest.raises(OSError) as refused:
        safe_files.open_folder(planted / "sublink")
    assert refused.value.errno in (errno.ELOOP, errno.ENOTDIR)
    folder = safe_files.open_folder(planted)
    try:
        assert safe_files.is_link("sublink", dir_fd=folder) is True
    finally:
        os.close(folder)
    assert safe_files.is_link(planted / "sub") is False
    assert safe_files.is_link(planted / "missing") is False


def test_writing_and_replacing_never_go_through_a_link(planted):
    """A new file is never created through a link (``O_EXCL``); a replacement renames over
    the link itself: the target keeps its bytes."""
    folder = safe_files.open_folder(planted)
    try:
        with pytest.raises(FileExistsError):
            safe_files.write_new("link", lambda handle: handle.write(b"mine"), dir_fd=folder)
        safe_files.replace_file("link", lambda handle: handle.write(b"mine"), dir_fd=folder)
    finally:
        os.close(folder)
    assert not (planted / "link").is_symlink()
    assert (planted / "link").read_bytes() == b"mine"
    assert (planted / "secret").read_bytes() == b"not yours"
    assert sorted(p.name for p in planted.iterdir()) == ["link", "secret", "sub", "sublink"]


def test_a_failed_write_leaves_the_old_file_and_no_scratch(tmp_path):
    (tmp_path / "result").write_bytes(b"old")

    def failing(handle):
        handle.write(b"half of the ne")
        raise OSError(errno.ENOSPC, "No space left on device")

    folder = safe_files.open_folder(tmp_path)
    try:
        with pytest.raises(OSError, match="No space"):
            safe_files.replace_file("result", failing, dir_fd=folder)
        with pytest.raises(KeyboardInterrupt):
            safe_files.write_new("fresh", lambda handle: (_ for _ in ()).throw(
                KeyboardInterrupt()), dir_fd=folder)
    finally:
        os.close(folder)
    assert [p.name for p in tmp_path.iterdir()] == ["result"]
    assert (tmp_path / "result").read_bytes() == b"old"


def test_make_folder_says_whether_it_made_one(tmp_path):
    assert safe_files.make_folder(tmp_path / "new", 0o700) is True
    assert os.stat(tmp_path / "new").st_mode & 0o777 == 0o700 & ~_umask()
    assert safe_files.make_folder(tmp_path / "new") is False
    os.symlink(tmp_path / "elsewhere", tmp_path / "dangling")
    assert safe_files.make_folder(tmp_path / "dangling") is False  # never made through it
    assert not (tmp_path / "elsewhere").exists()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


# The writer loads safe_files.py from its file, not through the package: the module needs only
# the standard library, and importing ddvp_nlp (numpy with it) cost each of the five writers
# 0.45 s of CPU, ten times the rest of its start.
WRITER = r"""
import importlib.util, os, sys
spec = importlib.util.spec_from_file_location("safe_files", sys.argv[3])
safe_files = importlib.util.module_from_spec(spec)
spec.loader.exec_module(safe_files)
folder = safe_files.open_folder(sys.argv[1])
size = int(sys.argv[2])
print("ready", flush=True)
k = 0
while True:
    k = (k + 1) % 200
    byte = bytes([65 + k % 26])
    safe_files.replace_file("data", lambda h: [h.write(byte * 4096) for _ in range(size)],
                            dir_fd=folder)
"""


def test_a_killed_replacement_leaves_the_old_or_the_new_file_whole(tmp_path):
    """A writer replacing a file in a loop, killed at moments nobody chose: the file is always
    one complete version (one repeated byte, full length), never a torn one."""
    size = 64  # 256 kB a version: a kill lands inside a write most of the time
    (tmp_path / "data").write_bytes(b"@" * 4096 * size)
    for delay in (0.0, 0.013, 0.031, 0.05, 0.077):
        child = subprocess.Popen([sys.executable, "-c", WRITER, str(tmp_path), str(size),
                                  safe_files.__file__], stdout=subprocess.PIPE)
        try:
            assert child.stdout.readline().strip() == b"ready"
            deadline = time.monotonic() + delay
            while time.monotonic() < deadline:
                data = (tmp_path / "data").read_bytes()  # a reader meanwhile
                assert len(data) == 4096 * size and data == data[:1] * len(data)
        finally:
            child.send_signal(signal.SIGKILL)
            child.wait()
            child.stdout.close()
        data = (tmp_path / "data").read_bytes()
        assert len(data) == 4096 * size and data == data[:1] * len(data)
