"""Regenerate the stress report the README shows, into docs/stress/ (a few minutes).

    python scripts/stress.py [--out docs/stress]
"""

from __future__ import annotations

import argparse
import sys
import time

from ddvp_nlp.cli import main as ddvp

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="docs/stress")
    args = parser.parse_args()
    started = time.perf_counter()
    code = ddvp(["stress", "--out", args.out])
    print(f"stress grid: {time.perf_counter() - started:.0f} s")
    sys.exit(code)
