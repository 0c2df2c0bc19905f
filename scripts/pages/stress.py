"""Regenerate docs/stress/: the stress report of ``ddvp stress`` (its table and heat map).

    python scripts/pages/stress.py [--quick] [--out docs/stress]

About a minute on two local workers (``--quick``: the short grid, seconds; not for docs/). The
command writes its folder (rows, report, figure, manifest) to a scratch folder; the page and its
figure are copied into ``--out``. The report ends with the machine and the date
(``ddvp_nlp.io.machine``).
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
SHOWN = ("stress.md", "stress.png")

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "docs" / "stress"))
    parser.add_argument("--quick", action="store_true", help="the short grid of `ddvp stress`")
    args = parser.parse_args()
    started = time.perf_counter()
    out = Path(args.out)
    with tempfile.TemporaryDirectory(prefix="stress-page-") as scratch:
        code = ddvp(["stress", "--out", scratch, "--no-progress",
                     *(["--quick"] if args.quick else [])])
        if code == 0:
            out.mkdir(parents=True, exist_ok=True)
            for name in SHOWN:
                shutil.copyfile(Path(scratch) / name, out / name)
    print(f"stress grid: exit {code}, {time.perf_counter() - started:.0f} s"
          + (f" -> {out / 'stress.md'}" if code == 0 else ""))
    sys.exit(code)
