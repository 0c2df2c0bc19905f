"""Fault injection against the ``ddvp`` command line: signals at random moments, full and
read-only disks on a small file system, concurrent writers, planted links, hostile files,
scenes and numbers. Every case runs the real command in a subprocess, in a folder of its own,
and is judged by the same checks:

- **traceback**: ``Traceback`` on stderr;
- **code**: the exit code is not one the case allows (0 success, 1 failed/interrupted/not
  written, 2 refused input);
- **hang**: the command did not end within its time (``TIMEOUT_S``; after a signal,
  ``STOP_TIMEOUT_S``);
- **torn/lost/lying**: a run folder that is not readable by the checking reader
  (``read_set``), a message that says what was written which the folder does not hold,
  scratch files or a lock file left behind, worker processes alive after the command ended;
- **link**: the target of a planted symbolic link was written or created;
- **code run**: code the user did not name ran (a planted scene, library or expression left
  its mark file, ``pwned``);
- **refused under load**: of valid runs started together on a loaded machine, those refused
  (the ``load`` group: 8 concurrent marches of built-in scenes, their scene limit 2 s).

The groups of issue 39 try what the tool wrote (``resume``, ``grids``, ``folders``: a run
folder, a grid file and a default folder name are data, never code or authority), the compiled
code ``cache``, the ``events`` evaluator, the ``bounds`` of a scene's code (defeated timers, a
process ended by a scene, threads left behind), the ``cluster`` file and the ``load`` group;
each with cases no issue names. Issue 45 adds ``backward`` (every method run backwards),
``merges`` (chaos parts that do not belong), ``ranges`` (non-finite options), ``target``
(``--target-error`` failures are statuses, a resumed target run keeps its step), ``thinned``
(``--keep-every`` where it cannot keep its promise) and ``supervision`` (what a scene starts
ends with the command; a scene deaf to SIGTERM does not keep the march from saving).

A full disk and a read-only one are a real tmpfs mounted for the run (root); where mounting is
refused, a file-size limit (EFBIG, as a full disk) stands in and the page says so.

Usage: ``python scripts/pages/faults.py [--seed N] [--out docs/reliability/faults.md] [--only
GROUP[,GROUP...]] [--quick]``. Prints the summary table and the counts (cases run, tracebacks,
wrong exit codes, hangs, torn/lost/lying results, code run that the user did not name, valid runs
refused under load); writes the page with every case and its outcome and the machine and date its
seconds were measured on (``ddvp_nlp.io.machine``), except with ``--only``. About ten minutes
(root, for the tmpfs); ``--quick`` runs the ``numbers`` group alone (about a minute) and writes
its page, not for docs/.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

TIMEOUT_S = 180.0
STOP_TIMEOUT_S = 30.0
SCENE_LIMIT_S = "3"  # $DDVP_SCENE_TIME_LIMIT for the cases: a hanging scene ends in seconds
PYTHON = sys.executable
VICTIM = "victim: this file must not change\n"


@dataclass
class Case:
    group: str
    name: str
    argv: list[str]
    codes: tuple = (0,)
    setup: object = None          # setup(folder) before the command
    signals: list = field(default_factory=list)  # [(delay_s, signal), ...] from the start
    check: object = None          # check(folder, result) -> list of problems
    expect_text: str = ""         # a text stderr must hold
    timeout: float = TIMEOUT_S
    env: dict = field(default_factory=dict)  # more environment ({folder}: the case's folder)
    teardown: object = None       # teardown(folder) once the command ended, before the checks


@dataclass
class Result:
    case: Case
    code: int | None
    stdout: str
    stderr: str
    seconds: float
    stop_s: float | None = None
    problems: list = field(default_factory=list)
    kinds: set = field(default_factory=set)
    refused_under_load: int = 0   # the load group: valid runs refused


# -- running ------------------------------------------------------------------------------

def run_case(case: Case, root: Path, tag: str) -> Result:
    folder = root / re.sub(r"[^A-Za-z0-9_.-]+", "_", f"{case.group}-{case.name}")[:120]
    base, number = folder, 1
    while folder.exists():  # two names that differ only in what the folder name leaves out
        number += 1
        folder = base.with_name(f"{base.name}-{number}")
    folder.mkdir(parents=True)
    if case.setup:
        case.setup(folder)
    env = {**os.environ, "DDVP_SCENE_TIME_LIMIT": SCENE_LIMIT_S, "DDVP_FAULT_CASE": tag,
           **{k: v.format(folder=folder) for k, v in case.env.items()}}
    started = time.monotonic()
    process = subprocess.Popen([PYTHON, "-m", "ddvp_nlp.cli", *case.argv], cwd=folder,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env=env, start_new_session=True)
    stop_s = None
    first_signal = None
    for delay, sig in case.signals:
        wait = started + delay - time.monotonic()
        if wait > 0:
            with contextlib.suppress(subprocess.TimeoutExpired):
                process.wait(wait)
        if process.poll() is not None:
            break
        with contextlib.suppress(ProcessLookupError):
            process.send_signal(sig)
        first_signal = first_signal or time.monotonic()
    limit = STOP_TIMEOUT_S if first_signal else case.timeout
    try:
        stdout, stderr = process.communicate(timeout=limit if not first_signal else
                                             max(1.0, first_signal + limit - time.monotonic()))
        code = process.returncode
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        stdout, stderr = process.communicate()
        code = None
    ended = time.monotonic()
    if first_signal:
        stop_s = ended - first_signal
    result = Result(case, code, stdout, stderr, ended - started, stop_s)
    if case.teardown:
        case.teardown(folder)
    judge(result, folder, tag)
    return result


def judge(result: Result, folder: Path, tag: str) -> None:
    case, problems, kinds = result.case, result.problems, result.kinds
    killed = any(sig == signal.SIGKILL for _, sig in case.signals)
    if result.code is None:
        problems.append("did not end (hang)")
        kinds.add("hang")
    if "Traceback" in result.stderr:
        problems.append("traceback: " + result.stderr.strip().splitlines()[-1][:160])
        kinds.add("traceback")
    allowed = case.codes if not killed else (-signal.SIGKILL, *case.codes)
    if result.code is not None and result.code not in allowed:
        problems.append(f"exit {result.code}, expected {' or '.join(map(str, case.codes))}")
        kinds.add("code")
    if case.expect_text and result.code is not None and case.expect_text not in result.stderr:
        problems.append(f"stderr lacks {case.expect_text!r}")
        kinds.add("code")
    for path in folder.rglob("*"):
        if path.name == "victim" and path.read_text() != VICTIM:
            problems.append(f"link followed: {path} was written")
            kinds.add("link")
        if path.name == "absent-target":
            problems.append(f"link followed: {path} was created")
            kinds.add("link")
        if path.name == "pwned":
            problems.append(f"code the user did not name ran: {path} was made")
            kinds.add("code run")
    problems += _leftovers(folder, killed, kinds)
    problems += _lying(result, folder, kinds)
    survivors = _processes_tagged(tag)
    if survivors:
        problems.append(f"{len(survivors)} processes alive after the command ended")
        kinds.add("torn/lost/lying")
        for pid in survivors:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
    if case.check and result.code is not None:
        found = case.check(folder, result)
        problems += found
        if found:
            kinds.add("torn/lost/lying")


def _leftovers(folder: Path, killed: bool, kinds: set) -> list[str]:
    """Scratch and lock files left behind, folders that no reader can read."""
    from ddvp_nlp.errors import InputError
    from ddvp_nlp.io import read_set

    problems = []
    for meta in folder.rglob("meta.json"):
        if meta.parent.name.startswith(("planted", "torn")):  # damaged on purpose by the case
            continue
        try:
            read_set(meta.parent)
        except InputError as exc:
            problems.append(f"unreadable folder {meta.parent.relative_to(folder)}: {exc}")
            kinds.add("torn/lost/lying")
    if not killed:
        for path in folder.rglob("*"):
            if path.name.endswith(".tmp") and path.name.startswith("."):
                problems.append(f"scratch file left: {path.relative_to(folder)}")
                kinds.add("torn/lost/lying")
            if path.name == ".ddvp.lock" and not path.is_symlink():
                problems.append(f"lock file left: {path.relative_to(folder)}")
                kinds.add("torn/lost/lying")
    return problems


def _lying(result: Result, folder: Path, kinds: set) -> list[str]:
    """What the messages say was written, against what the folder holds."""
    from ddvp_nlp.errors import InputError
    from ddvp_nlp.io import read_run

    problems = []
    said = re.search(r"written whole to (\S+)/ \((\d+) nodes", result.stderr)
    if said:
        try:
            arrays, _ = read_run(folder / said.group(1))
            if arrays["t"].size != int(said.group(2)):
                problems.append(f"says {said.group(2)} nodes were written, the folder holds "
                                f"{arrays['t'].size}")
        except InputError as exc:
            problems.append(f"says the run was written, but: {exc}")
    kept = re.search(r"(\d+) of (\d+) rows are finished and kept in (\S+) ", result.stderr)
    if kept:
        journal = folder / kept.group(3)
        rows = _journal_rows(journal)
        if rows != int(kept.group(1)):
            problems.append(f"says {kept.group(1)} rows are kept, {journal.name} holds {rows}")
    written = re.search(r"written to (\S+)/", result.stdout)
    if written and result.code in (0, 1) and "written to" in result.stdout:
        from ddvp_nlp.io import read_set

        try:
            read_set(folder / written.group(1))
        except InputError as exc:
            problems.append(f"says written to {written.group(1)}, but: {exc}")
    if problems:
        kinds.add("torn/lost/lying")
    return problems


def _journal_rows(path: Path) -> int:
    import csv

    if not path.exists():
        return -1
    with open(path, newline="") as handle:
        return sum(1 for row in csv.DictReader(handle) if None not in row.values())


def _processes_tagged(tag: str) -> list[int]:
    """Processes (other than this one) whose environment carries the case's tag, after a
    short grace for workers that are on their way out."""
    needle = f"DDVP_FAULT_CASE={tag}".encode()
    for _ in range(30):
        found = []
        for entry in Path("/proc").iterdir():
            if not entry.name.isdigit() or int(entry.name) == os.getpid():
                continue
            with contextlib.suppress(OSError):
                if needle in (entry / "environ").read_bytes().split(b"\0"):
                    found.append(int(entry.name))
        if not found:
            return []
        time.sleep(0.2)
    return found


# -- file systems ------------------------------------------------------------------------------

class SmallDisk:
    """A tmpfs of ``size`` mounted at a fresh folder (root only), or ``None``."""

    def __init__(self, size: str = "2m"):
        self.path = Path(tempfile.mkdtemp(prefix="ddvp-faults-fs-"))
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs",
                               str(self.path)], capture_output=True)
        self.mounted = done.returncode == 0

    def fill(self, leave: int) -> None:
        """Fill the file system but ``leave`` bytes."""
        stat = os.statvfs(self.path)
        free = stat.f_bavail * stat.f_frsize
        with open(self.path / "filler", "wb") as handle:
            handle.write(b"\0" * max(0, free - leave))

    def read_only(self) -> None:
        subprocess.run(["mount", "-o", "remount,ro", str(self.path)], check=True)

    def close(self) -> None:
        if self.mounted:
            subprocess.run(["umount", "-l", str(self.path)], capture_output=True)
        shutil.rmtree(self.path, ignore_errors=True)


# -- the cases -----------------------------------------------------------------------------

QUICK_MARCH = ["march", "harmonic", "--set", "t_end=5", "--no-progress"]
LONG_MARCH = ["march", "pendulum", "--set", "t_end=1e7", "--no-progress", "--max-steps",
              "3000000", "--checkpoint-every", "1"]
QUICK_SWEEP = ["sweep", "harmonic", "--grid", "tau0=0.1,0.05", "--set", "t_end=2",
               "--methods", "vddvp,rk4", "--no-progress", "--workers", "1"]
QUICK_POINCARE = ["poincare", "henon_heiles", "--energy", "0.1", "--orbits", "4", "--t-end",
                  "40", "--no-plot"]
QUICK_COMPARE = ["compare", "harmonic", "--set", "t_end=2", "--methods", "vddvp,rk4",
                 "--halvings", "1", "--repeats", "1", "--no-progress"]
QUICK_PERIODIC = ["periodic", "harmonic", "--nodes", "40", "--no-plot"]
QUICK_FAMILY = ["periodic", "harmonic", "--family", "0.2:0.5:3", "--nodes", "40",
                "--no-plot"]
QUICK_BVP = ["bvp", "pendulum", "--no-plot"]
QUICK_STRESS = ["stress", "--quick", "--no-progress", "--workers", "1"]
OUTPUTS = {  # a command, and the files it writes in its folder
    "march": (QUICK_MARCH, ["result.npz", "meta.json", "trajectory.png"]),
    "bvp": (QUICK_BVP, ["result.npz", "meta.json"]),
    "periodic": (QUICK_PERIODIC, ["result.npz", "meta.json"]),
    "family": (QUICK_FAMILY, ["family.csv", "meta.json", "family.png"]),
    "poincare": (QUICK_POINCARE, ["section.npz", "section.csv", "orbits.csv", "meta.json"]),
    "sweep": (QUICK_SWEEP, ["sweep.csv", "sweep.md", "sweep.png", "meta.json",
                            "sweep.partial.csv"]),
    "compare": (QUICK_COMPARE, ["work_precision.csv", "summary.md", "meta.json",
                                "work_precision.partial.csv"]),
}


def _plant(names, target="victim"):
    def setup(folder):
        (folder / "victim").write_text(VICTIM)
        out = folder / "out"
        out.mkdir()
        for name in names:
            os.symlink(folder / target if target == "victim" else folder / "absent-target",
                       out / name)
    return setup


def link_cases() -> list[Case]:
    cases = []
    for command, (argv, files) in OUTPUTS.items():
        cases.append(Case("links", f"{command}: every output file a link to a victim",
                          [*argv, "--out", "out"], (0,), _plant(files)))
        cases.append(Case("links", f"{command}: every output file a link to a missing file",
                          [*argv, "--out", "out"], (0,), _plant(files, "absent")))
        cases.append(Case("links", f"{command}: .ddvp.lock a link", [*argv, "--out", "out"],
                          (1,), _plant([".ddvp.lock"]), expect_text="symbolic link"))

        def folder_link(folder):
            (folder / "victim").write_text(VICTIM)
            (folder / "elsewhere").mkdir()
            os.symlink(folder / "elsewhere", folder / "out")
        cases.append(Case("links", f"{command}: the output folder a link",
                          [*argv, "--out", "out"], (1,), folder_link,
                          check=_nothing_in("elsewhere"), expect_text="symbolic link"))
    return cases


def _nothing_in(name):
    def check(folder, result):
        inside = list((folder / name).iterdir())
        return [f"{name}/ (a link's target) got {inside}"] if inside else []
    return check


def signal_cases(rng: random.Random) -> list[Case]:
    cases = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        for _ in range(4):
            delay = rng.uniform(0.5, 9.0)
            count = rng.choice([1, 2, 3])
            plan = [(delay + 0.15 * i, sig) for i in range(count)]
            cases.append(Case("signals", f"march: {count} x {sig.name} at {delay:.2f} s",
                              [*LONG_MARCH, "--out", "out"], (0, 1), signals=plan,
                              check=_march_kept))
    for _ in range(4):
        delay = rng.uniform(1.0, 9.0)
        cases.append(Case("signals", f"march: SIGKILL at {delay:.2f} s",
                          [*LONG_MARCH, "--out", "out"], (0, 1),
                          signals=[(delay, signal.SIGKILL)], check=_readable_or_none("out")))
    for command, argv in (("bvp", ["bvp", "pendulum", "--nodes", "200001", "--no-plot"]),
                          ("poincare", ["poincare", "henon_heiles", "--energy", "0.1",
                                        "--orbits", "8", "--t-end", "2000", "--no-plot"]),
                          ("sweep", ["sweep", "harmonic", "--grid", "tau0=0.1,0.05,0.02",
                                     "--grid", "w=1,2,3", "--set", "t_end=200", "--methods",
                                     "vddvp,rk4,dop853", "--no-progress"]),
                          ("periodic", ["periodic", "pendulum", "--family", "0.1:1.5:12",
                                        "--nodes", "400", "--no-plot"]),
                          ("compare", ["compare", "harmonic", "--set", "t_end=400",
                                       "--no-progress"])):
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            delay = rng.uniform(0.5, 6.0)
            count = 3 if sig == signal.SIGINT else 1
            cases.append(Case("signals", f"{command}: {count} x {sig.name} at {delay:.2f} s",
                              [*argv, "--out", "out"], (0, 1),
                              signals=[(delay + 0.2 * i, sig) for i in range(count)],
                              check=_readable_or_none("out")))
    return cases


def _march_kept(folder, result):
    """After Ctrl-C/SIGTERM: the folder holds the run whole (interrupted, or finished), or,
    stopped before the march had a node to keep, nothing, as the message says."""
    from ddvp_nlp.errors import InputError
    from ddvp_nlp.io import read_run

    if "nothing new was written" in result.stderr or "before anything was written" in \
            result.stderr:  # stopped while starting or building: no node to keep
        return [] if not (folder / "out" / "meta.json").exists() else [
            "says nothing was written, but the folder holds a run"]
    try:
        arrays, meta = read_run(folder / "out")
    except InputError as exc:
        return [f"no readable run after the interrupt: {exc}"]
    if meta["status"] not in ("interrupted", "max_steps", "success"):
        return [f"status {meta['status']} after an interrupt"]
    return []


def _readable_or_none(name):
    def check(folder, result):
        from ddvp_nlp.errors import InputError
        from ddvp_nlp.io import read_set

        out = folder / name
        if not out.exists() or not (out / "meta.json").exists():
            data = [p.name for p in out.iterdir() if not p.name.startswith(".")] \
                if out.exists() else []
            stray = [n for n in data if not n.endswith(".partial.csv") and not n.startswith("E=")]
            return [f"files without a manifest: {stray}"] if stray and result.code == 0 else []
        try:
            read_set(out)
        except InputError as exc:
            return [f"not readable: {exc}"]
        return []
    return check


def disk_cases(disk_kind: str) -> list[Case]:
    """Full and read-only file systems, for every command that writes."""
    cases = []
    for command, (argv, _) in OUTPUTS.items():
        for state in ("full", "read-only"):
            cases.append(Case("disk", f"{command}: {state} file system ({disk_kind})",
                              [*argv, "--out", f"@DISK/{command}-{state}"], (1,),
                              expect_text="cannot write"))
        cases.append(Case("disk", f"{command}: a full disk keeps the earlier result",
                          [*argv, "--out", f"@DISK/{command}-again"], (1,),
                          expect_text="cannot write"))
    for command, (argv, _) in OUTPUTS.items():
        cases.append(Case("paths", f"{command}: --out an existing file",
                          [*argv, "--out", "file"], (1,),
                          lambda f: (f / "file").write_text("x"), expect_text="not a folder"))
        cases.append(Case("paths", f"{command}: --out /dev/null",
                          [*argv, "--out", "/dev/null"], (1,), expect_text="not a folder"))
        cases.append(Case("paths", f"{command}: a component longer than the system allows",
                          [*argv, "--out", "x" * 300], (1,), expect_text="File name too long"))
    cases.append(Case("paths", "scenes: stdout a full disk", ["scenes"], (0, 1)))
    return cases


def concurrent_cases() -> list[Case]:
    """Several writers of one folder at once: run as a group by :func:`run_concurrent`."""
    return [Case("concurrent", "3 marches into one folder", [*QUICK_MARCH, "--out", "out"],
                 (0, 1)),
            Case("concurrent", "2 sweeps (different grids) into one folder",
                 [*QUICK_SWEEP, "--out", "out"], (0, 1, 2)),
            Case("concurrent", "a long march and a short one into one folder",
                 [*LONG_MARCH, "--out", "out"], (0, 1))]


GRID_HEADER = None


def hostile_file_cases() -> list[Case]:
    def sweep_file(content: bytes):
        def setup(folder):
            out = folder / "out"
            out.mkdir()
            (out / "sweep.csv").write_bytes(content)
        return setup

    def forged(folder):
        # a finished sweep, then a row forged to claim success with other numbers
        subprocess.run([PYTHON, "-m", "ddvp_nlp.cli", *QUICK_SWEEP, "--out", "out"],
                       cwd=folder, capture_output=True, check=True)
        lines = (folder / "out" / "sweep.csv").read_text().splitlines()
        header = lines[0].split(",")
        cells = lines[1].split(",")
        cells[header.index("energy_error")] = "1e-30"
        lines[1] = ",".join(cells)
        (folder / "out" / "sweep.csv").write_text("\n".join(lines) + "\n")

    def directory_at(name):
        def setup(folder):
            (folder / "out" / name).mkdir(parents=True)
        return setup

    def deep(folder):
        (folder / "deep.toml").write_text("a = " + "[" * 10000 + "]" * 10000 + "\n")

    def evil(folder):
        (folder / "evil.py").write_text("open('pwned', 'w').write('x')\n")
        (folder / "grid.toml").write_text(f'scene = "{folder / "evil.py"}"\n[grid]\nw = [1.0]\n')

    def guess(content: bytes):
        def setup(folder):
            (folder / "guess.npz").write_bytes(content)
        return setup

    def complex_guess(folder):
        import numpy as np

        t = np.linspace(0, 1, 5)
        np.savez(folder / "guess.npz", t=t, q=np.zeros((5, 1)) + 1j, p=np.zeros((5, 1)))

    def torn(folder):
        subprocess.run([PYTHON, "-m", "ddvp_nlp.cli", *QUICK_BVP, "--out", "torn"],
                       cwd=folder, capture_output=True, check=True)
        with open(folder / "torn" / "result.npz", "r+b") as handle:
            handle.seek(100)
            handle.write(b"\xff" * 64)

    def pwned(folder, result):
        return ["the grid file's scene ran"] if (folder / "pwned").exists() else []

    return [
        Case("files", "sweep.csv of binary garbage", [*QUICK_SWEEP, "--out", "out"], (2,),
             sweep_file(os.urandom(3000)), expect_text="sweep.csv"),
        Case("files", "sweep.csv of Latin-1 text", [*QUICK_SWEEP, "--out", "out"], (2,),
             sweep_file("clé,état\nvaleur,été\n".encode("latin-1")), expect_text="UTF-8"),
        Case("files", "sweep.csv with a huge field", [*QUICK_SWEEP, "--out", "out"], (2,),
             sweep_file(b"key,x\n" + b"a" * 300000 + b",1\n"), expect_text="sweep.csv"),
        Case("files", "a folder where sweep.csv belongs", [*QUICK_SWEEP, "--out", "out"],
             (1, 2), directory_at("sweep.csv"), expect_text="sweep.csv"),
        Case("files", "a folder at the journal's name", [*QUICK_SWEEP, "--out", "out"],
             (1, 2), directory_at("sweep.partial.csv"), expect_text="sweep.partial.csv"),
        Case("files", "a forged success row is run again", [*QUICK_SWEEP, "--out", "out"],
             (0,), forged, check=_forged_row_rerun),
        Case("files", "--file /dev/zero", ["sweep", "--file", "/dev/zero"], (2,),
             expect_text="not a regular file"),
        Case("files", "TOML nested 10^4 deep", ["sweep", "--file", "deep.toml"], (2,), deep,
             expect_text="deep.toml"),
        Case("files", "grid file naming a scene file", ["sweep", "--file", "grid.toml"], (2,),
             evil, check=pwned, expect_text="--allow-scene"),
        Case("files", "bvp --guess not an npz", [*QUICK_BVP, "--guess", "guess.npz"], (2,),
             guess(b"not a zip at all"), expect_text="guess.npz"),
        Case("files", "periodic --guess not an npz", [*QUICK_PERIODIC, "--guess", "guess.npz"],
             (2,), guess(os.urandom(500)), expect_text="guess.npz"),
        Case("files", "bvp --guess with complex numbers", [*QUICK_BVP, "--guess", "guess.npz"],
             (2,), complex_guess, expect_text="real numbers"),
        Case("files", "bvp --guess from a torn run folder", [*QUICK_BVP, "--guess", "torn"],
             (2,), torn, expect_text="checksum"),
    ]


def _forged_row_rerun(folder, result):
    import csv

    with open(folder / "out" / "sweep.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    if any(r["energy_error"] == "1e-30" for r in rows):
        return ["the forged row was kept"]
    if "checksum" not in result.stderr:
        return ["no warning named the forged row"]
    return []


SCENES = {
    "GeneratorExit": "raise GeneratorExit('boom')\n",
    "custom BaseException": "class Boom(BaseException):\n    pass\nraise Boom('boom')\n",
    "sys.exit(7)": "import sys\nsys.exit(7)\n",
    "os._exit(5) in H": "import os\n{scene}\ndef H(q, p, t):\n    os._exit(5)\n",
    "sys.exit(7) in H": "import sys\ndef H(q, p, t):\n    sys.exit(7)\n",
    "a loop in H": "def H(q, p, t):\n    while True:\n        pass\n",
    "a loop while loading": "while True:\n    pass\n",
    "n = 10**6": "def H(q, p, t):\n    return p[0]**2\n",
    "params a list": "def H(q, p, t, w):\n    return p[0]**2\n",
    "exact that raises": "def H(q, p, t):\n    return p[0]**2/2 + q[0]**2/2\n"
                         "def exact(t, q0, p0, t0):\n    raise KeyError('no')\n",
    "invariant returns a string": "def H(q, p, t):\n    return p[0]**2/2 + q[0]**2/2\n",
    "KeyboardInterrupt-like GeneratorExit in H": "def H(q, p, t):\n    raise GeneratorExit\n",
}
SCENE_TAIL = {
    "n = 10**6": "scene = Scene(H, n=10**6, q0=[1.0]*10**6, p0=[0.0]*10**6, tau0=0.1, t_end=1)\n",
    "params a list": "scene = Scene(H, n=1, params=[1.0], q0=[1.0], p0=[0.0], tau0=0.1, "
                     "t_end=1)\n",
    "exact that raises": "scene = Scene(H, n=1, q0=[1.0], p0=[0.0], tau0=0.1, t_end=1, "
                         "exact=exact)\n",
    "invariant returns a string": "scene = Scene(H, n=1, q0=[1.0], p0=[0.0], tau0=0.1, "
                                  "t_end=1, invariants={'x': lambda q, p: 'abc'})\n",
}


def scene_cases() -> list[Case]:
    cases = []
    for name, body in SCENES.items():
        tail = SCENE_TAIL.get(name, "scene = Scene(H, n=1, q0=[1.0], p0=[0.0], tau0=0.1, "
                                    "t_end=1)\n")
        text = "from ddvp_nlp import Scene\n" + body.replace("{scene}\n", "") + tail

        def setup(folder, text=text):
            (folder / "scene.py").write_text(text)
        for command in ("march", "periodic", "compare"):
            argv = [command, "scene.py", "--out", "out"]
            if command == "periodic":
                argv += ["--energy", "0.5", "--nodes", "20"]
            if command == "compare":
                argv += ["--methods", "rk4", "--halvings", "0", "--repeats", "1",
                         "--no-progress"]
            cases.append(Case("scenes", f"{command}: {name}", argv, (2,), setup,
                              expect_text="scene"))
    return cases


NUMBERS = [
    ["march", "pendulum", "--set", "tau0=5e-324"],
    ["march", "kepler", "--set", "e=-0.3"],
    ["march", "kepler", "--set", "e=1"],
    ["bvp", "pendulum", "--alpha", "-0.1"],
    ["bvp", "pendulum", "--alpha", "nan"],
    ["march", "pendulum", "--time-limit", "nan"],
    ["bvp", "pendulum", "--time-limit", "inf"],
    ["march", "pendulum", "--scheme", "dop853", "--tol", "0"],
    ["compare", "pendulum", "--methods", ""],
    ["compare", "pendulum", "--methods", "rk4,rk4"],
    ["sweep", "harmonic", "--grid", "w=1,1"],
    ["sweep", "harmonic", "--grid", "w=1:1:3"],
    ["sweep", "harmonic", "--grid", "w=nan"],
    ["poincare", "henon_heiles", "--energy", "0.1", "--section", ""],
    ["poincare", "henon_heiles", "--energy", "0.1", "--seed", "-1"],
    ["poincare", "henon_heiles", "--energy", "0.1", "--orbits", "4000000000"],
    ["poincare", "henon_heiles", "--energy", "nan"],
    ["bvp", "pendulum", "--nodes", "100000000000"],
    ["periodic", "pendulum", "--family", "0.1:0.5:1000000000"],
    ["periodic", "pendulum", "--energy", "inf"],
    ["march", "pendulum", "--max-steps", "0"],
    ["march", "pendulum", "--tau-min", "0.1", "--tau-max", "0.01"],
    ["march", "pendulum", "--max-step-ratio", "1"],
    ["compare", "pendulum", "--horizons", "10,10"],
    ["compare", "pendulum", "--workers", "0"],
    ["stress", "--time-limit", "-1"],
    ["march", "pendulum", "--checkpoint-every", "nan"],
    ["bvp", "pendulum", "--guess", "nonexistent.npz"],
    ["periodic", "pendulum", "--nodes", "0"],
    ["march", "pendulum", "--set", "q0=1,2"],
    ["march", "pendulum", "--set", "t_end=1e400"],
    ["sweep", "--file", "missing.toml"],
    ["sweep", "--scheduler", "tcp://127.0.0.1:1", "harmonic", "--grid", "w=1,2"],
]


def number_cases() -> list[Case]:
    return [Case("numbers", " ".join(argv)[:70], [*argv, "--out", "out"] if argv[0] not in
                 ("sweep",) or "--file" not in argv else argv, (2,), expect_text="error")
            for argv in NUMBERS]


# -- issue 39: what the tool wrote, the compiled-code cache, events, bounds, cluster files ------

def _ddvp(folder: Path, *argv, env=None) -> subprocess.CompletedProcess:
    """A set-up run of the command, unjudged."""
    return subprocess.run([PYTHON, "-m", "ddvp_nlp.cli", *argv], cwd=folder,
                          capture_output=True, text=True, env={**os.environ, **(env or {})})


def _marker_code(folder: Path) -> str:
    return f"open({str(folder / 'pwned')!r}, 'w').write('ran')\n"


HARMONIC_FILE = ("from ddvp_nlp import Scene\ndef H(q, p, t):\n    return p[0]**2/2 + "
                 "{k}*q[0]**2/2\nscene = Scene(H, n=1, q0=[1.0], p0=[0.0], tau0=0.1, t_end=2)\n")
RESUME = ["march", "--resume", "run", "--no-plot", "--no-progress"]


def _a_run(scene="harmonic", edit=None, *, k="1"):
    """Set-up: a finished march in run/ (of a scene file h.py when ``scene`` is h.py), then
    ``edit(meta)`` of its meta.json."""
    def setup(folder):
        (folder / "h.py").write_text(HARMONIC_FILE.format(k=k))
        (folder / "evil.py").write_text(_marker_code(folder))
        _ddvp(folder, "march", scene, "--set", "t_end=2", "--no-plot", "--no-progress",
              "--out", "run")
        if edit is not None:
            import json

            meta = json.loads((folder / "run" / "meta.json").read_text())
            edit(meta, folder)
            (folder / "run" / "meta.json").write_text(json.dumps(meta))
    return setup


def _writer_running(folder):
    """Set-up: a long march writing run/ (a checkpoint landed); teardown ends it."""
    import json

    process = subprocess.Popen([PYTHON, "-m", "ddvp_nlp.cli", *LONG_MARCH, "--out", "run"],
                               cwd=folder, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)
    (folder / "writer.pid").write_text(str(process.pid))
    meta = folder / "run" / "meta.json"
    for _ in range(30000):  # polls for the first checkpoint
        with contextlib.suppress(OSError, ValueError):
            if json.loads(meta.read_text()).get("status") == "running":
                return
        if process.poll() is not None:
            return
        time.sleep(0.02)


def _end_writer(folder):
    with contextlib.suppress(OSError, ValueError, ProcessLookupError):
        pid = int((folder / "writer.pid").read_text())
        os.killpg(pid, signal.SIGTERM)
        for _ in range(3000):
            os.killpg(pid, 0)
            time.sleep(0.02)
    with contextlib.suppress(OSError, ValueError, ProcessLookupError):
        os.killpg(int((folder / "writer.pid").read_text()), signal.SIGKILL)
    time.sleep(0.2)


def _status_is(name, wanted):
    def check(folder, result):
        from ddvp_nlp.errors import InputError
        from ddvp_nlp.io import read_run

        try:
            _, meta = read_run(folder / name)
        except InputError as exc:
            return [f"{name} is not readable: {exc}"]
        return [] if meta["status"] == wanted else [f"{name} holds status {meta['status']}"]
    return check


def resume_cases() -> list[Case]:
    def scene_to(value):
        return lambda meta, folder: meta["resume"].update(
            scene=value.format(folder=folder))

    def option(name, value):
        return lambda meta, folder: meta["resume"]["options"].update({name: value})

    def overrides(meta, folder):
        meta["resume"]["overrides"]["w"] = 3.0

    def carried(meta, folder):
        meta["carried"] = {"drift": "nan", "careful_left": 0, "phase": 0}

    def meta_a_link(folder):  # "planted": damaged on purpose, the reader's check skips it
        _a_run()(folder)
        os.rename(folder / "run", folder / "planted")
        (folder / "planted-other").mkdir()  # its meta.json without the files it names
        os.rename(folder / "planted" / "meta.json", folder / "planted-other" / "meta.json")
        os.symlink(folder / "planted-other" / "meta.json", folder / "planted" / "meta.json")

    def scene_edited(folder):
        _a_run("h.py")(folder)
        (folder / "h.py").write_text(HARMONIC_FILE.format(k="2"))

    cases = [
        Case("resume", "the run names a planted scene file", RESUME, (2,),
             _a_run("h.py", scene_to("{folder}/evil.py")), expect_text="name it on the command"),
        Case("resume", "the run names a planted file, the user a built-in scene",
             ["march", "harmonic", *RESUME[1:]], (2,),
             _a_run("h.py", scene_to("{folder}/evil.py")), expect_text="SHA-256"),
        Case("resume", "the scene file was edited since the run", ["march", "h.py", *RESUME[1:]],
             (2,), scene_edited, expect_text="is not the file the run was computed from"),
        Case("resume", "the run names another built-in scene", RESUME, (2,),
             _a_run("harmonic", scene_to("pendulum")), expect_text="SHA-256"),
        Case("resume", "the record's settings were edited", RESUME, (2,),
             _a_run("harmonic", lambda m, f: overrides(m, f)),
             expect_text="is not what the run was computed from"),
        Case("resume", "the record names an option --out", RESUME, (2,),
             _a_run("harmonic", option("out", "/tmp/elsewhere")), expect_text="'out'"),
        Case("resume", "the record's tol a text", RESUME, (2,),
             _a_run("harmonic", option("tol", "__import__('os')")), expect_text="tol"),
        Case("resume", "the record's scheme a compared method", RESUME, (2,),
             _a_run("harmonic", option("scheme", "rk4")), expect_text="scheme"),
        Case("resume", "the carried drift not a number", RESUME, (2,),
             _a_run("harmonic", lambda m, f: carried(m, f)), expect_text="carried state"),
        Case("resume", "a second --resume of a folder being written", [*RESUME, "--t-end", "9"],
             (2,), _writer_running, expect_text="is busy", teardown=_end_writer),
        Case("resume", "meta.json a link to another folder's",
             ["march", "--resume", "planted", "--no-progress"], (2,), meta_a_link,
             expect_text="symbolic link"),
        Case("resume", "the folder is a file", RESUME, (2,),
             lambda f: (f / "run").write_text("x"), expect_text="no such folder"),
        Case("resume", "the same scene file, unchanged (continued)",
             ["march", "h.py", *RESUME[1:], "--t-end", "3"], (0,), _a_run("h.py"),
             check=_status_is("run", "success")),
    ]
    return cases


def grid_cases() -> list[Case]:
    def forged_and_signed(folder):
        import csv

        _ddvp(folder, *QUICK_SWEEP, "--out", "out")
        path = folder / "out" / "sweep.csv"
        with open(path, newline="") as handle:
            rows = list(csv.DictReader(handle))
        columns = list(rows[0])
        rows[0]["energy_error"] = "1e-30"
        # re-signed as anyone can: the checksum is the SHA-256 of the row's cells (its
        # docstring in runner/journal.py says it is not a signature)
        cells = json.dumps([rows[0][c] for c in columns if c != "row_sha256"])
        rows[0]["row_sha256"] = hashlib.sha256(cells.encode()).hexdigest()[:16]
        with open(path, "w", newline="") as handle:
            writer = csv.DictWriter(handle, columns, lineterminator="\n")
            writer.writeheader()
            writer.writerows(rows)

    def twice_in_journal(folder):
        _ddvp(folder, *QUICK_SWEEP, "--out", "out")
        lines = (folder / "out" / "sweep.csv").read_text().splitlines()
        (folder / "out" / "sweep.partial.csv").write_text(
            "\n".join([lines[0], lines[1], lines[2], lines[1]]) + "\n")

    def manifest_gone(folder):
        _ddvp(folder, *QUICK_SWEEP, "--out", "out")
        (folder / "out" / "meta.json").unlink()

    def not_forged(folder, result):
        text = (folder / "out" / "sweep.csv").read_text()
        problems = ["the forged row was reused"] if "1e-30" in text else []
        if "is not the file its manifest describes" not in result.stderr:
            problems.append("no warning named the file")
        return problems

    return [
        Case("grids", "sweep.csv re-signed after an edit", [*QUICK_SWEEP, "--out", "out"],
             (0,), forged_and_signed, check=not_forged),
        Case("grids", "a key twice in the journal", [*QUICK_SWEEP, "--out", "out"], (2,),
             twice_in_journal, expect_text="twice"),
        Case("grids", "sweep.csv without its manifest", [*QUICK_SWEEP, "--out", "out"], (0,),
             manifest_gone, expect_text="is not reused"),
    ]


def folder_cases() -> list[Case]:
    def first(*argv, edit=None):
        def setup(folder):
            (folder / "h.py").write_text(HARMONIC_FILE.format(k="1"))
            _ddvp(folder, *argv, "--no-plot", "--no-progress")
            if edit:
                edit(folder)
        return setup

    def two_folders(folder, result):
        runs = sorted(p.name for p in (folder / "runs").iterdir())
        return [] if len(runs) == 2 else [f"two runs share a folder: {runs}"]

    harmonic = ["march", "harmonic", "--no-plot", "--no-progress"]
    scene = ["march", "h.py", "--no-plot", "--no-progress"]
    return [
        Case("folders", "--event after a plain run", [*harmonic, "--event", "q1"], (0,),
             first("march", "harmonic"), check=two_folders),
        Case("folders", "--t-eval after a plain run", [*harmonic, "--t-eval", "0:1:3"], (0,),
             first("march", "harmonic"), check=two_folders),
        Case("folders", "another --event after an event run",
             [*harmonic, "--event", "q1;up"], (0,), first("march", "harmonic", "--event", "q1"),
             check=two_folders),
        Case("folders", "a scene file edited after its run", scene, (0,),
             first("march", "h.py", edit=lambda f: (f / "h.py").write_text(
                 HARMONIC_FILE.format(k="2"))), check=two_folders),
    ]


PLANTED_C = """#include <stdio.h>
__attribute__((constructor)) static void planted(void) {
    FILE *f = fopen("%s", "w"); if (f) { fputs("ran", f); fclose(f); }
}
"""
CACHE_ENV = {"DDVP_NLP_CACHE": "{folder}/cache"}
CACHED_MARCH = ["march", "harmonic", "--set", "t_end=2", "--no-plot", "--no-progress", "--out",
                "run"]


def cache_cases() -> list[Case]:
    def planted(folder) -> bytes:
        import shutil

        source = folder / "planted.c"
        source.write_text(PLANTED_C % (folder / "pwned"))
        subprocess.run([shutil.which("gcc") or "cc", "-shared", "-fPIC", str(source), "-o",
                        str(folder / "planted.so")], check=True)
        return (folder / "planted.so").read_bytes()

    def filled(folder):
        _ddvp(folder, *CACHED_MARCH, env={"DDVP_NLP_CACHE": str(folder / "cache")})
        return sorted((folder / "cache").glob("*.so"))

    def plant_with_sha256(folder):
        import hashlib

        data = planted(folder)
        for library in filled(folder):
            library.write_bytes(data)
            library.with_name(library.name + ".sha256").write_text(
                hashlib.sha256(data).hexdigest() + "\n")

    def plant_as_link(folder):
        import hashlib

        data = planted(folder)
        for library in filled(folder):
            library.unlink()
            os.symlink(folder / "planted.so", library)
            library.with_name(library.name + ".sha256").write_text(
                hashlib.sha256(data).hexdigest() + "\n")

    def garbage(folder):
        import hashlib

        for library in filled(folder):
            data = b"\x7fELF" + os.urandom(3000)
            library.write_bytes(data)
            library.with_name(library.name + ".sha256").write_text(
                hashlib.sha256(data).hexdigest() + "\n")

    def open_cache(mode=0o777, owner=None):
        def setup(folder):
            (folder / "cache").mkdir()
            (folder / "cache").chmod(mode)
            if owner is not None:
                os.chown(folder / "cache", owner, owner)
        return setup

    def cache_a_link(folder):
        (folder / "real").mkdir(mode=0o700)
        os.symlink(folder / "real", folder / "cache")

    def killed_builds(folder):
        filled(folder)
        old = time.time() - 3600
        for name in (".build-host-1-dead", "tmpkilled1"):
            (folder / "cache" / name).mkdir()
            (folder / "cache" / name / "chunk.c").write_text("int x;\n")
            os.utime(folder / "cache" / name, (old, old))

    def key_a_link(folder):
        filled(folder)
        key = folder / "cache" / ".ddvp-cache-key"
        os.rename(key, folder / "key")
        os.symlink(folder / "key", key)

    def compiled(folder, result):
        import json

        path = json.loads((folder / "run" / "meta.json").read_text()).get("path")
        return [] if path == "compiled" else [f"ran on the path {path!r}, not compiled"]

    def vm_with_warning(folder, result):
        import json

        path = json.loads((folder / "run" / "meta.json").read_text()).get("path")
        problems = [] if path == "vm" else [f"ran on the path {path!r}"]
        return problems + ([] if "not safe to load libraries" in result.stderr else
                           ["no warning said why the cache was refused"])

    def scratch_gone(folder, result):
        left = [p.name for p in (folder / "cache").iterdir() if p.is_dir()]
        return [f"scratch of killed builds left: {left}"] if left else []

    cases = [
        Case("cache", "a planted library with its SHA-256 beside it", CACHED_MARCH, (0,),
             plant_with_sha256, env=CACHE_ENV, check=compiled),
        Case("cache", "a library that is a link to a planted one", CACHED_MARCH, (0,),
             plant_as_link, env=CACHE_ENV, check=compiled),
        Case("cache", "a damaged library with a matching SHA-256", CACHED_MARCH, (0,), garbage,
             env=CACHE_ENV, check=compiled),
        Case("cache", "a cache folder others may write", CACHED_MARCH, (0,), open_cache(),
             env=CACHE_ENV, check=vm_with_warning),
        Case("cache", "a cache folder its group may write", CACHED_MARCH, (0,),
             open_cache(0o770), env=CACHE_ENV, check=vm_with_warning),
        Case("cache", "the cache folder a link", CACHED_MARCH, (0,), cache_a_link,
             env=CACHE_ENV, check=vm_with_warning),
        Case("cache", "scratch of killed builds", CACHED_MARCH, (0,), killed_builds,
             env=CACHE_ENV, check=scratch_gone),
        Case("cache", "the cache's key a link", CACHED_MARCH, (0,), key_a_link, env=CACHE_ENV,
             check=compiled),
    ]
    if os.geteuid() == 0:
        cases.append(Case("cache", "a cache folder of another user", CACHED_MARCH, (0,),
                          open_cache(0o700, owner=12345), env=CACHE_ENV,
                          check=vm_with_warning))
    return cases


EVENTS_REFUSED = ["sin()", "sin(q1, q1)", "arctan2(q1)", "maximum(q1, p1, q1)", "exp(x=q1)",
                  "sin(*[q1])", "-" * 400 + "q1", "__import__('os').system('touch pwned')",
                  "q1.__class__", "(lambda: q1)()", "[q for q in (q1,)]", "9**9**9**9 + q9",
                  "open('pwned', 'w')", "q1 if q1 else p1", "q1 @ p1", "sin(q1)(q1)"]


def event_cases(rng: random.Random) -> list[Case]:
    def nothing_written(folder, result):
        return ["a folder was made"] if (folder / "out").exists() else []

    cases = [Case("events", f"--event {text[:40]!r}",
                  ["march", "harmonic", "--no-plot", "--no-progress", "--out", "out", "--event",
                   text], (2,), check=nothing_written, expect_text="--event")
             for text in EVENTS_REFUSED]
    atoms = ["q1", "p1", "t", "pi", "w", "2", "x", "q1.real", "()"]
    names = ["sin", "cos", "arctan2", "hypot", "exp", "log", "abs", "maximum", "eval"]
    for _ in range(12):
        text = rng.choice(atoms)
        for _ in range(rng.randint(1, 5)):
            kind = rng.random()
            if kind < 0.4:
                args = ", ".join([text] * rng.randint(0, 3))
                text = f"{rng.choice(names)}({args})"
            elif kind < 0.8:
                text = f"({text} {rng.choice(['+', '-', '*', '/', '**', '%'])} "\
                       f"{rng.choice(atoms)})"
            else:
                text = f"{rng.choice(['-', '+', 'not '])}{text}"
        cases.append(Case("events", f"drawn: {text[:50]}",
                          ["march", "harmonic", "--set", "t_end=2", "--no-plot",
                           "--no-progress", "--out", "out", "--event", text], (0, 2)))
    return cases


SCENE_HEAD = ("from ddvp_nlp import Scene\ndef H(q, p, t):\n    return p[0]**2/2 + "
              "q[0]**2/2\n")
SCENE_END = "scene = Scene(H, n=1, q0=[1.0], p0=[0.0], tau0=0.1, t_end=1)\n"
BOUNDS = {  # what the scene does while it loads, the codes allowed, a text stderr must hold
    "ignores the timers and loops": ("import signal\nfor s in (signal.SIGALRM, signal.SIGPROF)"
                                     ":\n    signal.signal(s, signal.SIG_IGN)\nwhile True:\n"
                                     "    pass\n", (2,), "went on past its limit"),
    "cancels the timers and loops": ("import signal\nsignal.setitimer(signal.ITIMER_PROF, 0)\n"
                                     "signal.setitimer(signal.ITIMER_REAL, 0)\nwhile True:\n"
                                     "    pass\n", (2,), "limit"),
    "catches what the timers raise": ("while True:\n    try:\n        while True:\n"
                                      "            pass\n    except BaseException:\n"
                                      "        pass\n", (2,), "limit"),
    "sleeps, deaf to the timers": ("import signal, time\nsignal.signal(signal.SIGALRM, "
                                   "signal.SIG_IGN)\ntime.sleep(10**6)\n", (2,), "limit"),
    "waits on a lock": ("import threading\nthreading.Event().wait()\n", (2,), "asleep"),
    "calls posix._exit(0)": ("import posix\nposix._exit(0)\n", (2,), "os._exit(0)"),
    "kills itself": ("import os, signal\nos.kill(os.getpid(), signal.SIGKILL)\n", (2,),
                     "ended the process"),
    "calls the C library's _exit": ("import ctypes\nctypes.CDLL(None)._exit(0)\n", (2,),
                                    "ended the process"),
    "loops in one C call": ("import re\nre.match('(a*)*b', 'a' * 40)\n", (2,), "limit"),
    "changes the folder": ("import os\nos.chdir('/')\n", (0,), ""),
}
BOUNDED_RUN = ["--set", "t_end=1", "--no-plot", "--no-progress", "--out", "out"]


def bound_cases() -> list[Case]:
    cases = []
    for name, (body, codes, text) in BOUNDS.items():
        def setup(folder, body=body):
            (folder / "scene.py").write_text(SCENE_HEAD + body + SCENE_END)
        check = _status_is("out", "success") if codes == (0,) else None
        cases.append(Case("bounds", f"a scene that {name}", ["march", "scene.py", *BOUNDED_RUN],
                          codes, setup, check=check, expect_text=text))

    def scene(body):
        def setup(folder):
            (folder / "scene.py").write_text(SCENE_HEAD + body + SCENE_END)
        return setup

    thread = "import threading\nthreading.Thread(target=threading.Event().wait).start()\n"
    ending = ("import os, posix, threading, time\ndef end():\n    while not os.path.exists("
              "'out/meta.json'):\n        time.sleep(0.01)\n    posix._exit(0)\n"
              "threading.Thread(target=end, daemon=True).start()\n")
    hang = "import atexit, time\natexit.register(lambda: time.sleep(10**6))\n"
    deaf = "import signal\nsignal.signal(signal.SIGTERM, signal.SIG_IGN)\n" + thread
    long = ["--set", "t_end=1e7", "--max-steps", "3000000", "--checkpoint-every", "0.2",
            "--no-plot", "--no-progress", "--out", "out"]
    cases += [
        Case("bounds", "a thread left behind after saving", ["march", "scene.py", *BOUNDED_RUN],
             (0,), scene(thread), check=_status_is("out", "success")),
        Case("bounds", "an atexit hook that hangs", ["march", "scene.py", *BOUNDED_RUN], (0,),
             scene(hang), check=_status_is("out", "success")),
        Case("bounds", "a scene thread ends the process mid-run", ["march", "scene.py", *long],
             (1,), scene(ending), expect_text="before it was done"),
        Case("bounds", "SIGTERM, the scene deaf to it, a thread left",
             ["march", "scene.py", *long], (1,), scene(deaf),
             signals=[(4.0, signal.SIGTERM)], check=_march_kept),
    ]
    return cases


def cluster_cases() -> list[Case]:
    def fifo(folder):
        os.mkfifo(folder / "cluster.toml")

    def huge(folder):
        with open(folder / "cluster.toml", "wb") as handle:
            handle.truncate(3 << 30)  # sparse: 3 GB that take no disk

    def text(content):
        return lambda folder: (folder / "cluster.toml").write_text(content)

    stress = ["stress", "--quick", "--no-progress", "--out", "out", "--cluster"]
    no_sbatch = {"PATH": os.path.dirname(PYTHON)}
    return [
        Case("cluster", "--cluster /dev/zero", [*stress, "/dev/zero"], (2,),
             expect_text="not a regular file", timeout=60),
        Case("cluster", "--cluster a FIFO", [*stress, "cluster.toml"], (2,), fifo,
             expect_text="not a regular file", timeout=60),
        Case("cluster", "--cluster a 3 GB file", [*stress, "cluster.toml"], (2,), huge,
             expect_text="bytes", timeout=60),
        Case("cluster", "--cluster local:workers=100000", [*stress, "local:workers=100000"],
             (2,), expect_text="more than this machine can hold"),
        Case("cluster", "workers = 100000 in a file", [*stress, "cluster.toml"], (2,),
             text('[cluster]\nkind = "local"\nworkers = 100000\n'),
             expect_text="more than this machine can hold"),
        Case("cluster", "workers = 2.9 in a file", [*stress, "cluster.toml"], (2,),
             text('[cluster]\nkind = "local"\nworkers = 2.9\n'), expect_text="must be int"),
        Case("cluster", "a slurm cluster without sbatch", [*stress, "slurm:cores=2"], (2,),
             env=no_sbatch, expect_text="sbatch was not found", timeout=60),
        Case("cluster", "a queue that is a shell line", [*stress, "cluster.toml"], (2,),
             text('[cluster]\nkind = "slurm"\nqueue = "x\\n#!/bin/sh"\n'),
             expect_text="queue must be"),
        Case("cluster", "a table nested 10000 deep", [*stress, "cluster.toml"], (2,),
             text("[cluster]\nkind = " + "[" * 10000 + "]" * 10000 + "\n"), timeout=60),
        Case("cluster", "a setting twice", [*stress, "local:workers=1,workers=2"], (2,),
             expect_text="twice"),
    ]


def periodic_cases() -> list[Case]:
    def singular(folder):
        (folder / "singular.py").write_text(
            "from ddvp_nlp import Scene\ndef H(q, p, t):\n    return p[0]**2/2 - 1/q[0]**2\n"
            "scene = Scene(H, n=1, q0=[1.0], p0=[0.5], tau0=0.01, t_end=1)\n")
    return [Case("periodic", "H not finite along the whole start ray",
                 ["periodic", "singular.py", "--energy", "0.5", "--nodes", "20", "--section",
                  "q1=0", "--no-plot", "--out", "out"], (2,), singular,
                 expect_text="not finite anywhere")]


# `ddvp periodic --search` (issue 46): each bad input named by its flag before a flow runs
# (exit 2), an energy with no motion on the section said so (exit 2, no period), and a search
# that finds nothing exits 1 saying what was searched.
SEARCHES = [
    (["--section", "x=0"], (2,), "section must be NAME=VALUE"),
    (["--section", "q3=0"], (2,), "section names no coordinate"),
    (["--section", "p1=0"], (2,), "section must fix a position coordinate"),
    ([], (2,), "--section is needed with --search"),
    (["--section", "q1=0", "--seeds", "0"], (2,), "--seeds must be a positive integer"),
    (["--section", "q1=0", "--max-returns", "0"], (2,), "--max-returns must be"),
    (["--section", "q1=0", "--reversing", "q9"], (2,), "reversing must name coordinates"),
    (["--section", "q1=0", "--energy", "nan"], (2,), "--energy must be finite"),
    (["--section", "q1=0", "--energy", "-1"], (2,), "no motion at this energy on the section"),
    (["--section", "q1=0", "--jitter", "-1"], (2,), "--jitter must be an integer >= 0"),
    (["--section", "q1=0", "--jitter", "x"], (2,), "argument --jitter: invalid int value"),
    (["--section", "q1=0", "--jitter", "1.5"], (2,), "argument --jitter: invalid int value"),
    (["--section", "q1=0", "--workers", "0"], (2,), "--workers must be a positive integer"),
    (["--section", "q1=0", "--workers", "-2"], (2,), "--workers must be a positive integer"),
    (["--section", "q1=0", "--workers", "x"], (2,), "argument --workers: invalid int value"),
    (["--section", "q1=0", "--workers", "1000000000"], (2,), "is more than this machine can"),
    # the search's verdicts read --stability-tol (an index within it of +-2 is marginal)
    (["--section", "q1=0", "--stability-tol", "nan"], (2,), "--stability-tol must be finite"),
    (["--section", "q1=0", "--stability-tol", "-1"], (2,), "--stability-tol must be > 0"),
    (["--section", "q1=0", "--stability-tol", "x"], (2,), "argument --stability-tol: invalid"),
]
# --workers without --search (the seeds' processes): it would be ignored unsaid.
SEARCH_ONLY_WORKERS = [
    (["--workers", "2"], "--workers 2: read with --search only"),
    (["--workers", "2", "--follow", "0.6"], "--workers 2: read with --search only"),
]


def search_cases() -> list[Case]:
    def plane(folder):
        (folder / "harmonic.py").write_text(
            "import casadi as ca\nfrom ddvp_nlp import Scene\ndef H(q, p, t):\n"
            "    return ca.sumsqr(p)/2 + ca.sumsqr(q)/2\n"
            "scene = Scene(H, n=2, q0=[1.0, 0.0], p0=[0.0, 1.0], tau0=0.01, t_end=1)\n")
    return [Case("search", " ".join(option) or "no section",
                 ["periodic", "harmonic.py", "--search", "--energy", "0.5", *option, "--no-plot",
                  "--out", "out"], codes, plane, expect_text=text)
            for option, codes, text in SEARCHES] + [
        Case("search", " ".join(option) + " (no --search)",
             ["periodic", "harmonic.py", "--energy", "0.5", *option, "--no-plot", "--out",
              "out"], (2,), plane, expect_text=text) for option, text in SEARCH_ONLY_WORKERS]


# Options of `ddvp periodic` that only --stability or --follow used: each had been taken
# unchecked without them (--stability-tol nan ran the orbit and exited 0, issue 45); now the
# option object (Continuation) checks them, whichever path runs, and names the flag.
RANGES = [
    (["--stability-tol", "nan"], "--stability-tol must be finite, got nan"),
    (["--stability-tol", "inf"], "--stability-tol must be finite, got inf"),
    (["--stability-tol", "-1"], "--stability-tol must be > 0, got -1.0"),
    (["--stability-tol", "nan", "--stability"], "--stability-tol must be finite, got nan"),
    (["--step", "nan"], "--step must be finite, got nan"),
    (["--step", "0"], "--step must be > 0, got 0.0"),
    (["--max-orbits", "1"], "--max-orbits must be an integer >= 2, got 1"),
    # the search's own flags without --search had been ignored unsaid
    (["--seeds", "5"], "--seeds 5: read with --search only"),
    (["--jitter", "1"], "--jitter 1: read with --search only"),
    (["--reversing", "none", "--follow", "0.6"], "--reversing none: read with --search only"),
]


def range_cases() -> list[Case]:
    """Every positive option of ``ddvp periodic`` refused by its flag when it is not finite
    or not positive, before any orbit is solved (exit 2, nothing written)."""
    return [Case("ranges", " ".join(option), ["periodic", "harmonic", "--nodes", "40",
                                               "--no-plot", *option, "--out", "out"], (2,),
                 expect_text=text) for option, text in RANGES]


# `ddvp periodic --follow ... --switch` (issue 46): a bad count or a --switch without --follow
# refused by its flag before any orbit is solved; a followed family with no branch point says
# there is nothing to switch onto (exit 2, after the family is written).
SWITCHES = [
    (["--energy", "0.5", "--switch", "3"], "--switch needs --follow"),
    (["--energy", "0.5", "--follow", "0.6", "--switch", "1"],
     "--switch must be an integer >= 2, got 1"),
    (["--energy", "0.5", "--follow", "0.6", "--switch", "-4"],
     "--switch must be an integer >= 2, got -4"),
    (["--energy", "0.5", "--follow", "0.6", "--switch", "x"],
     "argument --switch: invalid int value"),
    (["--energy", "0.5", "--follow", "0.6", "--switch", "2.5"],
     "argument --switch: invalid int value"),
    (["--energy", "0.5", "--family", "0.5:0.6:3", "--switch"], "--switch needs --follow"),
    (["--energy", "0.5", "--follow", "0.6", "--switch-tol", "1e-4"],
     "--switch-tol 1e-4 needs --switch"),
    (["--energy", "0.5", "--follow", "0.6", "--switch", "--switch-tol", "0"],
     "--switch-tol must be a positive number or 'none', got '0'"),
    (["--energy", "0.5", "--follow", "0.6", "--switch", "--switch-tol", "nan"],
     "--switch-tol must be a positive number or 'none', got 'nan'"),
]


def switch_cases() -> list[Case]:
    """Branch switching's refusals (``SWITCHES``, on the harmonic scene), a family with no
    branch point (Henon-Heiles from E = 0.02 to 0.04), Henon-Heiles' axis family switched at
    its period doubling (one branch) and stopped before it (exit 2)."""
    cases = [Case("switch", " ".join(option), ["periodic", "harmonic", "--nodes", "40",
                                                "--no-plot", *option, "--out", "out"], (2,),
                  expect_text=text) for option, text in SWITCHES]
    cases.append(Case("switch", "no branch point on the family",
                      ["periodic", "henon_heiles", "--energy", "0.02", "--follow", "0.04",
                       "--step", "0.01", "--nodes", "41", "--switch", "--no-plot", "--out",
                       "out"], (2,), expect_text="no branch point was located on the family"))
    doubling = ["periodic", "henon_heiles", "--energy", "0.13", "--follow", "0.14", "--step",
                "0.005", "--nodes", "61", "--no-plot", "--out", "out"]
    cases.append(Case("switch", "a period doubling: one branch of twice the period",
                      [*doubling, "--switch", "2"], (0,), check=_one_doubled_branch))
    cases.append(Case("switch", "the family stops before its period doubling",
                      [*doubling, "--max-orbits", "2", "--switch", "2"], (2,),
                      expect_text="no branch point was located on the family, nor a period "
                                  "doubling"))
    return cases


def _one_doubled_branch(folder, result) -> list[str]:
    """At Henon-Heiles' period doubling: the two signs said to be one orbit, one branch written
    (``branch-1/``, none beside it), its orbits of twice the nodes."""
    problems = []
    if "the two signs give one orbit shifted by half its period" not in result.stdout:
        problems.append("the two signs of the doubling direction were not found to be one orbit")
    branch = folder / "out" / "branch-1" / "family.csv"
    if not branch.exists():
        problems.append("no branch-1/family.csv written")
    if (folder / "out" / "branch-2").exists():
        problems.append("a second branch written for one orbit shifted by half its period")
    if "2 orbits of twice the period" not in result.stdout:
        problems.append("the branch did not reach its 2 orbits")
    return problems


def backward_cases() -> list[Case]:
    """Every method told to run backwards (t_end < t0): it marches to t_end with steps, or
    fails by name; a success with no step taken, t left at t0, is a lie (issue 45)."""
    import json

    def reached(folder, result):
        meta = folder / "out" / "meta.json"
        if not meta.exists():
            return ["no meta.json"]
        data = json.loads(meta.read_text())
        steps = data.get("steps") or 0
        if data.get("status") == "success" and steps < 1:
            return [f"success with {steps} steps"]
        return []
    methods = ["vddvp", "lee", "midpoint", "stormer_verlet", "leapfrog", "verlet_adaptive",
               "avf", "rk4", "dop853"]
    return [Case("backward", f"harmonic, {name}, t_end = -3",
                 ["march", "harmonic", "--scheme" if name in ("vddvp", "lee") else "--method",
                  name, "--set", "t_end=-3", "--no-plot", "--no-progress", "--out", "out"],
                 (0,), check=reached) for name in methods] + [
        Case("backward", "harmonic, lee_left, t_end = -3 (stops within a swing: status 1)",
             ["march", "harmonic", "--method", "lee_left", "--set", "t_end=-3", "--no-plot",
              "--no-progress", "--out", "out"], (1,), check=reached)]


CONSTRAINED_SCENE = """import casadi as ca
from ddvp_nlp import Scene


def H(q, p, t):
    return (p[0] ** 2 + p[1] ** 2) / 2 + q[1]


def g(q, t):
    {body}


scene = Scene(H, n=2, q0={q0}, p0={p0}, tau0=0.01, t_end=0.5, constraints=g)
"""

CONSTRAINTS = [  # (name, g's body, q0, p0, exit code, text on stderr)
    ("a broken constraint (raises)", "return q[7]", "[0.0, -1.0]", "[1.0, 0.0]", (2,),
     "constraints"),
    ("a wrong shape (a 2x2 matrix)", "return ca.SX.eye(2) * q[0]", "[0.0, -1.0]",
     "[1.0, 0.0]", (2,), "vector"),
    ("no q in it", "return ca.sin(t)", "[0.0, -1.0]", "[1.0, 0.0]", (2,), "depend on q"),
    ("as many rows as coordinates", "return ca.vertcat(q[0], q[1])", "[0.0, -1.0]",
     "[1.0, 0.0]", (2,), "n - 1"),
    ("redundant rows", "return ca.vertcat(q[0]**2 + q[1]**2 - 1, 2*(q[0]**2 + q[1]**2 - 1))",
     "[0.0, -1.0]", "[1.0, 0.0]", (2,), "n - 1"),
    ("singular Jacobian at the start", "return q[0]**2 + q[1]**2", "[0.0, 0.0]",
     "[1.0, 0.0]", (2,), "singular"),
    ("a start that cannot be made consistent", "return q[0]**2 + q[1]**2 + 1",
     "[0.3, 0.2]", "[1.0, 0.0]", (2,), "consistent"),
    ("non-finite at the start", "return ca.log(q[0]) + q[1]", "[-1.0, 0.0]", "[1.0, 0.0]",
     (2,), "finite"),
    ("an inconsistent start, projected (warned, marched)", "return q[0]**2 + q[1]**2 - 1",
     "[0.1, -1.05]", "[1.0, 0.3]", (0,), "projected"),
]


def constraint_cases() -> list[Case]:
    """A scene file whose constraint is broken, of the wrong shape, singular, redundant or
    unreachable from its start: exit 2 naming it before anything is built; an inconsistent but
    reachable start is projected, said, and marched; the solvers that do not know constraints
    refuse them (issue 48)."""
    cases = []
    for name, body, q0, p0, codes, text in CONSTRAINTS:
        scene = CONSTRAINED_SCENE.format(body=body, q0=q0, p0=p0)

        def setup(folder, scene=scene):
            (folder / "scene.py").write_text(scene)
        cases.append(Case("constraints", f"march: {name}", ["march", "scene.py", "--no-plot",
                                                           "--no-progress", "--out", "out"],
                          codes, setup, expect_text=text))
    small = ["--halvings", "0", "--repeats", "1", "--no-progress", "--out", "out"]
    for method in ("rk4", "dop853"):  # compare runs the methods that know constraints only
        cases.append(Case("constraints", f"compare: {method} on the Cartesian pendulum is "
                          "refused by name", ["compare", "cartesian_pendulum", "--methods",
                                              method, *small], (2,),
                          expect_text="does not know holonomic constraints"))
    cases.append(Case("constraints", "compare: target errors on the Cartesian pendulum",
                      ["compare", "cartesian_pendulum", "--target-errors", "1e-3", *small],
                      (2,), expect_text="target_errors"))
    return cases


CONSTRAINED_ENDS = ["--set", "q_start=0,-1", "--set", "t0=0", "--set", "t_end=1",
                    "--no-plot", "--no-progress", "--out", "out"]


def constrained_bvp_cases() -> list[Case]:
    """``ddvp bvp`` on the Cartesian pendulum (fixed ends of a constrained system): a quarter
    turn solved by Newton and by IPOPT, fixed and energy steps (exit 0, the constraint
    residuals said); an end off the rod, too few nodes, shooting, a transfer at an energy and a
    banded linear solve refused by name, exit 2 (issue 48)."""
    quarter = ["bvp", "cartesian_pendulum", "--set", "q_end=1,0", *CONSTRAINED_ENDS]
    cases = [Case("constrained_bvp", f"a quarter turn, {scheme} steps, {solver}",
                  [*quarter, "--scheme", scheme, "--solver", solver, "--nodes", "41"], (0,),
                  expect_text="")
             for scheme, solver in (("fixed", "newton"), ("fixed", "ipopt"),
                                    ("vddvp", "auto"))]
    for name, extra, text in (
            ("q_end off the rod", ["--set", "q_end=1,1", "--nodes", "11"], "q_end"),
            ("two nodes", ["--set", "q_end=1,0", "--nodes", "2"], "nodes"),
            ("shooting", ["--set", "q_end=1,0", "--nodes", "11", "--guess", "march"],
             "shooting"),
            ("a transfer at an energy", ["--set", "q_end=1,0", "--nodes", "11", "--energy",
                                         "0.5"], "AtEnergy")):
        cases.append(Case("constrained_bvp", f"refused: {name}",
                          ["bvp", "cartesian_pendulum", *extra, *CONSTRAINED_ENDS], (2,),
                          expect_text=text))
    return cases


CONSTRAINED_RUN = ["--no-plot", "--no-progress"]


def _constrained_run(edit=None):
    """Set-up: a vddvp march of the Cartesian pendulum to t = 2 in run/, then ``edit(meta)``
    of its meta.json."""
    def setup(folder):
        _ddvp(folder, "march", "cartesian_pendulum", "--t-end", "2", *CONSTRAINED_RUN, "--out",
              "run")
        if edit is not None:
            import json

            meta = json.loads((folder / "run" / "meta.json").read_text())
            edit(meta)
            (folder / "run" / "meta.json").write_text(json.dumps(meta))
    return setup


def _reached(name, low, high):
    """A check: the run in ``name`` succeeded and its last node lies in ``[low, high]``."""
    def check(folder, result):
        import numpy as np

        meta = _meta_of(folder, name)
        if meta is None:
            return [f"{name} has no meta.json"]
        with np.load(folder / name / "result.npz") as arrays:  # read_run takes forward runs
            t = float(arrays["t"][-1])
        problems = [] if meta["status"] == "success" else [f"status {meta['status']}"]
        return problems + ([] if low <= t <= high else [f"last node at t = {t}"])
    return check


def constrained_march_cases() -> list[Case]:
    """``ddvp march`` of a constrained scene backwards in time and continued with --resume
    (issue 48): a backward march with energy and fixed steps (exit 0, its last node at the
    asked-for end or one step past it), a run continued to a later end (exit 0), and a run
    folder whose carried multipliers were damaged or do not fit the scene, refused by name
    (exit 2)."""
    def multipliers(value):
        return lambda meta: meta["carried"].update(multipliers=value)

    march_to = ["march", "cartesian_pendulum", *CONSTRAINED_RUN, "--out", "out"]
    return [
        Case("constrained_march", "backward, vddvp steps", [*march_to, "--t-end", "-5"], (0,),
             check=_reached("out", -5.03, -5.0)),
        Case("constrained_march", "backward, fixed steps",
             [*march_to, "--t-end", "-3", "--scheme", "fixed"], (0,),
             check=_reached("out", -3.0, -3.0)),
        Case("constrained_march", "a backward run to t_end = t0",
             [*march_to, "--t-end", "0"], (2,), expect_text="t_end"),
        Case("constrained_march", "resumed to a later end", [*RESUME, "--t-end", "5"], (0,),
             _constrained_run(), check=_reached("run", 5.0, 5.03)),
        Case("constrained_march", "resumed: the carried multipliers a text", RESUME, (2,),
             _constrained_run(multipliers("nan")), expect_text="multipliers"),
        Case("constrained_march", "resumed: three carried multipliers for one rod", RESUME,
             (2,), _constrained_run(multipliers([1.0, 2.0, 3.0])), expect_text="multipliers"),
        Case("constrained_march", "resumed to an earlier end", [*RESUME, "--t-end", "1"], (2,),
             _constrained_run(), expect_text="t_end"),
    ]

CONSTRAINED_PERIODIC = ["--no-plot", "--no-progress", "--out", "out"]


def constrained_periodic_cases() -> list[Case]:
    """``ddvp periodic`` on constrained scenes (``solvers/periodic/constrained_orbit.py``): the
    spherical pendulum's conical orbit (its multipliers, a family of them) and the Cartesian
    pendulum's libration found (exit 0); an energy with no motion at the start, a section the
    orbit does not cross, a bad section, too few nodes and a followed family refused by name,
    exit 2 (issue 48)."""
    cases = [Case("constrained_periodic", "the conical orbit of the spherical pendulum",
                  ["periodic", "spherical_pendulum", "--nodes", "41", *CONSTRAINED_PERIODIC],
                  (0,)),
             Case("constrained_periodic", "the libration of the Cartesian pendulum",
                  ["periodic", "cartesian_pendulum", "--energy", "-0.5", "--nodes", "81",
                   *CONSTRAINED_PERIODIC], (0,)),
             Case("constrained_periodic", "the conical orbit's multipliers (exact flow)",
                  ["periodic", "spherical_pendulum", "--nodes", "41", "--stability",
                   *CONSTRAINED_PERIODIC], (0,)),
             Case("constrained_periodic", "a family of cones (each orbit the next's guess)",
                  ["periodic", "spherical_pendulum", "--nodes", "41",
                   "--family=-0.64:-0.6:3", *CONSTRAINED_PERIODIC], (0,))]
    for scene, name, extra, text in (
            ("cartesian_pendulum", "an energy below the start's potential",
             ["--energy", "-1.5"], "no motion"),
            ("cartesian_pendulum", "a section the libration never crosses",
             ["--section", "q2=0.5"], "does not cross the section"),
            ("spherical_pendulum", "an energy below the pendulum at rest (no cone)",
             ["--energy", "-2"], "least energy is -1"),
            ("spherical_pendulum", "a section on no coordinate", ["--section", "q4=0"],
             "section"),
            ("spherical_pendulum", "too few nodes", ["--nodes", "3"], "nodes"),
            ("spherical_pendulum", "a followed family (its predictor is unconstrained)",
             ["--energy", "-0.63", "--follow=-0.6"], "follow_periodic_family")):
        cases.append(Case("constrained_periodic", f"refused: {name}",
                          ["periodic", scene, *extra, *CONSTRAINED_PERIODIC], (2,),
                          expect_text=text))
    return cases


def merge_cases() -> list[Case]:
    """``ddvp chaos --merge`` on parts that are not one job's whole parts (written through the
    tool's own manifest, so only the merge's checks can catch them): refused by name, exit 2."""
    import numpy as np

    from ddvp_nlp.io import output_folder
    from ddvp_nlp.io.chaos_files import arrays_writer  # internal: the writer of a part
    from ddvp_nlp.studies.chaos_map import KEYS  # internal: the arrays a part holds

    def parts(damage):
        def setup(folder):
            for k in (1, 2):
                status = np.array(["success" if i % 2 == k - 1 else "other_shard"
                                   for i in range(6)])
                if damage == "twice" and k == 2:
                    status = np.array(["success" if i % 2 == 0 else "other_shard"
                                       for i in range(6)])
                arrays = {"status": status, **{key: np.ones(6) for key in KEYS}}
                if damage == "nan" and k == 2:
                    arrays["megno"][1] = np.nan
                (folder / "parts").mkdir(exist_ok=True)
                with output_folder(folder / "parts" / f"shard-{k}-of-2") as out:
                    out.commit({"part.npz": arrays_writer(arrays)}, {"settings": {"scene": "s"}})
            if damage == "stray":
                (folder / "parts" / "shard-1-of-2.bak").mkdir()
        return setup
    argv = ["chaos", "--merge", "parts", "--no-plot"]
    return [Case("merges", "a stray shard-1-of-2.bak folder", argv, (2,), parts("stray"),
                 expect_text="is not a shard folder"),
            Case("merges", "two parts holding the same cells", argv, (2,), parts("twice"),
                 expect_text="both hold"),
            Case("merges", "a success cell with megno NaN", argv, (2,), parts("nan"),
                 expect_text="a success with megno = nan")]


def _meta_of(folder, name="out"):
    import json

    meta = folder / name / "meta.json"
    return json.loads(meta.read_text()) if meta.exists() else None


def target_cases() -> list[Case]:
    """``--target-error``: its failures are statuses, never a verdict for steps not taken,
    never the bad-input code for a breakdown, and a run resumes at the step it chose
    (issue 45)."""
    def no_verdict_without_steps(folder, result):
        meta = _meta_of(folder)
        if meta is None:
            return []
        verdict = (meta.get("accuracy") or {}).get("verdict")
        if (meta.get("steps") or 0) < 1 and verdict is not None:
            return [f"verdict {verdict!r} with {meta.get('steps')} steps"]
        return []

    def pilot_said(folder, result):
        meta = _meta_of(folder)
        said = meta is not None and "pilot march" in str(meta.get("message"))
        return no_verdict_without_steps(folder, result) + ([] if said else
                                                          ["the message does not say the pilot"])

    def resumed(folder, result):
        meta = _meta_of(folder)
        if meta is None or "resumed_from" not in meta:
            return ["not resumed"]
        return [] if meta.get("accuracy", {}).get("global_tol") == 1e-3 else \
            ["resumed without the target's tolerance"]
    base = ["march", "kepler", "--no-plot", "--no-progress", "--out", "out"]
    first = ["march", "pendulum", "--set", "t_end=20", "--target-error", "1e-3", "--no-plot",
             "--no-progress", "--out", "out"]
    return [
        Case("target", "a pilot that breaks down (kepler e = 0.9, tau0 = 0.5): a status",
             [*base, "--set", "e=0.9", "--set", "tau0=0.5", "--set", "t_end=50",
              "--target-error", "1e-3"], (1,), check=pilot_said),
        Case("target", "a target of 1e-300: refused up front", [*base, "--target-error",
                                                                "1e-300"], (2,),
             expect_text="below what the check can measure", timeout=30.0),
        Case("target", "SIGINT during the tries: interrupted, no verdict for steps not taken",
             ["march", "pendulum", "--set", "t_end=1e6", "--target-error", "1e-6",
              "--no-plot", "--no-progress", "--out", "out"], (1,),
             signals=[(3.0, signal.SIGINT)], check=no_verdict_without_steps),
        Case("target", "--resume of a finished target-error run: at the chosen step",
             ["march", "--resume", "out", "--t-end", "30", "--no-plot", "--no-progress"], (0,),
             setup=lambda folder: _ddvp(folder, *first), check=resumed),
    ]


def small_motion_cases() -> list[Case]:
    """Motions far below the units (the acceptance's scales from the problem, with the round-off
    bound of H; Newton's rows scaled below a node of 1e-2): marched where the scheme can be
    solved, refused by cause where it cannot (a floor of 1 used to return the RK4 guess of a
    motion of 1e-9 as a vddvp success)."""
    def said(*words):
        def check(folder, result):
            meta = _meta_of(folder)
            if meta is None:
                return ["no meta.json"]
            message = str(meta.get("message"))
            problems = [f"the message does not say {w!r}" for w in words if w not in message]
            if meta.get("status") == "success":
                problems.append("called a success")
            return problems
        return check

    def solved(folder, result):
        """The returned nodes solve the scheme to the acceptance tolerance of the motion's own
        size: the RK4 guesses a floor of 1 had passed off as the scheme left their equations
        at 5e-6 of the motion (canonical residual 7.4e-15 at a motion of 1.4e-9)."""
        meta = _meta_of(folder)
        if meta is None or meta.get("status") != "success":
            return []
        residual = meta.get("canonical_residual_max")
        size = max((meta.get("accuracy") or {}).get("scale") or [0.0])
        if residual is None or not residual <= 1e-10 * size:
            return [f"canonical residual {residual} against a motion of size {size:.3g}"]
        return []

    def judged_or_said(*words):
        """A success judged whole by the accuracy check (the steps the energy equation sets
        within H's round-off still solve the scheme), or a failure that names its cause."""
        def check(folder, result):
            meta = _meta_of(folder)
            if meta is None:
                return ["no meta.json"]
            if meta.get("status") != "success":
                return said(*words)(folder, result)
            verdict = (meta.get("accuracy") or {}).get("verdict")
            if verdict not in ("accurate", "drifted"):
                return [f"a success judged {verdict!r}"]
            return solved(folder, result)
        return check

    def varied(folder, result):
        meta = _meta_of(folder)
        return solved(folder, result) if meta is not None and meta.get("status") == "success" \
            else [f"status {None if meta is None else meta.get('status')!r}"]
    march = ["march", "pendulum", "--set", "t_end=5", "--no-plot", "--no-progress", "--out",
             "out"]
    return [
        Case("small", "the pendulum at amplitude 1e-4 (1 - cos q from terms of size 1)",
             [*march, "--set", "q0=5e-5", "--set", "p0=5e-5"], (0,), check=varied),
        Case("small", "the pendulum at amplitude 1e-6: the energy equation at H's round-off",
             [*march, "--set", "q0=5e-7", "--set", "p0=5e-7"], (0, 1),
             check=judged_or_said("round-off sets the step length", "fixed")),
        Case("small", "the pendulum at amplitude 1e-9, fixed steps (Newton's rows scaled)",
             [*march, "--set", "q0=5e-10", "--set", "p0=5e-10", "--scheme", "fixed"], (0,),
             check=varied),
        Case("small", "the pendulum at amplitude 1e-9, energy steps",
             [*march, "--set", "q0=5e-10", "--set", "p0=5e-10"], (0, 1),
             check=judged_or_said("round-off sets the step length")),
    ]


def thinned_cases() -> list[Case]:
    """``--keep-every``: refused where it cannot keep its promise (checkpoints, resume, a
    keep_every past 2**62), by name (issue 45)."""
    march = ["march", "harmonic", "--set", "t_end=5", "--no-plot", "--no-progress", "--out",
             "out"]
    return [
        Case("thinned", "--keep-every 10 --checkpoint-every 1", [*march, "--keep-every", "10",
                                                                "--checkpoint-every", "1"],
             (2,), expect_text="does not apply to a thinned march"),
        Case("thinned", "--keep-every 99999999999999999999999",
             [*march, "--keep-every", "99999999999999999999999"], (2,),
             expect_text="--keep-every"),
        Case("thinned", "--keep-every 10 then --resume", ["march", "--resume", "out",
                                                           "--keep-every", "10", "--no-plot",
                                                           "--no-progress"], (2,),
             setup=lambda folder: _ddvp(folder, *march), expect_text="--keep-every"),
        Case("thinned", "--keep-every 7 (a thinned run, whole)", [*march, "--keep-every", "7"],
             (0,)),
    ]


def compare_cases() -> list[Case]:
    """``ddvp compare --horizons`` (issue 49): bad horizons refused by name before a folder is
    made (exit 2, no traceback); unsorted horizons run shortest first, with the crossover
    figure and its words."""
    base = ["compare", "harmonic", "--methods", "rk4,avf", "--halvings", "1", "--repeats", "1",
            "--no-progress", "--out", "out"]

    def no_folder(folder, result):
        return ["a folder was made for refused input"] if (folder / "out").exists() else []

    def shortest_first(folder, result):
        summary = folder / "out" / "horizons.md"
        if not summary.exists() or not (folder / "out" / "crossover.png").exists():
            return ["horizons.md or crossover.png missing"]
        text = summary.read_text()
        problems = [] if text.index("## T = 10") < text.index("## T = 100") else \
            ["the horizons were not run shortest first"]
        return problems + ([] if "## Crossovers" in text else ["no crossovers in words"])
    bad = [("a negative horizon", "--horizons=-1,10", "--horizons must be > 0"),
           ("NaN", "--horizons=nan", "--horizons must be finite"),
           ("infinity", "--horizons=10,inf", "--horizons must be finite"),
           ("empty", "--horizons=", "--horizons must be comma-separated numbers"),
           ("an empty item", "--horizons=10,,100", "--horizons must be comma-separated"),
           ("unsorted duplicates", "--horizons=100,10,100", "has the value 100.0 twice"),
           ("a horizon shorter than a step", "--horizons=0.01,10",
            "horizon 0.01 (t_end - t0 = 0.01) is shorter than the scene's first step"),
           ("a time unit of zero", "--time-unit=0", "--time-unit must be > 0")]
    cases = [Case("compare", f"--horizons: {name}", [*base, flag] if "horizons" in flag
                  else [*base, "--horizons=10,100", flag], (2,), expect_text=text,
                  check=no_folder, timeout=60.0)
             for name, flag, text in bad]
    cases.append(Case("compare", "--horizons 100,10 (unsorted): run shortest first",
                      [*base, "--horizons=100,10"], (0,), check=shortest_first))
    return cases


SPAWNING_SCENE = ("import subprocess\nfrom ddvp_nlp import Scene\n"
                  "child = subprocess.Popen(['sleep', '300'])\n"
                  "open('pid', 'w').write(str(child.pid))\n"
                  "def H(q, p, t):\n    return p[0]**2/2 + q[0]**2/2\n"
                  "scene = Scene(H, n=1, q0=[1.0], p0=[0.0], tau0=0.1, t_end=1)\n")


def supervision_cases() -> list[Case]:
    """What a scene starts ends with the command; a scene that ignores SIGTERM at import
    still lets the march stop on SIGTERM and save (issue 45)."""
    def write(text, name="scene.py"):
        return lambda folder: (folder / name).write_text(text)

    def gone(folder, result):
        pid_file = folder / "pid"
        if not pid_file.exists():
            return ["the scene did not start its process"]
        try:
            os.kill(int(pid_file.read_text()), 0)
        except ProcessLookupError:
            return []
        return ["the scene's process outlived the command"]
    deaf = ("import signal\nfrom ddvp_nlp import Scene\n"
            "signal.signal(signal.SIGTERM, signal.SIG_IGN)\n"
            "def H(q, p, t):\n    return p[0]**2/2 - __import__('casadi').cos(q[0])\n"
            "scene = Scene(H, n=1, q0=[0.5], p0=[0.0], tau0=0.001, t_end=1e7)\n")
    return [
        Case("supervision", "a scene's subprocess", ["march", "scene.py", "--no-plot",
                                                     "--no-progress", "--out", "out"], (0,),
             setup=write(SPAWNING_SCENE), check=gone, expect_text="left running"),
        Case("supervision", "a scene that ignores SIGTERM, then SIGTERM",
             ["march", "scene.py", "--no-plot", "--no-progress", "--max-steps", "100000000",
              "--out", "out"], (1,), setup=write(deaf), signals=[(4.0, signal.SIGTERM)],
             check=_march_kept),
    ]


LOAD_SCENES = ["pendulum", "harmonic", "kepler", "henon_heiles", "paper_pendulum", "cr3bp",
               "fpu", "figure_eight"]


def load_cases() -> list[Case]:
    return [Case("load", "8 marches at once, scene limit 2 s", [], (0, 1))]


def run_load(case: Case, root: Path, tag: str) -> Result:
    """Eight marches of built-in scenes started together into folders of their own, each
    with a scene limit of 2 s (the wall clock had refused built-in scenes 12 times under this
    load): a valid run refused (exit 2) is counted."""
    folder = root / "load"
    folder.mkdir()
    env = {**os.environ, "DDVP_FAULT_CASE": tag, "DDVP_SCENE_TIME_LIMIT": "2"}
    started = time.monotonic()
    processes = [subprocess.Popen([PYTHON, "-m", "ddvp_nlp.cli", "march", scene, "--set",
                                   "t_end=5", "--no-plot", "--no-progress", "--out",
                                   f"run-{scene}"], cwd=folder, env=env,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                 for scene in LOAD_SCENES]
    outputs = []
    for process in processes:
        try:
            out, err = process.communicate(timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            process.kill()
            out, err = process.communicate()
        outputs.append((process.returncode, out, err))
    load = os.getloadavg()[0]
    result = Result(case, max(abs(c or 0) for c, _, _ in outputs),
                    "\n".join(o for _, o, _ in outputs), "\n".join(e for _, _, e in outputs),
                    time.monotonic() - started)
    judge(result, folder, tag)
    refused = [scene for scene, (code, _, err) in zip(LOAD_SCENES, outputs, strict=True)
               if code == 2]
    result.refused_under_load = len(refused)
    result.case = Case(case.group, f"{case.name} (load average {load:.1f} at the end)",
                       case.argv, case.codes)
    if refused:
        result.problems.append(f"valid runs refused under load: {refused}")
        result.kinds.add("refused under load")
    return result


# -- the disk and concurrency groups need set-up around the command ----------------------------

def run_disk(case: Case, root: Path, tag: str, disk_kind: str) -> Result:
    disk = SmallDisk("3m") if disk_kind == "tmpfs" else None
    try:
        target = case.argv[-1]
        command = target.split("/")[-1]
        if disk is not None:
            base = disk.path
            if command.endswith("again"):
                first = [a if not a.startswith("@DISK") else str(base / command)
                         for a in case.argv]
                subprocess.run([PYTHON, "-m", "ddvp_nlp.cli", *first], capture_output=True,
                               cwd=root)
            if command.endswith("read-only"):
                disk.read_only()
            else:
                disk.fill(leave=6000)
        else:
            base = root / "rlimit"
            base.mkdir(exist_ok=True)
        argv = [a if not a.startswith("@DISK") else str(base / command) for a in case.argv]
        run = Case(case.group, case.name, argv, case.codes, case.setup, case.signals,
                   case.check, case.expect_text, case.timeout)
        before = _folder_state(base / command)
        result = run_case(run, root, tag)
        result.case = case
        after = _folder_state(base / command)
        if command.endswith("again") and before and before != after:
            result.problems.append("the earlier result changed after a failed write")
            result.kinds.add("torn/lost/lying")
        if (base / command).exists() and not before:
            leftovers = [p.name for p in (base / command).iterdir()]
            if leftovers:
                result.problems.append(f"left behind in a failed write: {leftovers}")
                result.kinds.add("torn/lost/lying")
        return result
    finally:
        if disk is not None:
            disk.close()


def _folder_state(path: Path):
    if not path.exists():
        return None
    return sorted((p.name, p.stat().st_size) for p in path.iterdir())


def run_concurrent(case: Case, root: Path, tag: str) -> Result:
    """Start three writers of one folder together; judge the group."""
    folder = root / re.sub(r"[^A-Za-z0-9_.-]+", "_", f"{case.group}-{case.name}")
    folder.mkdir(parents=True)
    env = {**os.environ, "DDVP_FAULT_CASE": tag}
    variants = [case.argv, case.argv, case.argv]
    if "sweep" in case.argv:
        variants = [case.argv, [*case.argv[:2], "--grid", "tau0=0.2,0.3", *case.argv[4:]]]
    if case.argv == [*LONG_MARCH, "--out", "out"]:
        variants = [case.argv, [*QUICK_MARCH, "--out", "out"]]
    started = time.monotonic()
    processes = []
    for argv in variants:
        processes.append(subprocess.Popen([PYTHON, "-m", "ddvp_nlp.cli", *argv], cwd=folder,
                                          stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                          text=True, env=env))
        time.sleep(0.3 if argv is variants[0] and len(variants) == 2 else 0.0)
    outputs = []
    for process in processes:
        try:
            out, err = process.communicate(timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            process.kill()
            out, err = process.communicate()
        outputs.append((process.returncode, out, err))
    result = Result(case, max((c or 0) for c, _, _ in outputs),
                    "\n".join(o for _, o, _ in outputs), "\n".join(e for _, _, e in outputs),
                    time.monotonic() - started)
    judge(result, folder, tag)
    winners = [i for i, (c, o, _) in enumerate(outputs) if c in (0, 1) and "written to" in o]
    refused = [i for i, (c, _, e) in enumerate(outputs) if c in (1, 2) and (
        "is writing this folder" in e or "another grid" in e)]
    if len(winners) + len(refused) != len(outputs):
        result.problems.append(f"writers neither written nor refused: {outputs}")
        result.kinds.add("torn/lost/lying")
    if not winners:
        result.problems.append("no writer wrote")
        result.kinds.add("torn/lost/lying")
    return result


# -- the page ----------------------------------------------------------------------------------

KINDS = ("traceback", "code", "hang", "torn/lost/lying", "link", "code run",
         "refused under load")


def page(results: list[Result], seed: int, disk_kind: str, seconds: float) -> str:
    from ddvp_nlp.io import machine

    groups = list(dict.fromkeys(r.case.group for r in results))
    lines = ["# Fault injection: every command against signals, disks, links and hostile input",
             "", f"`python scripts/pages/faults.py --seed {seed}` ({len(results)} cases in "
             f"{seconds / 60:.1f} min; {machine()}) Each case runs the real command in a "
             "subprocess; the checks are the script's docstring. Disks: "
             + ("a real tmpfs (3 MB) mounted for each case, filled to 6 kB free or remounted "
                "read-only." if disk_kind == "tmpfs" else
                "no mount was allowed; a file-size limit stands in for a full disk."),
             "", "## Summary", "",
             "| group | cases | passed | " + " | ".join(KINDS) + " |",
             "|---|---|---|" + "---|" * len(KINDS)]
    for group in [*groups, "all"]:
        mine = [r for r in results if group in ("all", r.case.group)]
        counts = [sum(kind in r.kinds for r in mine) for kind in KINDS]
        lines.append(f"| {group} | {len(mine)} | {sum(not r.problems for r in mine)} | "
                     + " | ".join(map(str, counts)) + " |")
    stops = [r.stop_s for r in results if r.stop_s is not None and r.code is not None]
    if stops:
        lines += ["", f"Time from the first signal to the end of the command: median "
                  f"{sorted(stops)[len(stops) // 2]:.2f} s, largest {max(stops):.2f} s "
                  f"({len(stops)} signalled cases that were still running)."]
    lines += ["", "## Every case", "", "| group | case | exit | seconds | outcome |",
              "|---|---|---|---|---|"]
    for r in results:
        outcome = ("; ".join(r.problems) + " (stderr: " + _summary_line(r) + ")") \
            if r.problems else _summary_line(r)
        stop = f" (stopped {r.stop_s:.2f} s after the signal)" if r.stop_s is not None else ""
        lines.append(f"| {r.case.group} | {_cell(r.case.name)} | {r.code} | {r.seconds:.1f} | "
                     f"{'FAIL: ' if r.problems else 'ok: '}{_cell(outcome)}{stop} |")
    return "\n".join(lines) + "\n"


def _summary_line(r: Result) -> str:
    text = (r.stderr.strip().splitlines() or r.stdout.strip().splitlines() or [""])[-1]
    return text[:200]


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=28)
    parser.add_argument("--out", default=str(Path(__file__).resolve().parents[2] / "docs"
                                             / "reliability" / "faults.md"))
    parser.add_argument("--only", default=None,
                        help="groups of cases, comma-separated (writes no page)")
    parser.add_argument("--quick", action="store_true",
                        help="the numbers group alone, its page written (not for docs/)")
    args = parser.parse_args()
    if args.quick:
        args.only = "numbers"
    rng = random.Random(args.seed)
    probe = SmallDisk("1m")
    disk_kind = "tmpfs" if probe.mounted else "rlimit"
    probe.close()
    groups = {"links": link_cases, "signals": lambda: signal_cases(rng),
              "disk": lambda: disk_cases(disk_kind), "concurrent": concurrent_cases,
              "files": hostile_file_cases, "scenes": scene_cases, "numbers": number_cases,
              "resume": resume_cases, "grids": grid_cases, "folders": folder_cases,
              "cache": cache_cases, "events": lambda: event_cases(rng), "bounds": bound_cases,
              "cluster": cluster_cases, "periodic": periodic_cases, "ranges": range_cases,
              "search": search_cases, "switch": switch_cases,
              "backward": backward_cases, "constraints": constraint_cases,
              "constrained_bvp": constrained_bvp_cases,
              "constrained_march": constrained_march_cases,
              "constrained_periodic": constrained_periodic_cases,
              "merges": merge_cases, "target": target_cases, "thinned": thinned_cases,
              "small": small_motion_cases,
              "supervision": supervision_cases, "compare": compare_cases,
              "load": load_cases}
    only = set(args.only.split(",")) if args.only else None
    unknown = sorted((only or set()) - set(groups))
    if unknown:
        parser.error(f"unknown group {unknown[0]!r} (groups: {', '.join(groups)})")
    started = time.monotonic()
    results = []
    with tempfile.TemporaryDirectory(prefix="ddvp-faults-") as tmp:
        root = Path(tmp)
        for group, make in groups.items():
            if only and group not in only:
                continue
            for index, case in enumerate(make()):
                tag = f"{group}-{index}-{os.getpid()}"
                if group == "disk" and case.argv[-1].startswith("@DISK"):
                    result = run_disk(case, root, tag, disk_kind)
                elif group == "concurrent":
                    result = run_concurrent(case, root, tag)
                elif group == "load":
                    result = run_load(case, root, tag)
                elif case.name.startswith("scenes: stdout"):
                    result = _stdout_full(case, root, tag, disk_kind)
                else:
                    result = run_case(case, root, tag)
                results.append(result)
                print(f"{'FAIL' if result.problems else 'ok  '} {group:10s} {case.name[:60]:60s}"
                      f" exit {result.code} {result.seconds:5.1f} s"
                      + (f"  {result.problems}" if result.problems else ""), flush=True)
    text = page(results, args.seed, disk_kind, time.monotonic() - started)
    if args.quick:
        text = text.replace("\n\n", "\n\nA quick run (`--quick`): the numbers group alone.\n\n", 1)
    if not args.only or args.quick:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text)
    print(text.split("## Every case")[0])
    print(counts(results))
    return 1 if any(r.problems for r in results) else 0


def counts(results: list[Result]) -> str:
    """The figures of the closing note, one line each."""
    def having(kind):
        return sum(kind in r.kinds for r in results)

    load_runs = sum(len(LOAD_SCENES) for r in results if r.case.group == "load")
    lines = [f"cases run: {len(results)}",
             f"tracebacks: {having('traceback')}",
             f"wrong exit codes: {having('code')}",
             f"hangs: {having('hang')}",
             f"torn/lost/lying results: {having('torn/lost/lying')}",
             f"links followed: {having('link')}",
             f"code executed that the user did not name: {having('code run')}",
             f"valid runs refused under load: {sum(r.refused_under_load for r in results)} of "
             f"{load_runs}"]
    return "\n".join(lines)


def _stdout_full(case: Case, root: Path, tag: str, disk_kind: str) -> Result:
    """``ddvp scenes > FULL_DISK/file``: exit 1 with a message, no traceback."""
    disk = SmallDisk("1m") if disk_kind == "tmpfs" else None
    try:
        if disk is None:
            return Result(case, 0, "", "", 0.0, problems=[], kinds=set())
        disk.fill(leave=0)
        with open(disk.path / "out.txt", "w") as sink:
            started = time.monotonic()
            done = subprocess.run([PYTHON, "-m", "ddvp_nlp.cli", "scenes"], stdout=sink,
                                  stderr=subprocess.PIPE, text=True, timeout=TIMEOUT_S)
        result = Result(Case(case.group, case.name, case.argv, (1,)), done.returncode, "",
                        done.stderr, time.monotonic() - started)
        own = root / "stdout-full"
        own.mkdir(exist_ok=True)
        judge(result, own, tag)
        result.case = case
        return result
    finally:
        if disk is not None:
            disk.close()


if __name__ == "__main__":
    sys.exit(main())
