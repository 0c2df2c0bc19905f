"""Regenerate docs/reproduce/: the paper's claims beside the measurements (``ddvp reproduce``),
its report and its three figures.

    python scripts/pages/reproduce_page.py [--quick] [--out docs/reproduce]

A few minutes (``--quick``: the command's short horizons, seconds; not for docs/). The command
writes its folder to a scratch folder; the report and the figures it shows are copied into
``--out``. No timing is shown.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

from ddvp_nlp.cli import main as ddvp

ROOT = Path(__file__).resolve().parents[2]
SHOWN = ("report.md", "paper_figures.png", "site_density.png", "step_ratios.png")

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "docs" / "reproduce"))
    parser.add_argument("--quick", action="store_true", help="`ddvp reproduce --quick`")
    args = parser.parse_args()
    started = time.perf_counter()
    out = Path(args.out)
    with tempfile.TemporaryDirectory(prefix="reproduce-page-") as scratch:
        code = ddvp(["reproduce", "--out", scratch, *(["--quick"] if args.quick else [])])
        if code == 0:
            out.mkdir(parents=True, exist_ok=True)
            for name in SHOWN:
                shutil.copyfile(Path(scratch) / name, out / name)
    print(f"reproduce: exit {code}, {time.perf_counter() - started:.0f} s"
          + (f" -> {out / 'report.md'}" if code == 0 else ""))
    sys.exit(code)
