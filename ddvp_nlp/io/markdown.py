"""Pieces every Markdown report of a grid shares: the failure table and the machine line."""

from __future__ import annotations

import datetime
import os
import platform

import numpy as np


def failure_table(rows, title, *columns) -> list[str]:
    """Markdown lines: a section ``title`` with one row per failed run: the given
    ``(header, cell)`` columns, then its status and message."""
    failures = [r for r in rows if r["status"] != "success"]
    if not failures:
        return []
    headers = [h for h, _ in columns] + ["status", "where and why"]
    lines = ["", f"## {title}", "", "| " + " | ".join(headers) + " |",
             "|" + "---|" * len(headers)]
    for r in failures:
        cells = [cell(r) for _, cell in columns] + [r["status"],
                                                    r["message"].replace("|", "/")]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def machine(compiler) -> str:
    """One sentence: platform, cores, versions, how the compiled methods ran, and the date."""
    import casadi
    import scipy

    return (f"{platform.platform()}, {os.cpu_count()} cores, Python "
            f"{platform.python_version()}, CasADi {casadi.__version__}, NumPy {np.__version__}, "
            f"SciPy {scipy.__version__}; compiled methods: "
            f"{'gcc-compiled chunks (' + compiler + ')' if compiler else 'CasADi virtual machine'}"
            f"; generated {datetime.date.today().isoformat()}.")


def seconds(value) -> str:
    """A run time in ms below one second, else in s, to three figures."""
    return f"{value * 1e3:.3g} ms" if value < 1 else f"{value:.3g} s"


def yes_no(flag) -> str:
    return "yes" if flag else "no"
