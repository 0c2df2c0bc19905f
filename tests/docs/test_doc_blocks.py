"""Every documented form works (issue 40): the ```python blocks of README.md and docs/**/*.md
run, and every `ddvp ...` line of their ```bash/```sh/```console blocks parses with the real
command-line parser (ddvp_nlp/cli/parser.py), so an option that does not exist fails here.

The python blocks of one page run in order in one namespace and one scratch folder (its home
too), as a reader following the page would, in a process of their own bounded by CPU seconds
(RLIMIT_CPU: a count of the work, not a wall clock on this shared machine): a fork of a warm
interpreter that has imported numpy, scipy, CasADi, matplotlib and the package once
(tests/helpers/forked.py, the ``warm_python`` fixture of tests/docs/conftest.py; every page a
fork of the same state, so no page can depend on another). A fresh interpreter per page spent
about 2 s of CPU importing them again.
Conventions in the pages:

- a block whose first line is ``# not run`` (or fenced ```python no-run) is skipped: only for a
  block that needs a cluster or hours;
- a block whose first line is ``# after: ddvp ...`` needs that command's output: the command
  runs first (through ``ddvp_nlp.cli.main``, in the same folder);
- a block of snippet includes (``--8<-- "examples/..."``) is the example file, run by
  tests/docs/test_examples.py.
"""

import re
import shlex
from pathlib import Path

import pytest

from ddvp_nlp.cli.parser import build_parser

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
FENCE = re.compile(r"^```([^\n]*)\n(.*?)^```", re.S | re.M)
SHELL = {"bash", "sh", "console", "shell"}
# CPU seconds a page's python blocks may take together (the guide's are the most: about 60 s
# on this 2-core machine under load)
CPU_SECONDS = 600
# pages whose python blocks cost more than a few seconds: run with -m slow
# (the search and gradient pages repeat what tests/library/periodic/test_search*.py and
# tests/library/marching/test_*gradient*.py check in the default run)
SLOW_PAGES = {"README.md", "docs/guide.md", "docs/periodic/search.md", "docs/gradients.md"}


def blocks(page: Path, kinds: set[str]):
    """``(line, info, body)`` of the fenced blocks of ``page`` whose language is in
    ``kinds``."""
    text = page.read_text()
    for match in FENCE.finditer(text):
        info = match.group(1).strip()
        if info.split(" ")[0] in kinds:
            yield text[:match.start()].count("\n") + 1, info, match.group(2)


def runnable(info: str, body: str) -> bool:
    first = body.lstrip().splitlines()[0] if body.strip() else ""
    return "no-run" not in info.split() and not first.startswith("# not run") \
        and not first.startswith("--8<--")


def python_pages():
    for page in PAGES:
        found = [(line, body) for line, info, body in blocks(page, {"python"})
                 if runnable(info, body)]
        if found:
            name = str(page.relative_to(ROOT))
            marks = [pytest.mark.slow(why="repetition")] if name in SLOW_PAGES else []
            yield pytest.param(page, found, id=name, marks=marks)


@pytest.mark.parametrize("page, found", list(python_pages()))
def test_python_blocks_run(page, found, tmp_path, warm_python):
    code, out, err = warm_python.run("blocks", tmp_path, cpu=CPU_SECONDS, blocks=found,
                                     env={"HOME": str(tmp_path)})
    assert code == 0, f"{page.relative_to(ROOT)}: {out[-3000:]}{err[-3000:]}"


def command_lines(body: str):
    """The ``ddvp ...`` commands of a shell block: continuations joined, prompts and comments
    dropped, ``&&``/``;`` chains split."""
    text = re.sub(r"\\\n\s*", " ", body)
    for raw in text.splitlines():
        line = raw.strip().removeprefix("$ ")
        try:
            words = shlex.split(line, comments=True)
        except ValueError:
            continue
        command = []
        for word in [*words, "&&"]:
            if word in ("&&", ";", "||"):
                if command and command[0] == "ddvp":
                    yield command
                command = []
            else:
                command.append(word)


def shell_commands():
    for page in PAGES:
        for line, info, body in blocks(page, SHELL):
            if not runnable(info, body):
                continue
            for words in command_lines(body):
                yield pytest.param(words, id=f"{page.relative_to(ROOT)}:{line}:{words[1]}")


@pytest.mark.parametrize("words", list(shell_commands()))
def test_documented_commands_parse(words, capsys):
    parser = build_parser()
    try:
        parser.parse_args(words[1:])
    except SystemExit as stop:
        assert stop.code == 0, (" ".join(words), capsys.readouterr().err)


def test_the_extraction_finds_the_blocks():
    """Not vacuous: the README's march example and its commands are found, and an option
    that does not exist fails to parse."""
    lines = [words for page in PAGES for _, _, body in blocks(page, SHELL)
             for words in command_lines(body)]
    assert ["ddvp", "march", "kepler", "--set", "e=0.7", "--set", "tau0=0.005"] in lines
    assert len(lines) > 30
    with pytest.raises(SystemExit):
        build_parser().parse_args(["march", "kepler", "--no-such-option"])
    assert any(page.name == "README.md" for page, *_ in
               (p.values for p in python_pages()))


# The fault pages quote refused command lines on purpose (a scheme given as a method, ...).
QUOTES_REFUSALS = ("docs/reliability/",)


def test_every_scheme_and_method_named_in_the_docs_is_one_the_command_takes():
    """``--scheme X`` names an energy rule and ``--method X`` a compared method, in every
    page, prose and usage lines included (argparse checks ``--method``'s choices in the
    command blocks, not ``--scheme``'s, nor anything in prose: the guide once said
    ``--scheme METHOD``, which the command refuses)."""
    from ddvp_nlp.discrete import RULES
    from ddvp_nlp.studies.methods import METHODS

    takes = {"scheme": set(RULES), "method": {m for m in METHODS if m not in RULES}}
    placeholders = {"METHOD", "NAME", "RULE", "SCHEME"}
    wrong, seen = [], 0
    for page in PAGES:
        where = str(page.relative_to(ROOT))
        if where.startswith(QUOTES_REFUSALS):
            continue
        for flag, value in re.findall(r"--(scheme|method)[ =]([A-Za-z_0-9|]+)",
                                      page.read_text()):
            for name in value.split("|"):
                seen += 1
                if name not in placeholders and name not in takes[flag]:
                    wrong.append(f"{where}: --{flag} {name}")
    assert seen > 10
    assert not wrong, wrong
