"""mkdocs hook: MathJax served from the built site, never from a CDN.

The MathJax 3 files come from the PyPI package ``django-static-mathjax`` (the docs extra of
pyproject.toml; it ships MathJax's ``es5`` build as package data and needs no Django to be
read). After the build, the one component the pages load (``tex-chtml.js``) and its web fonts are
copied into ``site/javascripts/mathjax/``, so the site shows typeset maths with no network.
"""

from __future__ import annotations

import shutil
from importlib.resources import files
from pathlib import Path

COMPONENT = "tex-chtml.js"
FONTS = Path("output/chtml/fonts/woff-v2")


def on_post_build(config, **kwargs):
    source = Path(str(files("mathjax"))) / "static" / "mathjax" / "es5"
    if not (source / COMPONENT).is_file():
        raise FileNotFoundError(f"MathJax not found at {source}: pip install -e '.[docs]' "
                                "(django-static-mathjax)")
    target = Path(config["site_dir"]) / "javascripts" / "mathjax"
    (target / FONTS).mkdir(parents=True, exist_ok=True)
    shutil.copy2(source / COMPONENT, target / COMPONENT)
    shutil.copytree(source / FONTS, target / FONTS, dirs_exist_ok=True)
