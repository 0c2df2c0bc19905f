"""Pieces every Markdown report shares: a table that renders, the failure table of a grid and
the machine line beside every timing."""

from __future__ import annotations

import datetime
import os
import platform

import numpy as np


def markdown_table(header, rows) -> list[str]:
    """Markdown lines of a table that renders as one: a blank line first (a table glued to the
    paragraph above is read as its text) and every ``|`` inside a cell escaped (``|M|`` in a
    header would add cells and turn the table into text)."""

    def line(cells):
        return "| " + " | ".join(str(c).replace("|", r"\|") for c in cells) + " |"

    return ["", line(header), "|" + "---|" * len(header)] + [line(row) for row in rows]


def failure_table(rows, title, *columns) -> list[str]:
    """Markdown lines: a section ``title`` with one row per failed run: the given
    ``(header, cell)`` columns, then its status and message."""
    failures = [r for r in rows if r["status"] != "success"]
    if not failures:
        return []
    headers = [h for h, _ in columns] + ["status", "where and why"]
    cells = [[cell(r) for _, cell in columns] + [r["status"], r["message"].replace("|", "/")]
             for r in failures]
    return ["", f"## {title}"] + markdown_table(headers, cells)


def machine(compiler: str | None | bool = False) -> str:
    """One sentence to stand beside every timing a page shows: the CPU model, its cores and the
    load average now, the platform and the versions, how the compiled methods ran (when
    ``compiler`` is given: its name, or ``None`` for CasADi's virtual machine; ``False``, the
    default, leaves it out) and the date and time (UTC)."""
    import casadi
    import scipy

    compiled = "" if compiler is False else (
        f"; compiled methods: gcc-compiled chunks ({compiler})" if compiler
        else "; compiled methods: CasADi virtual machine")
    when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return (f"{cpu_model()}, {os.cpu_count()} cores, load average {load_average()}; "
            f"{platform.platform()}, Python {platform.python_version()}, CasADi "
            f"{casadi.__version__}, NumPy {np.__version__}, SciPy {scipy.__version__}"
            f"{compiled}; measured {when}.")


def cpu_model() -> str:
    """The processor's model name (``/proc/cpuinfo`` on Linux), else what ``platform`` says."""
    try:
        with open("/proc/cpuinfo") as handle:
            for line in handle:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def load_average() -> str:
    """The 1, 5 and 15 minute load averages, or ``unknown`` where the system has none."""
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "unknown"


def seconds(value) -> str:
    """A run time in ms below one second, else in s, to three figures."""
    return f"{value * 1e3:.3g} ms" if value < 1 else f"{value:.3g} s"


def yes_no(flag) -> str:
    return "yes" if flag else "no"
