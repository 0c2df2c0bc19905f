"""What the ``ddvp`` command sets as it starts (``ddvp_nlp/startup.py``): OpenBLAS with one
thread unless the user chose a count; a library user's import sets nothing."""

import os
import subprocess
import sys

from ddvp_nlp import startup

SHOW = "import os\nimport ddvp_nlp\nprint(os.environ.get('OPENBLAS_NUM_THREADS'))"


def _threads_seen(code: str) -> str:
    environ = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    return subprocess.run([sys.executable, "-c", code], env=environ, check=True,
                          capture_output=True, text=True).stdout.strip()


def test_the_command_starts_openblas_with_one_thread_and_a_library_import_does_not():
    as_command = "import sys\nsys.orig_argv = [sys.executable, '-m', 'ddvp_nlp.cli']\n" + SHOW
    assert _threads_seen(as_command) == "1"
    assert _threads_seen(SHOW) == "None"


def test_a_thread_count_of_the_users_is_kept(monkeypatch):
    monkeypatch.setattr(startup, "started_as_command", lambda: True)
    environ = {"OPENBLAS_NUM_THREADS": "4"}
    startup.one_blas_thread(environ)
    assert environ == {"OPENBLAS_NUM_THREADS": "4"}
    environ = {}
    startup.one_blas_thread(environ)
    assert environ == {"OPENBLAS_NUM_THREADS": "1"}
    monkeypatch.setattr(startup, "started_as_command", lambda: False)
    environ = {}
    startup.one_blas_thread(environ)
    assert environ == {}
