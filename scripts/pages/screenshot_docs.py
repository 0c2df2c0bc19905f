"""Build the documentation site, serve it on localhost and screenshot three pages (theory, user
guide, API reference) in headless Chromium, so a person can check that the maths is typeset by
the MathJax the site carries (docs/hooks.py) and that the API pages show no raw roles.

    pip install -e '.[docs]'            # mkdocs, the theme, MathJax (django-static-mathjax)
    apt-get install chromium            # Debian's headless browser (or set $CHROMIUM)
    python scripts/pages/screenshot_docs.py [--out docs-screenshots] [--no-build]

Nothing leaves the machine: the site is served from 127.0.0.1 on a free port, and Chromium is
started with networking to other hosts disabled. Prints the PNG files written.
"""

from __future__ import annotations

import argparse
import functools
import http.server
import os
import shutil
import subprocess
import sys
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAGES = {"theory": "theory/", "guide": "guide/", "api": "api/solvers/"}
# Time Chromium lets the page run its scripts (MathJax typesets after load) before the shot.
BUDGET_MS = 8000


def chromium() -> str:
    """The Chromium binary: $CHROMIUM, else the first of the usual names on PATH."""
    for name in (os.environ.get("CHROMIUM"), "chromium", "chromium-browser", "google-chrome"):
        if name and shutil.which(name):
            return shutil.which(name)
    sys.exit("no Chromium found: apt-get install chromium, or set $CHROMIUM")


def serve(site: Path) -> tuple[http.server.ThreadingHTTPServer, int]:
    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args):  # the page list is what the script prints
            pass

    handler = functools.partial(Quiet, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, server.server_address[1]


def screenshot(browser: str, url: str, path: Path, size=(1280, 1600)) -> None:
    subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu",
                    "--hide-scrollbars", f"--window-size={size[0]},{size[1]}",
                    f"--virtual-time-budget={BUDGET_MS}",
                    "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
                    f"--screenshot={path}", url],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   timeout=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "docs-screenshots"))
    parser.add_argument("--no-build", action="store_true",
                        help="use the site/ already built")
    args = parser.parse_args()
    site = ROOT / "site"
    if not args.no_build:
        subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet"],
                       cwd=ROOT, check=True)
    if not (site / "javascripts" / "mathjax" / "tex-chtml.js").is_file():
        sys.exit("site/ has no MathJax: build it with `mkdocs build` (docs/hooks.py copies it)")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    browser = chromium()
    server, port = serve(site)
    try:
        for name, page in PAGES.items():
            path = out / f"{name}.png"
            screenshot(browser, f"http://127.0.0.1:{port}/{page}", path)
            print(path)
    finally:
        server.shutdown()


if __name__ == "__main__":
    main()
