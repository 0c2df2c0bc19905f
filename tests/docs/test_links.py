"""The documentation holds together: every relative link in the README and docs/*.md names a file
or folder of the repository, and the licence pyproject.toml declares is there."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
# [text](target) and ![alt](target); the target ends at the first space or closing parenthesis.
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def relative_links(page: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)  # code blocks hold no links
    return [target for target in LINK.findall(text)
            if not re.match(r"[a-z][a-z0-9+.-]*:", target) and not target.startswith("#")]


@pytest.mark.parametrize("page", PAGES, ids=lambda page: str(page.relative_to(ROOT)))
def test_relative_links_exist(page):
    missing = [target for target in relative_links(page)
               if not (page.parent / target.split("#")[0]).exists()]
    assert not missing, f"{page.relative_to(ROOT)}: links to missing files {missing}"


def test_link_pattern_finds_links():
    """The check above is not vacuous: the README links to the theory page and the guide."""
    links = relative_links(ROOT / "README.md")
    assert "docs/theory.md" in links and "docs/guide.md" in links


def test_licence_and_version():
    assert "MIT License" in (ROOT / "LICENSE").read_text()
    from ddvp_nlp.cli import main

    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0


def test_one_version_everywhere():
    """pyproject.toml, ddvp_nlp.__version__ and the newest release of CHANGELOG.md agree."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    import ddvp_nlp

    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    releases = re.findall(r"^## \[(\d+\.\d+\.\d+)\]", (ROOT / "CHANGELOG.md").read_text(),
                          flags=re.M)
    assert declared == ddvp_nlp.__version__ == releases[0], (declared, ddvp_nlp.__version__,
                                                             releases)
