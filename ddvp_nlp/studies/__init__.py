"""Studies: many runs and what they measure (work-precision, horizons, stress cases, sweeps,
the paper's claims, Poincare sections, the verdict study). Each study is a plan (its inputs
checked, its tasks listed, before anything runs), a run (the tasks, through ``runner``) and a
report (its files, written through ``io``). The module map is in ``docs/architecture.md``.

Rules: a study imports the library's public names, ``scenes``, ``io`` and ``runner``; never
``cli``.
"""

from typing import TYPE_CHECKING

from ..cache import lazy_exports

# name -> module (relative to this package) that defines it: what the scripts and pages built
# on the studies call and read back. A name that is also a module of this package (stress,
# reproduce, work_precision) cannot be exported: importing the module rebinds the name to it.
PUBLIC = {
    # work-precision and long horizons
    "read_rows": "work_precision_report", "in_words": "work_precision_report",
    "CompareOptions": "work_precision", "ERROR_KINDS": "work_precision",
    "cheapest": "work_precision", "methods_in": "work_precision",
    "winner_spans": "work_precision", "work_precision_horizons": "horizons_report",
    "compare": "comparison", "WorkPrecision": "work_precision",
    "HorizonComparison": "horizons_choice",
    # Poincare sections
    "poincare_section": "poincare", "section_starts": "poincare",
    "SectionOutput": "poincare",
    # the accuracy verdicts on drawn systems
    "draw_case": "verdict_study", "judge_case": "verdict_study", "MARGIN": "verdict_study",
}

if TYPE_CHECKING:  # for readers and static tools; loaded on first use below
    from .comparison import compare
    from .horizons_choice import HorizonComparison
    from .horizons_report import work_precision_horizons
    from .poincare import SectionOutput, poincare_section, section_starts
    from .verdict_study import MARGIN, draw_case, judge_case
    from .work_precision import (
        ERROR_KINDS,
        CompareOptions,
        WorkPrecision,
        cheapest,
        methods_in,
        winner_spans,
    )
    from .work_precision_report import in_words, read_rows

__getattr__, __dir__ = lazy_exports(__name__, PUBLIC)

__all__ = ["CompareOptions", "ERROR_KINDS", "HorizonComparison", "MARGIN", "SectionOutput",
           "WorkPrecision",
           "cheapest", "compare",
           "draw_case", "in_words", "judge_case", "methods_in", "poincare_section",
           "read_rows", "section_starts", "winner_spans", "work_precision_horizons"]
