"""The built site renders what the Markdown means (issue 40): `mkdocs build --strict` once per
session into a temporary folder, its pages parsed with the standard library's HTML parser.

- No table left as text: no paragraph line that starts and ends with `|` and has two cells or
  more (a table whose header has a stray `|`, or no blank line before it, becomes a paragraph).
- Every list is a list: no paragraph line starting with "- ", "* " or "1. " (a list glued
  to the paragraph before it), and in the Markdown no continuation paragraph of a list item
  indented by fewer than four spaces (Python-Markdown ends the list there).
- Maths is maths: an inline code span whose text is maths notation (`RULE`, below) should be
  `$...$`, typeset by MathJax through pymdownx.arithmatex (mkdocs.yml); and no `$...$` or
  `\\tau` is left as text outside the maths arithmatex marks.

The build (without the search index) takes about 3 s of CPU; it runs under a CPU limit, never
a wall-clock bound.
"""

from __future__ import annotations

import re
import resource
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BUILD_CPU_SECONDS = 120

# --- the rule: which inline code spans are maths -------------------------------------------------
# Maths notation that Python never writes: a braced subscript, a power with ^, a Greek letter by
# name with a short index, a big O, ~ between terms, an indexed letter (t_k, H_zz, q_N).
GREEK = ("alpha|beta|gamma|delta|epsilon|eps|zeta|eta|theta|kappa|lambda|mu|nu|xi|pi|rho|sigma|"
         "tau|phi|chi|psi|omega|Gamma|Delta|Lambda|Sigma|Phi|Psi|Omega")
SYMBOL = rf"(?:[A-Za-z]|{GREEK})(?:_(?:[A-Za-z0-9]{{1,2}}|\{{[^}}]*\}}))"
MATHS = re.compile(
    r"_\{"                                   # t_{k+1}
    r"|[\w)|]\^[\w({-]"                      # p^2, w^(-1/3), |w|^(1/3)
    rf"|\b(?:{GREEK})(?:_\w{{1,2}})?\b"      # tau, tau_k, mu + 1/mu (whole words only)
    r"|\bO\(\w"                              # O(tau)
    r"|\s~\s"                                # tau ~ |w|^(-1/3)
    rf"|\b{SYMBOL}(?!\w)"                    # t_k, H_zz, S_i
)
# Code: a command-line option, a string, a file, a call with keywords, the tool, a module.
CODE = re.compile(r"--\w|\"|\.py\b|\w\(.*\w=|\bddvp\b|\bnp\.|\bimport\b|^\w+\.\w+|\w=\w|::|\$"
                  r"|\blambda\b[^:]*:")
# One name given a value (`alpha = 0.3`, `delta_w = 1e-4`): an option and its value, code. One
# name alone (`tau`, `tau_min`): the code's own name for a variable, code, unless it is an
# indexed symbol (`t_k`, `S_i`, `tau_k`).
NAME = re.compile(r"^\s*([A-Za-z]\w*)\s*$")
SETTING = re.compile(r"^\s*[A-Za-z]\w*\s*=\s*[-+\d.e]+\s*$")


def is_maths(text: str) -> bool:
    """Whether an inline code span's text is maths notation rather than code."""
    if CODE.search(text) or SETTING.match(text):
        return False
    name = NAME.match(text)
    if name:
        return bool(re.fullmatch(SYMBOL, name.group(1)))
    return bool(MATHS.search(text))


@pytest.mark.parametrize("text", [
    "tau_k = t_{k+1} - t_k", "O(tau)", "tau ~ |w|^(-1/3)", "H = p^2/2 + q^4/4", "t_k", "S_i",
    "mu + 1/mu", "(mu, 1/mu)", "z_k -> z_{k+1}", "H_zz", "E^(k)", "x_3 >= 0", "omega*tau"])
def test_rule_calls_maths_maths(text):
    assert is_maths(text)


@pytest.mark.parametrize("text", [
    "tau", "tau_min", "tau_floor", "alpha = 0.3", "delta_w = 1e-4", "march(..., tau0=0.01)",
    "--tau-min 0.02", "ddvp march kepler", "ddvp_nlp/discrete/scheme.py", "energy_residual",
    "clock=\"left\"", "Solution.tau", "np.cos(q)", "$DDVP_SCHEDULER", "lambda q, p, t: p",
    "global_tol", "t_end", "max_steps"])
def test_rule_leaves_code_code(text):
    assert not is_maths(text)


# Pages whose maths is not all converted yet, and how many inline maths spans each still
# writes as code (at most): the count may only go down. The API reference (api/, from the
# docstrings, which are also read with help() in a terminal) is not held to the rule.
STILL_CODE: dict[str, int] = {
    "accuracy/check/": 3,
    "accuracy/": 2,
    "benchmarks/bench_bvp/": 7,
    "benchmarks/bench_ipopt/": 3,
    "benchmarks/bench_march/": 3,
    "benchmarks/bench_overheads/": 3,
    "chaos/": 1,
    "periodic/bifurcations/": 6,
    "periodic/": 14,
    "poincare/": 1,
    "reproduce/report/": 4,
    "transfers/": 7,
}


# --- the built site ------------------------------------------------------------------------------

class Page(HTMLParser):
    """The article of one built page: its paragraphs' text, its inline code spans and the text
    that is neither code nor maths."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.stack: list[str] = []
        self.article = 0
        self.paragraphs: list[str] = []
        self.codes: list[str] = []
        self.prose: list[str] = []
        self.maths = 0
        self._paragraph: list[str] | None = None
        self._code: list[str] | None = None
        self._skip = 0  # inside <pre>, <code>, <script>, <style> or an arithmatex mark

    def handle_starttag(self, tag, attrs):
        if tag in {"br", "img", "hr", "input", "meta", "link", "wbr"}:
            return
        classes = (dict(attrs).get("class") or "").split()
        self.stack.append((tag, "arithmatex" in classes))
        if tag == "article":
            self.article += 1
        if not self.article:
            return
        if "arithmatex" in classes:
            self.maths += 1
        if tag == "p":
            self._paragraph = []
        if tag == "code" and not any(t == "pre" for t, _ in self.stack[:-1]):
            self._code = []
        if tag in {"pre", "code", "script", "style"} or "arithmatex" in classes:
            self._skip += 1

    def handle_endtag(self, tag):
        while self.stack:
            open_tag, maths = self.stack.pop()
            if self.article and (open_tag in {"pre", "code", "script", "style"} or maths):
                self._skip -= 1
            if open_tag == tag:
                break
        if tag == "article":
            self.article -= 1
        if tag == "p" and self._paragraph is not None:
            self.paragraphs.append("".join(self._paragraph))
            self._paragraph = None
        if tag == "code" and self._code is not None:
            self.codes.append(" ".join("".join(self._code).split()))
            self._code = None

    def handle_data(self, data):
        if self._paragraph is not None:
            self._paragraph.append(data)
        if self._code is not None:
            self._code.append(data)
        if self.article and not self._skip:
            self.prose.append(data)


def _without_search(folder: Path) -> Path:
    """mkdocs.yml as it is but for the search plugin, whose index this test does not read (a
    third of the build's CPU; CI's own `mkdocs build --strict` keeps it), with its paths made
    absolute for a copy in ``folder``."""
    import yaml

    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    config["plugins"] = [p for p in config["plugins"] if p != "search"]
    assert len(config["plugins"]) == 1, "a plugin besides search and mkdocstrings: keep it"
    config["plugins"][0]["mkdocstrings"]["handlers"]["python"]["paths"] = [str(ROOT)]
    config["docs_dir"] = str(ROOT / config["docs_dir"])
    config["hooks"] = [str(ROOT / hook) for hook in config["hooks"]]
    path = folder / "mkdocs.yml"
    path.write_text(yaml.safe_dump(config))
    return path


@pytest.fixture(scope="session")
def site(tmp_path_factory):
    """Every page of the strict build, parsed, by its path in the site (`theory/index.html`)."""
    pytest.importorskip("mkdocs", reason="the docs extra: pip install -e '.[docs]'")
    target = tmp_path_factory.mktemp("site")

    def limit_cpu():
        resource.setrlimit(resource.RLIMIT_CPU, (BUILD_CPU_SECONDS, BUILD_CPU_SECONDS))

    build = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-f",
                            str(_without_search(tmp_path_factory.mktemp("config"))), "-d",
                            str(target)], cwd=ROOT, capture_output=True, text=True,
                           preexec_fn=limit_cpu)
    assert build.returncode == 0, f"mkdocs build --strict failed:\n{build.stderr[-3000:]}"
    pages = {}
    for path in sorted(target.rglob("*.html")):
        page = Page()
        page.feed(path.read_text(encoding="utf-8"))
        pages[path.relative_to(target).as_posix()] = page
    assert "theory/index.html" in pages and "periodic/stability/index.html" in pages
    return pages


TABLE_ROW = re.compile(r"^\s*\|(?:[^|]*\|){2,}\s*$")
LIST_ITEM = re.compile(r"^\s*(?:[-*]|\d+\.)\s")  # "+ " starts wrapped sums in docstrings


def test_no_table_left_as_text(site):
    rows = {name: [line for text in page.paragraphs for line in text.splitlines()
                   if TABLE_ROW.match(line)] for name, page in site.items()}
    rows = {name: found for name, found in rows.items() if found}
    assert not rows, "tables rendered as paragraphs: " + "; ".join(
        f"{name}: {len(found)} rows, first {found[0][:100]!r}" for name, found in rows.items())


def test_every_list_is_a_list(site):
    glued = {name: [line for text in page.paragraphs for line in text.splitlines()
                    if LIST_ITEM.match(line)] for name, page in site.items()}
    glued = {name: found for name, found in glued.items() if found}
    assert not glued, "list items rendered inside paragraphs: " + "; ".join(
        f"{name}: {found[0][:100]!r}" for name, found in glued.items())


def short_continuations(text: str) -> list[int]:
    """Lines (1-based) continuing a list item after a blank line with an indent of 1 to 3
    spaces, which Python-Markdown does not take as part of the item."""
    found, fenced, in_list = [], False, False
    lines = text.splitlines()
    for number, line in enumerate(lines, 1):
        if re.match(r"^\s*(```|~~~)", line):
            fenced = not fenced
            continue
        if fenced or not line.strip():
            continue
        if LIST_ITEM.match(line):
            in_list = True
            continue
        if in_list and re.match(r"^ {1,3}\S", line) and not lines[number - 2].strip():
            found.append(number)
        if not line.startswith(" "):
            in_list = False
    return found


def test_short_continuation_found():
    assert short_continuations("- item\n\n  more of it\n") == [3]
    assert short_continuations("- item\n\n    more of it\n- next\n") == []


def test_list_items_continue_with_four_spaces():
    found = {page.relative_to(ROOT).as_posix(): lines
             for page in sorted((ROOT / "docs").rglob("*.md"))
             if (lines := short_continuations(page.read_text(encoding="utf-8")))}
    assert not found, f"list continuations indented by fewer than 4 spaces (lines): {found}"


def maths_as_code(site) -> dict[str, list[str]]:
    return {name: [code for code in page.codes if is_maths(code)] for name, page in site.items()
            if not name.startswith("api/")}


def test_inline_maths_is_maths(site):
    found = maths_as_code(site)
    over = {name: spans for name, spans in found.items()
            if len(spans) > STILL_CODE.get(name.removesuffix("index.html"), 0)}
    assert not over, "inline maths written as code (write $...$): " + "; ".join(
        f"{name}: {len(spans)} (allowed {STILL_CODE.get(name.removesuffix('index.html'), 0)}),"
        f" {spans[:4]}" for name, spans in over.items())


def test_maths_is_typeset_not_shown(site):
    """No `$...$` or TeX command left in the text: arithmatex took every one."""
    leftover = {name: re.findall(r"\$[^$\s][^$\n]*\$|\\[a-zA-Z]{2,}\b", "".join(page.prose))
                for name, page in site.items()}
    leftover = {name: found for name, found in leftover.items() if found}
    assert not leftover, f"maths shown as text: {leftover}"
    assert site["theory/index.html"].maths > 0
