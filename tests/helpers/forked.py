"""A warm interpreter that runs each job in a fork of itself: the documentation tests run the
docs' pages and the examples each in a process of its own, and a fresh interpreter spent most of
a short page's CPU importing numpy, scipy, CasADi, matplotlib and the package again (about 2 s
of CPU a page on a 2-core machine). The warm interpreter imports them once; every job is a
fork of that same state, so a job sees nothing of the jobs before it (its modules' globals,
its folder, its environment and its output are its own and end with it): a page can depend on
no other page. tests/docs/test_warm_python.py checks that a job leaves nothing behind.

A job runs in the folder ``cwd`` with ``env`` added to the environment (``HOME`` included),
stdin read from /dev/null and fds 1 and 2 written to files, under a CPU limit
(``RLIMIT_CPU``: a fork's CPU time starts at zero), and ends as an interpreter does
(``SystemExit``: exit hooks run, output flushed). Kinds: ``"script"`` runs a file as
``__main__`` (``sys.argv[0]`` the file, its folder first on ``sys.path``, as ``python FILE``);
``"blocks"`` runs ``[(line, code), ...]`` in order in one namespace, a block whose first line is
``# after: ddvp ...`` after that command (through ``ddvp_nlp.cli.main``), as
tests/docs/test_doc_blocks.py describes."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

# What the pages and examples import: loaded once, before any fork.
PRELOAD = ("numpy", "scipy.integrate", "scipy.optimize", "casadi", "matplotlib.pyplot",
           "ddvp_nlp", "ddvp_nlp.cli")

SERVER = textwrap.dedent("""
    import gc, json, os, resource, runpy, shlex, sys, traceback
    import matplotlib
    matplotlib.use("Agg")
    for name in PRELOAD:
        __import__(name)
    gc.freeze()  # the imports' objects shared by the forks: no collection walks them


    def blocks(found):
        namespace = {"__name__": "__doc_block__"}
        for line, body in found:
            first = body.lstrip().splitlines()[0] if body.strip() else ""
            if first.startswith("# after: ddvp "):
                from ddvp_nlp.cli import main
                code = main(shlex.split(first[len("# after: ddvp "):]))
                if code != 0:
                    print(f"line {line}: the command of '{first}' exited {code}")
                    return 1
            try:
                exec(compile(body, f"<block at line {line}>", "exec"), namespace)
            except Exception:
                print(f"the block at line {line} failed:")
                traceback.print_exc(file=sys.stdout)
                return 1
        return 0


    def child(job):
        os.chdir(job["cwd"])
        os.environ.update(job["env"])
        resource.setrlimit(resource.RLIMIT_CPU, (job["cpu"], job["cpu"] + 5))
        with open(os.devnull) as stdin:
            os.dup2(stdin.fileno(), 0)
        for fd, name in ((1, "stdout"), (2, "stderr")):
            with open(job[name], "w") as out:
                os.dup2(out.fileno(), fd)
        if job["kind"] == "script":
            sys.argv = [job["path"]]
            sys.path[0] = os.path.dirname(job["path"])
            runpy.run_path(job["path"], run_name="__main__")
            return 0
        return blocks(job["blocks"])


    for line in sys.stdin:
        job = json.loads(line)
        pid = os.fork()
        if pid == 0:
            try:
                sys.exit(child(job))  # an exception: printed, exit 1, as python's own
            finally:
                gc.freeze()  # the exit frees the job's objects by their counts alone
        _, status = os.waitpid(pid, 0)
        print(json.dumps(os.waitstatus_to_exitcode(status)), flush=True)
""").replace("PRELOAD", repr(PRELOAD))


class WarmPython:
    """The warm interpreter (`SERVER`), started in ``folder`` with the environment ``env``,
    and the jobs sent to it, one at a time; their output files are kept in ``folder``."""

    def __init__(self, env: dict, folder: Path):
        self.folder, self.jobs = folder, 0
        self.process = subprocess.Popen([sys.executable, "-c", SERVER], stdin=subprocess.PIPE,
                                        stdout=subprocess.PIPE, text=True, env=env, cwd=folder)

    def run(self, kind: str, cwd: Path, *, cpu: int, env: dict | None = None, **what):
        """``(exit code, stdout, stderr)`` of one job run in the folder ``cwd``: ``path=`` a
        script, or ``blocks=`` a page's python blocks; ``cpu`` seconds at most."""
        self.jobs += 1
        out, err = (self.folder / f"job{self.jobs}.{name}" for name in ("stdout", "stderr"))
        job = {"kind": kind, "cwd": str(cwd), "env": env or {}, "cpu": cpu,
               "stdout": str(out), "stderr": str(err), **what}
        self.process.stdin.write(json.dumps(job) + "\n")
        self.process.stdin.flush()
        answer = self.process.stdout.readline()
        assert answer, f"the warm interpreter ended (exit {self.process.wait()})"
        return json.loads(answer), out.read_text(), err.read_text()

    def close(self) -> int:
        """End the interpreter (its end of input) and wait for it: its CPU and its jobs' are
        counted in this process's children."""
        self.process.stdin.close()
        return self.process.wait()
