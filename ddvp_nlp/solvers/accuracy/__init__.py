"""The accuracy check: a verdict on a solution that does not trust the scheme's own equations,
measured against the exact flow (``exact/``): ``accurate``, ``drifted`` (every step follows the
flow and the energy is right, but the phase is lost from ``t_drift`` on) or ``inaccurate``. The
module map is in ``docs/architecture.md``.

The contract of a verdict. An implementer must keep:

1. Scales come from the motion, never from 1: each component's size is its range over the run,
   the energy scale how much ``H`` changes over that size; a verdict does not change when the
   units change or a constant is added to ``H``.
2. What decides is measured against the exact flow (or the exact solution, where one is
   given), with the reference's own error held below a tenth of the tolerance; a first-order
   estimate may be reported, never decide.
3. Every family (a march, a fixed-endpoint or periodic grid, a higher-order trajectory, a
   compared method) gets the same three verdicts and the same report, with the first failure's
   test, step, time, value and limit.
4. This package imports only the core and ``exact/``.
5. A trajectory fed a window at a time (``streaming.py``, a thinned march) keeps only bounded
   state between windows and gets the same report; where a figure depends on scales the
   windows could not know yet, its docstring says which.
"""

from typing import TYPE_CHECKING

from ...cache import lazy_exports

if TYPE_CHECKING:  # for readers and static tools; loaded on first use below
    from .judgement import Level, assess, describe, judge, motion_scales

# loaded when first asked for: importing one module of the family loads only what it needs
__getattr__, __dir__ = lazy_exports(__name__, {
    "assess": "judgement", "judge": "judgement", "describe": "judgement",
    "Level": "judgement", "motion_scales": "judgement"})

__all__ = ["Level", "assess", "describe", "judge", "motion_scales"]
